"""A UWB tag runs live: its ranges (an id as text, failed rangings, several at one time) are taken
as they come, never pacing the run, and applied at the batch run's events; one that arrives after
the fuser passed its time is counted late and said, not applied out of order."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bodyfusion.base.errors import InputError
from bodyfusion.core.layout import load_layout
from bodyfusion.live.engine import LOOKAHEAD_S, LiveRun
from bodyfusion.live.sources import replay_rows
from bodyfusion.plugins.uwb.streaming import LATE
from bodyfusion.runner.batch import run_layout
from bodyfusion.sim import simulate
from tests.paths import CONFIGS

SHORT = ["path.laps=1", "path.length_m=12", "path.width_m=8"]


@pytest.fixture(scope="module")
def layout(tmp_path_factory):
    folder = tmp_path_factory.mktemp("foot_uwb")
    simulate(CONFIGS / "foot_uwb_sim.yaml", folder, seed=2, overrides=SHORT)
    return folder / "config.yaml"


def _live(layout, delay_s: float = 0.0):
    """The recording replayed live, the tag's ranges arriving ``delay_s`` after their time."""
    run = LiveRun(load_layout(layout, ["output.plots=false"]))
    rows = sorted(replay_rows(run), key=lambda r: r[0] + (delay_s if r[1] == "left_tag" else 0.0))
    for _, name, row in rows:
        run.push(name, row)
    return run, run.close()


def test_a_live_uwb_tag_gives_each_range_the_batch_runs_verdict(layout):
    run, live = _live(layout)
    batch = run_layout(load_layout(layout, ["output.plots=false"]))
    assert not run.buffers["left_tag"].paces and run.buffers["left_tag"].text_columns == ["id"]
    tag, batch_tag = live.aiding["left_tag"], batch.aiding["left_tag"]
    assert len(tag.log) == len(batch_tag.log) > 500 and tag.log.dropped == batch_tag.log.dropped
    assert tag.log.dropped["failed"] > 0  # failed rangings crossed the live path and were dropped by the policy
    assert np.array_equal(tag.fate, batch_tag.fate)
    assert tag.diagnostics()["anchor_ranges"]["late"] == 0 and not any(f.kind == "late_ranges" for f in live.findings)
    rmse = {r.scores["left_foot"].metrics["horizontal_error_m"]["rmse"] for r in (live, batch)}
    assert max(rmse) - min(rmse) < 0.01  # the feet level on their first rest live (a live_levelling finding)


def test_ranges_that_arrive_after_the_fuser_passed_their_time_are_counted_late_and_said(layout):
    _, live = _live(layout, delay_s=LOOKAHEAD_S + 3.0)
    tag = live.aiding["left_tag"]
    late = tag.fate == LATE
    assert late.mean() > 0.5 and (~late).sum() > 0
    assert tag.diagnostics()["anchor_ranges"]["late"] == late.sum()
    finding = next(f for f in live.findings if f.kind == "late_ranges")
    assert f"{late.sum()} of {len(tag.log)} ranges" in finding.message and "--lookahead" in finding.advice


def test_the_tags_row_buffer_keeps_ids_as_text_failed_rangings_and_shared_times(layout):
    run = LiveRun(load_layout(layout))
    buffer = run.buffers["left_tag"]
    assert buffer.add({"t": 1.0, "id": " A1 ", "range_m": 3.5, "nlos": 0})
    assert buffer.add({"t": 1.0, "id": "A2", "range_m": "", "nlos": 0})  # one time, a failed ranging
    assert not buffer.add({"t": 0.9, "id": "A3", "range_m": 2.0, "nlos": 0}) and buffer.dropped == 1
    table = buffer.table()
    assert list(table["id"]) == ["A1", "A2"] and table["range_m"][0] == 3.5 and math.isnan(table["range_m"][1])
    with pytest.raises(InputError, match=r"systems\.left_tag\.ranges: row 4: id is 7, not a name"):
        buffer.add({"t": 2.0, "id": 7, "range_m": 2.0, "nlos": 0})
    with pytest.raises(InputError, match=r"row 4: range_m is inf, not a finite number"):
        buffer.add({"t": 2.0, "id": "A1", "range_m": math.inf, "nlos": 0})


def test_a_bounded_live_run_forgets_the_ranges_taken_and_keeps_what_they_came_to(layout):
    whole_run, whole = _live(layout)
    run = LiveRun(load_layout(layout, ["output.plots=false"]), keep_s=10.0)
    held = 0
    for _, name, row in replay_rows(run):
        run.push(name, row)
        held = max(held, run.buffers["left_tag"].rows)
    bounded = run.close()
    tag, whole_tag = bounded.aiding["left_tag"], whole.aiding["left_tag"]
    forgotten = int(tag.forgotten_tally.fates.sum())
    assert forgotten + len(tag.log) == len(whole_tag.log) and len(tag.log) < 0.6 * len(whole_tag.log)
    assert held < 0.7 * len(whole_tag.log)  # the rows the run held of the tag's stream at most
    diagnostics, whole_diagnostics = tag.diagnostics(), whole_tag.diagnostics()
    for counts, whole_counts in zip([diagnostics["anchor_ranges"], *diagnostics["per_end"].values()],
                                    [whole_diagnostics["anchor_ranges"], *whole_diagnostics["per_end"].values()]):
        assert counts.pop("mean_nis_accepted") == pytest.approx(whole_counts.pop("mean_nis_accepted"), rel=1e-12)
    assert diagnostics == whole_diagnostics and tag.samples == whole_tag.samples
    assert tag.health()["nis"]["anchor_ranges"]["count"] == whole_tag.health()["nis"]["anchor_ranges"]["count"]
    kept, track = bounded.trajectories["left_foot"], whole.trajectories["left_foot"]  # the same ranges applied
    assert np.array_equal(kept.pos_n, track.pos_n[np.searchsorted(track.t, kept.t)])
