"""A live run that keeps a bounded history (``keep_s``, ``fusion live --keep``) forgets its oldest
samples as it goes and emits the same states, bit for bit, as one that keeps everything."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import load_layout
from bodyfusion.live.engine import LiveRun
from bodyfusion.live.sources import replay_rows
from bodyfusion.runner.batch import run_layout
from tests.paths import CONFIGS

VICON = CONFIGS / "dual_foot_vicon.yaml"


class Collect:
    def __init__(self) -> None:
        self.states: list[dict] = []

    def write(self, state) -> None:
        self.states.append(state.to_dict())

    def close(self) -> None:
        pass


def _replay(keep_s: float | None):
    sink = Collect()
    run = LiveRun(load_layout(VICON), [sink], keep_s=keep_s)
    held = held_s = 0
    for _, name, row in replay_rows(run):
        run.push(name, row)
        held = max(held, max(b.rows for b in run.buffers.values()))
        held_s = max(held_s, run.held_s)
    assert held_s == pytest.approx((held - 1) / 60.0, abs=0.05)  # what the status line says it holds
    return run, run.close(), sink.states, held


@pytest.fixture(scope="module")
def whole():
    return _replay(None)


@pytest.fixture(scope="module")
def bounded():
    return _replay(20.0)


def test_a_run_keeping_20_s_emits_every_state_of_a_run_keeping_all(whole, bounded):
    assert bounded[2] == whole[2] and len(whole[2]) == 1200


@pytest.mark.parametrize("keep_s", [10.0, 47.3])
def test_any_history_kept_emits_the_same_states(whole, keep_s):
    """Forgetting at other points of the gait (a stance, the stride period's grid) changes nothing."""
    run, _, states, _ = _replay(keep_s)
    assert states == whole[2] and all(s.forgotten > 0 for s in run.fusion.systems.values())


def test_it_holds_a_bounded_part_of_the_recording(whole, bounded):
    run, _, _, held = bounded
    rows = whole[0].buffers["left_foot"].rows  # 120 s at 60 Hz
    forgotten = {name: s.forgotten for name, s in run.fusion.systems.items()}
    assert all(f > 0 and f == run.buffers[name].forgotten for name, f in forgotten.items())
    # the 30 s each pass derives again, the 20 s kept, a forgetting every 20 s and the look-ahead
    assert held <= 75 * 60 < rows


def test_its_finished_run_is_the_last_part_of_the_batch_run(bounded):
    batch = run_layout(load_layout(VICON))
    _, live, _, _ = bounded
    for name, expected in batch.trajectories.items():
        got = live.trajectories[name]
        k = int(np.searchsorted(expected.t, got.t[0]))
        assert got.t[0] > expected.t[0] and got.t[-1] == expected.t[-1]
        np.testing.assert_array_equal(got.pos_n, expected.pos_n[k:])
        np.testing.assert_array_equal(got.pos_sd, expected.pos_sd[k:])
    # the counts cover the whole run; the constraint log the part kept
    assert live.fuser.epochs == batch.fuser.epochs and live.fuser.activations == batch.fuser.activations
    log = live.fuser.constraint_log
    assert 0 < log.n < batch.fuser.constraint_log.n
    np.testing.assert_array_equal(log.t[:log.n], batch.fuser.constraint_log.t[-log.n:])
    assert all(s.revised_inputs == 0 for s in live.systems.values())
    # and it says so: one finding a foot, naming the span its result covers
    windows = [f for f in live.findings if f.kind == "live_window"]
    assert sorted(f.system for f in windows) == ["left_foot", "right_foot"]
    assert all(f.t_start == live.trajectories[f.system].t[0] for f in windows)


def test_a_section_timed_by_row_count_cannot_keep_a_bounded_history():
    loaded = load_layout(VICON, ["systems.left_foot.data.time_column=null", "systems.left_foot.data.rate_hz=60"])
    with pytest.raises(ConfigError, match=r"systems\.left_foot\.data\.time_column: .*--keep"):
        LiveRun(loaded, keep_s=60.0)


@pytest.mark.parametrize("value", [1.0, float("inf"), 1e9])
def test_a_history_beyond_sense_is_refused_naming_it(value):
    with pytest.raises(ConfigError, match=r"keep_s \(fusion live --keep\)"):
        LiveRun(load_layout(VICON), keep_s=value)


def test_the_fusers_records_keep_the_part_held(whole, bounded):
    """What the fuser keeps per epoch is forgotten with the samples: the heading ties' measurements
    (their summary then covers the part kept) and each system's covariance-check times."""
    run, _, _, _ = bounded
    forgot = run._forgot_at
    ties = run.fusion.fuser.ties
    assert ties and all(m[0] >= forgot for tie in ties for m in tie.log)
    assert all(len(tie.log) < len(w.log) for tie, w in zip(ties, whole[0].fusion.fuser.ties))
    held = [len(m._stride_t) for m in run.fusion.monitors.values()]
    every = [len(m._stride_t) for m in whole[0].fusion.monitors.values()]
    assert max(held) < min(every) / 2  # a check time a second: 120 s whole, the part kept
