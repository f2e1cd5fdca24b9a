"""The states a live run emits, scored as they pass: the whole run's errors of a run that keeps a
bounded history, by the batch scoring's rule on the states' track."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.base.types import TruthTrack
from bodyfusion.core.epoch_state import EpochState, SystemState
from bodyfusion.core.layout import load_layout
from bodyfusion.evaluation import streamed_scores
from bodyfusion.evaluation.streamed_scores import StreamedScores
from bodyfusion.io import lines
from bodyfusion.io.truth import TruthWindow
from bodyfusion.live.engine import LiveRun
from bodyfusion.live.sources import replay, replay_rows
from bodyfusion.outputs.write import metrics_document
from bodyfusion.runner.batch import run_layout
from bodyfusion.runner.truth import read_truth
from tests.paths import CONFIGS


def _walk(rotation_rad: float, offset_m: np.ndarray, scorer: StreamedScores) -> None:
    """A straight 1 m/s walk north-east, its states every 0.1 s turned by ``rotation_rad`` and
    moved by ``offset_m`` from the truth."""
    c, s = np.cos(rotation_rad), np.sin(rotation_rad)
    for t in np.arange(0.0, 20.0, 0.1):
        true = np.array([0.6 * t, 0.8 * t, 0.0])
        est = np.array([c * true[0] - s * true[1], s * true[0] + c * true[1], 0.0]) + offset_m
        scorer.write(EpochState(float(t), {"foot": SystemState(float(t), est, np.zeros(3))}, {}, 0.0))


def _truth(chunk: int = 2000) -> dict[str, TruthWindow]:
    """The walk's truth at 100 Hz, read ``chunk`` epochs at a time."""
    t = np.arange(0.0, 20.0, 0.01)
    pos = np.column_stack([0.6 * t, 0.8 * t, np.zeros_like(t)])
    return {"foot": TruthWindow(TruthTrack(t[k:k + chunk], pos[k:k + chunk]) for k in range(0, t.size, chunk))}


def test_the_first_metres_alignment_takes_out_a_turned_and_moved_frame():
    scorer = StreamedScores(_truth(), "first_3m", 3.0)
    _walk(np.deg2rad(30.0), np.array([2.0, -1.0, 0.5]), scorer)
    score = scorer.scores()["foot"]
    assert score["horizontal_error_m"]["max"] < 1e-5  # the states' track is straight: interpolation is exact
    assert score["scored_epochs"] == 1991  # the truth epochs from the first state to the last: 0–19.9 s at 100 Hz


def test_without_alignment_the_errors_are_the_frames_offset():
    scorer = StreamedScores(_truth(), "none", 3.0)
    _walk(0.0, np.array([3.0, 4.0, 1.0]), scorer)
    score = scorer.scores()["foot"]
    assert score["horizontal_error_m"]["mean"] == pytest.approx(5.0, abs=1e-5)
    assert score["vertical_error_m"]["mean"] == pytest.approx(1.0, abs=1e-5)


def test_a_bounded_live_run_scores_its_whole_track_as_the_batch_run_does():
    """The Vicon walk kept 20 s at a time: its result scores the last part; ``whole_run`` scores
    every state emitted, within 1 % of the batch run's figures on the whole walk."""
    loaded = load_layout(CONFIGS / "dual_foot_vicon.yaml")
    run = LiveRun(loaded, keep_s=20.0)
    replay(run, replay_rows(run))
    result = run.close()
    batch = run_layout(load_layout(CONFIGS / "dual_foot_vicon.yaml"))
    doc = json.loads(json.dumps(metrics_document(result, "vicon", 0.0)))
    for name, score in batch.scores.items():
        whole = doc["systems"][name]["whole_run"]
        assert whole["horizontal_error_m"]["rmse"] == pytest.approx(score.metrics["horizontal_error_m"]["rmse"],
                                                                    rel=0.01)
        assert whole["scored_epochs"] == pytest.approx(score.metrics["scored_epochs"], rel=0.01)
        assert result.scores[name].metrics["scored_epochs"] < 0.6 * whole["scored_epochs"]  # the kept part's


class _Kept:
    """A sink that keeps every state."""

    def __init__(self) -> None:
        self.states: list[EpochState] = []

    def write(self, state: EpochState) -> None:
        self.states.append(state)

    def close(self) -> None:
        pass


def test_a_bounded_run_reads_its_truth_as_it_goes_and_scores_as_with_the_whole_truth(monkeypatch):
    """The Vicon walk kept 20 s at a time, its truth file read a few kilobytes at a time: the
    scores of every state emitted are those the same states get against the truth read whole,
    and the truth held at the close is the part kept, not the walk's."""
    monkeypatch.setattr(lines, "CHUNK_BYTES", 4096)
    loaded = load_layout(CONFIGS / "dual_foot_vicon.yaml")
    kept = _Kept()
    run = LiveRun(loaded, [kept], keep_s=20.0)
    replay(run, replay_rows(run))
    result = run.close()
    whole = read_truth(loaded.layout.truth, None, list(loaded.layout.systems))
    again = StreamedScores({name: TruthWindow(iter([track])) for name, track in whole.items()},
                           loaded.layout.truth.alignment, loaded.layout.truth.alignment_distance_m)
    for state in kept.states:
        again.write(state)
    assert result.whole_run == again.scores()
    for name, window in run.truth.items():
        assert window.epochs == whole[name].t.size and window.span == (whole[name].t[0], whole[name].t[-1])
        assert window.first > 0.6 * window.epochs  # the walk's first 60 % released as the scores passed
        assert result.truths[name].t[0] >= run.fusion.systems[name].stream.t[0] - 20.0  # the part kept


@settings(max_examples=40, deadline=None)
@given(steps=st.lists(st.floats(-0.05, 0.3), min_size=2, max_size=700), block=st.integers(1, 600),
       seed=st.integers(0, 2**31 - 1))
def test_states_scored_a_block_at_a_time_make_the_errors_of_one_at_a_time(steps, block, seed):
    """Irregular state times (repeated, going back: those are passed over), a wandering track: the
    errors made a block of ``block`` states at a time are those made state by state."""
    rng = np.random.default_rng(seed)
    t = 0.3 + np.cumsum(steps)
    pos = np.cumsum(rng.normal(0.0, 0.1, (t.size, 3)), axis=0)
    figures = []
    for size in (1, block):
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(streamed_scores, "BLOCK_STATES", size)
            scorer = StreamedScores(_truth(chunk=150), "none", 3.0)
            for tk, p in zip(t, pos):
                scorer.write(EpochState(float(tk), {"foot": SystemState(float(tk), p, np.zeros(3))}, {}, 0.0))
            figures.append(scorer.scores()["foot"])
    one, blocks = figures
    assert blocks["scored_epochs"] == one["scored_epochs"]
    assert (blocks["t_start"], blocks["t_end"]) == (one["t_start"], one["t_end"])
    for key in ("horizontal_error_m", "vertical_error_m"):
        if one["scored_epochs"]:
            assert blocks[key] == pytest.approx(one[key], rel=1e-12, abs=1e-15)
