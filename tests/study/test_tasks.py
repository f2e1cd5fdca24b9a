"""Tasks: runs grouped by the data they simulate (one simulation per group in a task, the same
bits as a simulation per run), every run in exactly one task; a run's files only when the
study asks for them."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from bodyfusion.sim import load_scenario, simulated
from bodyfusion.study import expand_grid, load_study, plan_tasks, run_study
from bodyfusion.study.grid import DEFAULT_RUNS_PER_TASK, outage_override
from tests.paths import ROOT
from tests.study.test_study import write_study


def test_tasks_hold_every_run_once_and_the_runs_of_one_simulation_together():
    grid = expand_grid(load_study(ROOT / "configs" / "gnss_outage_study.yaml"))
    assert len({r.data_key for r in grid}) == 2 * 20  # the seven outages of a layout and seed: one walk
    for size, workers in ((None, 2), (3, 2), (1, 1), (50, 4)):
        tasks = plan_tasks(grid, size, workers)
        flat = [r.key for task in tasks for r in task]
        assert sorted(flat) == sorted(r.key for r in grid)  # none lost, none twice
        assert max(map(len, tasks)) <= (size or DEFAULT_RUNS_PER_TASK)
        if size is None:
            assert all(len({r.data_key for r in task}) == 1 and len(task) == 7 for task in tasks)
    assert len(plan_tasks(grid[:6], None, 2)) >= 3  # a small study still gives each worker two tasks


def test_runs_share_data_across_layout_overrides_and_outages_only(tmp_path):
    study = write_study(tmp_path, """\
        layouts:
          walk: {scenario: walk.yaml}
        parameters:
          layout.fuser.method: [projection, none]
          systems.hand_phone.gnss.white_sigma_m: [1.0, 2.0]
        outages: {system: hand_phone, start_s: 8, durations_s: [0, 5]}
        seeds: [3, 4]
        """)
    grid = expand_grid(load_study(study))
    groups: dict[str, set] = {}
    for r in grid:
        groups.setdefault(r.data_key, set()).add((dict(r.params)["systems.hand_phone.gnss.white_sigma_m"], r.seed))
    assert len(groups) == 4 and all(len(g) == 1 for g in groups.values())


def _tables(sim):
    layout, tables = sim.in_memory()
    return json.dumps(layout, sort_keys=True), {f"{k}.{c}": v for k, t in tables.items() for c, v in t.items()}


def test_a_relaid_simulation_is_the_simulation_of_its_own_overrides(tmp_path):
    write_study(tmp_path, "seeds: 1\n")
    walk = tmp_path / "walk.yaml"
    first = simulated(walk, 5, [outage_override("scenario", {}, "hand_phone", 8.0, 5.0)])
    for extra, duration in (([], 0.0), (["layout.fuser.method=none"], 10.0)):
        overrides = [*extra, outage_override("scenario", {}, "hand_phone", 8.0, duration)]
        loaded = load_scenario(walk, overrides)
        windows = [(o.start_s, o.duration_s) for o in loaded.systems["hand_phone"].gnss.outages]
        layout, tables = _tables(first.relaid(loaded, overrides, {"hand_phone": windows}))
        fresh_layout, fresh = _tables(simulated(walk, 5, overrides))
        assert layout == fresh_layout and tables.keys() == fresh.keys()
        assert all(np.array_equal(tables[k], fresh[k]) for k in tables)


@pytest.mark.slow
def test_run_outputs_write_each_runs_folder(tmp_path):
    study = write_study(tmp_path, """\
        layouts:
          walk: {scenario: walk.yaml}
        outages: {system: hand_phone, start_s: 8, durations_s: [0, 5]}
        seeds: 1
        run_outputs: true
        """)
    report = run_study(study, tmp_path / "out", workers=1)
    assert report.done == 2
    rows = pq.read_table(tmp_path / "out" / "results.parquet").to_pylist()
    for row in rows:
        folder = tmp_path / "out" / "runs" / row["run_key"]
        assert {"config.yaml", "truth.csv", "hand_phone_imu.csv", "metrics.json", "trajectories.csv"} <= {
            p.name for p in folder.iterdir()}
        metrics = json.loads((folder / "metrics.json").read_text())
        rmse = metrics["systems"]["hand_phone"]["horizontal_error_m"]["rmse"]
        assert rmse == row["systems.hand_phone.horizontal_error_m.rmse"]
    assert "outages" in (tmp_path / "out" / "runs" / rows[1]["run_key"] / "config.yaml").read_text()
