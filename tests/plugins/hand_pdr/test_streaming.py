"""The hand-held phone live: its IMU rows pace the run, its fixes are taken as they come, and a
replay places the batch run's steps, takes its fixes and keeps a bounded history bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import load_layout
from bodyfusion.live.engine import LiveRun
from bodyfusion.live.sources import replay_rows
from bodyfusion.runner.batch import run_layout


class Collect:
    def __init__(self) -> None:
        self.states: list[dict] = []

    def write(self, state) -> None:
        self.states.append(state.to_dict())

    def close(self) -> None:
        pass


@pytest.fixture(scope="module")
def walk(short_hand_walk):
    return short_hand_walk


def _live(config, keep_s=None, delay_fixes_s=0.0):
    sink = Collect()
    run = LiveRun(load_layout(config), [sink], keep_s=keep_s)
    rows = list(replay_rows(run))
    if delay_fixes_s:  # every fix arrives late: pushed with the IMU row delay_fixes_s after it
        rows.sort(key=lambda r: r[0] + (delay_fixes_s if r[1].endswith(".gnss") else 0.0))
    for _, name, row in rows:
        run.push(name, row)
    return run, run.close(), sink.states


@pytest.fixture(scope="module")
def live(walk):
    return _live(walk)


def test_the_live_phone_places_the_batch_runs_steps_and_takes_its_fixes(walk, live):
    run, result, states = live
    batch = run_layout(load_layout(walk))
    hand, ours = batch.systems["hand_phone"], result.systems["hand_phone"]
    assert np.array_equal(ours.step_index, hand.step_index)
    assert ours.gnss_counts == hand.gnss_counts
    assert ours.revised_steps == 0 and ours.late_fixes == 0
    assert run.buffers["hand_phone.gnss"].rows == 59  # a fix a second, every one taken into its buffer
    assert len(states) > 550
    ours_t, batch_t = ours.trajectory(), hand.trajectory()
    common = np.intersect1d(ours_t.t, batch_t.t)
    a = ours_t.pos_n[np.searchsorted(ours_t.t, common)]
    b = batch_t.pos_n[np.searchsorted(batch_t.t, common)]
    assert np.max(np.hypot(*(a - b)[:, :2].T)) < 0.5  # the feet start on the live run's first rest


def test_a_bounded_history_with_the_phone_emits_the_same_states(walk, live):
    _, _, whole = live
    run, result, states = _live(walk, keep_s=20.0)
    assert states == whole
    hand = result.systems["hand_phone"]
    assert hand.forgotten > 1000 and run.buffers["hand_phone.gnss"].forgotten > 10
    assert "live_window" in {f.kind for f in hand.findings()}
    nis_t = np.concatenate([r.columns()["t"] for r in run.fusion.built["hand_phone"].nis_records.values()])
    assert nis_t.size and nis_t.min() >= hand.t[0]  # its updates' NIS forgotten with its samples


def test_fixes_that_arrive_after_their_time_was_decided_are_counted_and_said(walk):
    _, result, _ = _live(walk, delay_fixes_s=5.0)  # beyond the 2 s look-ahead
    hand = result.systems["hand_phone"]
    assert hand.late_fixes > 30
    assert "late_fixes" in {f.kind for f in hand.findings()}


def test_the_run_waits_for_a_first_fix(walk):
    run = LiveRun(load_layout(walk))
    for t, name, row in replay_rows(run):
        if not name.endswith(".gnss"):
            run.push(name, row)
        if t > 20.0:
            break
    assert run.fusion is None and "no fix has arrived yet" in str(run.not_started)


@pytest.mark.parametrize("edit, key", [
    ({"phone_log": "log.txt", "imu": None}, "systems.hand_phone.phone_log"),
    ({"magnetometer": {"enabled": True, "columns": ["mx", "my", "mz"]}}, "systems.hand_phone.magnetometer.enabled"),
    ({"gnss": {"format": "nmea", "path": "fixes.nmea"}}, "systems.hand_phone.gnss.format"),
], ids=["phone_log", "magnetometer", "nmea"])
def test_what_the_phone_cannot_do_live_is_refused_naming_its_key(walk, tmp_path, edit, key):
    layout = yaml.safe_load(walk.read_text())
    hand = layout["systems"]["hand_phone"]
    for k, v in edit.items():
        if v is None:
            hand.pop(k)
        else:
            hand[k] = v
    for name in ("log.txt", "fixes.nmea"):
        (tmp_path / name).write_text("")
    for name in ("left_foot_imu.csv", "right_foot_imu.csv", "hand_phone_imu.csv", "hand_phone_gnss.csv", "truth.csv"):
        (tmp_path / name).symlink_to(walk.parent / name)
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(layout))
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        LiveRun(load_layout(path))
