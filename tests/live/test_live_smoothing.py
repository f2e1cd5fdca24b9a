"""A live run with ``smoother.kind: fixed-lag`` emits, beside the filtered states, the states of the
batch run's fixed-lag smoother, bit for bit, each once the data reach its lag: with the whole
history held or a bounded one, to every sink."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from bodyfusion.core.layout import load_layout
from bodyfusion.live.engine import LOOKAHEAD_S, LiveRun
from bodyfusion.live.sources import replay_rows
from bodyfusion.runner.batch import run_layout
from tests.live.test_fusion_live import _read_mcap
from tests.paths import CONFIGS

VICON = CONFIGS / "dual_foot_vicon.yaml"
LAG_S = 2.0
FIXED_LAG = ["smoother.kind=fixed-lag", f"smoother.lag_s={LAG_S}"]


class Collect:
    """Every state written, with the newest data the run held when it was written."""

    def __init__(self) -> None:
        self.run: LiveRun | None = None
        self.states: list = []
        self.newest: list[float] = []

    def write(self, state) -> None:
        self.states.append(state)
        self.newest.append(min(b.newest_t for b in self.run.buffers.values()))

    def close(self) -> None:
        pass


def _replay(keep_s: float | None) -> tuple[LiveRun, Collect]:
    sink = Collect()
    sink.run = run = LiveRun(load_layout(VICON, FIXED_LAG), [sink], keep_s=keep_s)
    for _, name, row in replay_rows(run):
        run.push(name, row)
    run.close()
    return run, sink


@pytest.fixture(scope="module")
def batch():
    return run_layout(load_layout(VICON, FIXED_LAG))


@pytest.mark.parametrize("keep_s", [None, 20.0])
def test_the_smoothed_stream_is_the_batch_fixed_lag_smoother_bit_for_bit(batch, keep_s):
    run, sink = _replay(keep_s)
    smoothed = [s for s in sink.states if s.smoothed_lag_s == LAG_S]
    filtered = [s for s in sink.states if s.smoothed_lag_s is None]
    assert [s.t for s in smoothed] == [s.t for s in filtered] and len(smoothed) == 1200
    for name, track in batch.trajectories.items():
        t = np.array([s.systems[name].t for s in smoothed])
        i = np.searchsorted(track.t, t)
        assert np.array_equal(track.t[i], t)
        assert np.array_equal(track.pos_n[i], np.array([s.systems[name].position_n for s in smoothed]))
        assert not np.array_equal(track.pos_n[i], np.array([s.systems[name].position_n for s in filtered]))
    diagnostics = run.smoothed.diagnostics()
    assert diagnostics["epochs"] == 1200
    assert all(d["windows"] > 50 and d["gain_failures"] == 0 for d in diagnostics["systems"].values())
    if keep_s is not None:
        assert all(s.forgotten > 0 for s in run.fusion.systems.values())


def test_a_smoothed_state_leaves_once_the_data_reach_its_lag():
    _, sink = _replay(None)
    pairs = [(s.t, newest) for s, newest in zip(sink.states, sink.newest) if s.smoothed_lag_s is not None]
    before_close = [(t, newest) for t, newest in pairs if newest < 120.0]
    assert len(before_close) > 1000
    delay = np.array([newest - t for t, newest in before_close])  # the look-ahead, the lag, the segments' ends
    assert delay.min() >= LOOKAHEAD_S + LAG_S and np.median(delay) < LOOKAHEAD_S + LAG_S + 3.0


def test_fusion_live_writes_both_streams_to_json_lines_mcap_and_csv_and_scores_the_smoothed_one(tmp_path):
    jsonl, mcap, csv = tmp_path / "s.jsonl", tmp_path / "s.mcap", tmp_path / "s.csv"
    proc = subprocess.run([sys.executable, "-m", "bodyfusion.cli", "live", str(VICON), "--speed", "max",
                           "--set", "smoother.kind=fixed-lag", "--sink", str(jsonl), "--sink", str(mcap),
                           "--sink", str(csv), "--out", str(tmp_path / "run")], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    states = [json.loads(line) for line in jsonl.read_text().splitlines()]
    smoothed = [s for s in states if "smoothed_lag_s" in s]
    assert len(smoothed) == len(states) - len(smoothed) == 1200 and smoothed[0]["health"] == {}
    topics = _read_mcap(mcap)
    assert len(topics["/bodyfusion/left_foot/pose_smoothed"]) == len(topics["/bodyfusion/epoch_smoothed"]) == 1200
    assert topics["/bodyfusion/epoch_smoothed"][-1] == smoothed[-1]
    rows = csv.read_text().splitlines()
    assert rows[0].endswith(",stream") and sum(r.endswith(",smoothed") for r in rows) == 2400
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["live_smoothing"]["epochs"] == 1200 and metrics["live_smoothing"]["not_smoothed"] == {}
    for name in ("left_foot", "right_foot"):
        scores = metrics["systems"][name]["whole_run_smoothed"]
        assert scores["scored_epochs"] > 7000 and scores["horizontal_error_m"]["rmse"] < 0.2


def test_a_run_that_starts_at_its_close_still_emits_the_smoothed_stream(batch):
    """A recording too short for the warm-up starts on the whole of it at the close, smoothed all the same."""
    sink = Collect()
    sink.run = run = LiveRun(load_layout(VICON, FIXED_LAG), [sink], warmup_s=600.0)
    for _, name, row in replay_rows(run):
        run.push(name, row)
    run.close()
    smoothed = [s for s in sink.states if s.smoothed_lag_s is not None]
    assert run.started is None and len(smoothed) == 1200
    track = batch.trajectories["left_foot"]
    t = np.array([s.systems["left_foot"].t for s in smoothed])
    assert np.array_equal(track.pos_n[np.searchsorted(track.t, t)],
                          np.array([s.systems["left_foot"].position_n for s in smoothed]))
