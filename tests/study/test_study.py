"""Studies: grid and run keys, validation up front, failing runs, crash-safe resume, the
local and Dask executors giving the same bits, the outage error metric, summary and plots."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from bodyfusion.base.errors import ConfigError, FusionError
from bodyfusion.base.types import Trajectory, TruthTrack
from bodyfusion.evaluation.metrics import PlanarTransform, outage_errors
from bodyfusion.study import (
    ResultStore,
    expand_grid,
    is_timing_column,
    load_study,
    run_study,
    summarise,
)
from tests.paths import ROOT

# A 40 m walk (~30 s): foot INS and a hand-held phone with GNSS within 1.5 m.
WALK = """\
name: tiny_walk
rate_hz: 100
geodetic_origin: [49.4613, 11.1109, 390.0]
path: {kind: rectangle, length_m: 12, width_m: 6, laps: 1, clockwise: true, start_heading_deg: 0, turn_radius_m: 1.0}
gait: {stride_m: 1.4, cadence_steps_per_min: 108, stance_fraction: 0.6, start_still_s: 2, end_still_s: 1}
systems:
  left_foot: {kind: foot_imu, foot: left, imu: {preset: icm20948}}
  hand_phone: {kind: hand_phone, imu: {preset: phone}, gnss: {rate_hz: 1}}
layout:
  constraints:
    - {between: [left_foot, hand_phone], kind: max, distance_m: 1.5}
  fuser: {method: projection, epochs: events, correct: positions, cross_covariance: true}
"""


def write_study(folder: Path, body: str) -> Path:
    (folder / "walk.yaml").write_text(WALK)
    path = folder / "study.yaml"
    path.write_text(textwrap.dedent(body))
    return path


def fusion(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bodyfusion.cli", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope="module")
def local_run(tmp_path_factory) -> tuple[Path, Path, subprocess.CompletedProcess]:
    """``fusion study`` on 1 layout × 3 outages × 2 seeds = 6 short simulate-and-run runs, 2 workers."""
    folder = tmp_path_factory.mktemp("study")
    study = write_study(folder, """\
        layouts:
          walk: {scenario: walk.yaml}
        outages: {system: hand_phone, start_s: 8, durations_s: [0, 5, 10]}
        seeds: 2
        """)
    proc = fusion("study", study, "--out", folder / "local", "--workers", "2")
    return study, folder / "local", proc


def rows_bits(table: pa.Table) -> dict[str, list]:
    """Every non-timing column; floats as their IEEE-754 bit patterns (NaN equals NaN)."""
    out = {}
    for name in table.column_names:
        if is_timing_column(name):
            continue
        col = table.column(name)
        if pa.types.is_floating(col.type):
            a = col.to_numpy(zero_copy_only=False).astype(np.float64)
            out[name] = [None if v is None else b for v, b in zip(col.to_pylist(), a.view(np.int64).tolist())]
        else:
            out[name] = col.to_pylist()
    return out


# --------------------------------------------------------------------------- grid and keys


def test_shipped_studies_expand_to_their_grids():
    full = expand_grid(load_study(ROOT / "configs" / "gnss_outage_study.yaml"))
    smoke = expand_grid(load_study(ROOT / "configs" / "gnss_outage_study_smoke.yaml"))
    assert len(full) == 2 * 7 * 20 and len(smoke) == 2 * 2 * 2
    assert len({r.key for r in full}) == len(full)
    assert {r.outage[2] for r in full} == {0, 10, 20, 30, 40, 60, 120}
    assert {r.key for r in smoke} <= {r.key for r in full}  # same config and seed, same key


def test_run_key_changes_with_parameters_outage_and_seed(tmp_path):
    study = write_study(tmp_path, """\
        layouts:
          walk: {scenario: walk.yaml}
        parameters:
          layout.fuser.method: [projection, none]
        outages: {system: hand_phone, start_s: 8, durations_s: [0, 5]}
        seeds: [3, 4]
        """)
    grid = expand_grid(load_study(study))
    assert len(grid) == 8 and len({r.key for r in grid}) == 8
    assert grid == expand_grid(load_study(study))  # deterministic
    zero = [r for r in grid if r.outage[2] == 0][0]
    assert "systems.hand_phone.gnss.outages=[]" in zero.overrides
    assert dict(zero.params) == {"layout.fuser.method": "projection"}


# --------------------------------------------------------------------------- validation up front


@pytest.mark.parametrize("body, key", [
    ("layouts: {walk: {scenario: missing.yaml}}\nseeds: 1\n", "layouts.walk.scenario"),
    ("layouts: {walk: {scenario: walk.yaml}}\nseeds: 0\n", "seeds"),
    ("layouts: {walk: {scenario: walk.yaml}}\nseeds: []\n", "seeds"),
    ("layouts: {walk: {scenario: walk.yaml}}\nparameters: {layout.fuser.methd: [none]}\nseeds: 1\n",
     "parameters.layout.fuser.methd"),
    ("layouts: {walk: {scenario: walk.yaml}}\nparameters: {systems.hand_phone.gnss.white_sigma: [1]}\nseeds: 1\n",
     "parameters.systems.hand_phone.gnss.white_sigma"),
    ("layouts: {walk: {scenario: walk.yaml}}\nparameters: {layout.fuser.method: [fastest]}\nseeds: 1\n",
     "parameters.layout.fuser.method"),
    ("layouts: {walk: {scenario: walk.yaml, set: [gait.stride=1]}}\nseeds: 1\n", "layouts.walk"),
    ("layouts: {walk: {scenario: walk.yaml}}\noutages: {system: hand_phone, start_s: 8, durations_s: [-5]}\n"
     "seeds: 1\n", "outages.durations_s"),
    ("layouts: {walk: {scenario: walk.yaml}}\noutages: {system: hand_phone, start_s: 8, durations_s: [500]}\n"
     "seeds: 1\n", "outages.durations_s"),
    ("layouts: {walk: {scenario: walk.yaml}}\noutages: {system: left_foot, start_s: 8, durations_s: [5]}\n"
     "seeds: 1\n", "outages.system"),
    ("layouts: {walk: {scenario: walk.yaml, layout: walk.yaml}}\nseeds: 1\n", "layouts.walk"),
    # a plugin section the simulator completes: its unknown keys and bad values, up front
    ("layouts: {walk: {scenario: walk.yaml}}\nparameters: {layout.systems.hand_phone.filter.step_scale_sdd: [0.1]}\n"
     "seeds: 1\n", "parameters.layout.systems.hand_phone.filter.step_scale_sdd"),
    ("layouts: {walk: {scenario: walk.yaml}}\nparameters: {layout.systems.left_foot.filter.kind: [ukf]}\n"
     "seeds: 1\n", "parameters.layout.systems.left_foot.filter.kind"),
])
def test_bad_study_is_refused_naming_file_and_key(tmp_path, body, key):
    study = write_study(tmp_path, body)
    with pytest.raises(ConfigError) as info:
        load_study(study)
    assert info.value.path == str(study)
    assert str(info.value).startswith(f"{study}: {key}"), str(info.value)


@pytest.mark.slow
def test_cli_refuses_a_bad_study_in_one_line_before_any_run(tmp_path):
    study = write_study(tmp_path, "layouts: {walk: {scenario: walk.yaml}}\n"
                                  "parameters: {layout.fuser.methd: [none]}\nseeds: 1\n")
    proc = fusion("study", study, "--out", tmp_path / "out")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and str(study) in lines[0] and "parameters.layout.fuser.methd" in lines[0]
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- runs, failures, outputs


@pytest.mark.slow
def test_failing_run_is_recorded_with_its_error_and_the_study_goes_on(tmp_path):
    (tmp_path / "broken.yaml").write_text(textwrap.dedent("""\
        systems:
          foot:
            plugin: foot_ins
            data: {path: no_such.csv, rate_hz: 100, acc_columns: [a, b, c], gyro_columns: [d, e, f]}
        """))
    study = write_study(tmp_path, """\
        layouts:
          broken: {layout: broken.yaml}
          walk: {scenario: walk.yaml}
        seeds: 1
        """)
    told: list[tuple[float, float]] = []
    report = run_study(study, tmp_path / "out", workers=1, progress=lambda done, total: told.append((done, total)))
    assert (report.done, report.failed) == (1, 1)
    assert told == [(1, 2), (2, 2)]  # failed runs count as finished
    rows = {r["layout"]: r for r in pq.read_table(tmp_path / "out" / "results.parquet").to_pylist()}
    assert rows["broken"]["status"] == "failed" and "no_such.csv" in rows["broken"]["error"]
    assert rows["walk"]["status"] == "ok" and rows["walk"]["error"] is None
    assert rows["walk"]["systems.hand_phone.horizontal_error_m.rmse"] > 0
    tidy = pq.read_table(tmp_path / "out" / "results_by_system.parquet").to_pylist()
    assert sorted((r["layout"], r["system"]) for r in tidy) == [
        ("broken", None), ("walk", "hand_phone"), ("walk", "left_foot")]  # a failed run: one row, no system


@pytest.mark.slow
def test_cli_study_writes_rows_summary_and_plots_quietly(local_run):
    study, out, proc = local_run
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # no progress bar when stderr is not a terminal
    assert "6 runs: 6 done, 0 failed, 0 skipped" in proc.stdout
    table = pq.read_table(out / "results.parquet")
    assert table.num_rows == 6 and table.column_names[0] == "run_key"
    row = table.to_pylist()[-1]
    assert row["outage.duration_s"] == 10 and row["outage.end_t_s"] < 18
    # one outage: metrics.json's own outage metric is the study's
    assert row["systems.hand_phone.outage_end_error_m"] == row["outage.end_error_m"]
    assert not list((out / "parts").iterdir())
    summary = (out / "summary.csv").read_text().splitlines()
    assert summary[0].startswith("layout,outage_system,outage_start_s,outage_duration_s,metric,runs,failed,mean,sd")
    assert any(",outage.end_error_m,2,0," in line for line in summary)
    assert (out / "end_error_vs_outage.png").stat().st_size > 10_000


def test_results_are_typed_and_the_per_system_view_has_one_row_per_run_and_system(local_run):
    _, out, _ = local_run
    runs = pq.read_table(out / "results.parquet")
    types = {f.name: f.type for f in runs.schema}
    assert types["system_names"] == pa.list_(pa.string())
    assert types["evaluation.transform.translation_m"] == pa.list_(pa.float64())
    assert types["systems.left_foot.diagnostics.initialisation.still_interval_s"] == pa.list_(pa.float64())
    assert pa.types.is_list(types["input.notes"]) and pa.types.is_list(types["input.warnings"])
    assert types["systems.left_foot.horizontal_error_m.rmse"] == pa.float64()
    for name, col in zip(runs.column_names, runs.columns):  # no JSON text left
        if pa.types.is_string(col.type):
            assert not any(str(v).startswith(("[", "{")) for v in col.to_pylist() if v is not None), name

    tidy = pq.read_table(out / "results_by_system.parquet")
    assert tidy.num_rows == runs.num_rows * 2
    pairs = list(zip(tidy.column("run_key").to_pylist(), tidy.column("system").to_pylist()))
    assert pairs == [(k, s) for k, names in zip(runs.column("run_key").to_pylist(),
                                                runs.column("system_names").to_pylist()) for s in names]
    assert {s for _, s in pairs} == {"left_foot", "hand_phone"}
    assert tidy.column_names[:tidy.column_names.index("system") + 1][-2:] == ["error", "system"]
    assert tidy.schema.field("horizontal_error_m.rmse").type == pa.float64()
    assert tidy.schema.field("samples").type == pa.int64()
    by_run = {r["run_key"]: r for r in runs.to_pylist()}
    for row in tidy.to_pylist():
        assert row["horizontal_error_m.rmse"] == by_run[row["run_key"]][f"systems.{row['system']}.horizontal_error_m.rmse"]
    groups = tidy.group_by(["system", "outage.duration_s"]).aggregate([("horizontal_error_m.rmse", "mean")])
    assert groups.num_rows == 2 * 3


@pytest.mark.parametrize("name", ["summary.csv", "results_by_system.parquet", "max_error_vs_outage.png", "runs"])
def test_a_folder_with_no_study_but_a_studys_file_names_is_refused(tmp_path, name):
    (tmp_path / name).write_text("mine\n")
    (tmp_path / "notes.txt").write_text("kept\n")
    with pytest.raises(FusionError, match=rf"holds {name} but no study to resume"):
        ResultStore(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([name, "notes.txt"])
    (tmp_path / "parts").mkdir()  # a study's folder: resumed, its files its own
    ResultStore(tmp_path)


def test_list_parameters_are_list_cells_and_summarised_by_their_value(tmp_path):
    store = ResultStore(tmp_path)
    row = {"layout": "a", "outage.duration_s": 0.0, "status": "ok", "system_names": ["foot"],
           "systems.foot.horizontal_error_m.rmse": 1.0}
    store.append([{**row, "run_key": "k1", "param.lever_m": [0, 0.5]},
                  {**row, "run_key": "k2", "param.lever_m": [0, 0.5], "systems.foot.horizontal_error_m.rmse": 3.0}])
    table = store.compact({"k1": 0, "k2": 1})
    assert table.schema.field("param.lever_m").type == pa.list_(pa.float64())
    assert pq.read_table(tmp_path / "results_by_system.parquet").column("param.lever_m").to_pylist() == [[0, 0.5]] * 2
    (rec,) = summarise(table.to_pylist(), ["param.lever_m"])
    assert rec["param.lever_m"] == "[0.0, 0.5]" and rec["mean"] == 2.0


def test_rerun_skips_completed_runs(local_run, tmp_path):
    study, out, _ = local_run
    copy = tmp_path / "out"
    copy.mkdir()
    (copy / "results.parquet").write_bytes((out / "results.parquet").read_bytes())
    again = run_study(study, copy, workers=2)
    assert (again.done, again.skipped) == (0, 6)
    assert pq.read_table(copy / "results.parquet").equals(pq.read_table(out / "results.parquet"))


@pytest.mark.slow
def test_killed_study_resumes_without_lost_or_duplicated_rows(tmp_path):
    study = write_study(tmp_path, """\
        layouts:
          walk: {scenario: walk.yaml}
        outages: {system: hand_phone, start_s: 8, durations_s: [0, 5, 10]}
        seeds: 4
        """)
    out = tmp_path / "out"
    code = f"from bodyfusion.study import run_study; run_study({str(study)!r}, {str(out)!r}, workers=1, batch_rows=1)"
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    parts = out / "parts"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(parts.glob("part-*.parquet"))) < 3:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    saved = pq.read_table(parts).select(["run_key", "runtime.run_s"]).to_pylist()
    assert 3 <= len(saved) < 12, "the study finished before it was killed"
    assert not (out / "results.parquet").exists()

    report = run_study(study, out, workers=1)
    assert report.skipped == len(saved) and report.done == 12 - len(saved)
    table = pq.read_table(out / "results.parquet")
    keys = table.column("run_key").to_pylist()
    assert sorted(keys) == sorted(r.key for r in expand_grid(load_study(study)))  # none lost, none twice
    run_s = dict(zip(keys, table.column("runtime.run_s").to_pylist()))
    assert all(run_s[r["run_key"]] == r["runtime.run_s"] for r in saved)  # saved rows kept, not re-run


@pytest.mark.slow
def test_one_run_per_task_gives_the_same_rows_as_shared_simulations(local_run, tmp_path):
    """The CLI study shared simulations within its tasks; one run per task simulates every run
    afresh: the same bits."""
    study, out, _ = local_run
    shared = pq.read_table(out / "results.parquet")
    assert any(shared.column("runtime.simulation_reused").to_pylist())
    assert not (out / "runs").exists()  # no run's files unless the study asks
    single = run_study(study, tmp_path / "single", workers=1, runs_per_task=1)
    assert single.tasks == 6
    alone = pq.read_table(tmp_path / "single" / "results.parquet")
    assert not any(alone.column("runtime.simulation_reused").to_pylist())
    assert rows_bits(shared) == rows_bits(alone)


def test_compaction_keeps_the_first_row_of_a_key_saved_twice(tmp_path):
    store = ResultStore(tmp_path)
    store.append([{"run_key": "a", "status": "ok", "x": 1.0}, {"run_key": "b", "status": "ok", "x": 2.0}])
    store.append([{"run_key": "a", "status": "ok", "x": 9.0}])  # a crash between save and bookkeeping
    table = store.compact({"b": 0, "a": 1})
    assert table.column("run_key").to_pylist() == ["b", "a"] and table.column("x").to_pylist() == [2.0, 1.0]
    assert store.keys() == {"a", "b"}


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_rows_as_the_local_pool(local_run, tmp_path):
    study, out, _ = local_run
    told: list[tuple[float, float]] = []
    dask = run_study(study, tmp_path / "dask", "dask", workers=2, progress=lambda done, total: told.append((done, total)))
    assert dask.done == 6 and told == [(k, 6) for k in range(1, 7)]
    a = pq.read_table(out / "results.parquet")
    b = pq.read_table(tmp_path / "dask" / "results.parquet")
    assert rows_bits(a) == rows_bits(b)
    pids = set(b.column("runtime.pid").to_pylist())
    assert len(pids) == 2 and os.getpid() not in pids  # two worker processes, not threads


# --------------------------------------------------------------------------- metric and summary


def test_outage_end_error_is_taken_before_gnss_returns():
    t = np.arange(0.0, 20.0, 0.5)
    truth = TruthTrack(t, np.zeros((t.size, 3)))
    east = np.where((t >= 5) & (t < 10), t - 5, 0.0)  # drifts 1 m/s during the outage, reset at 10 s
    est = Trajectory(t, np.column_stack([east, np.zeros((t.size, 2))]), np.ones((t.size, 3)))
    errs = outage_errors(est, truth, PlanarTransform.identity(), 5.0, 5.0)
    assert errs == {"end_error_m": 4.5, "max_error_m": 4.5, "end_t_s": 9.5}
    base = outage_errors(est, truth, PlanarTransform.identity(), 5.0, 0.0)
    assert base == {"end_error_m": 0.0, "max_error_m": 0.0, "end_t_s": 4.5}


def test_summary_gives_mean_sd_and_percentiles_per_layout_and_outage():
    rows = [{"layout": "a", "outage.duration_s": 10.0, "outage.system": "h", "outage.start_s": 0.0,
             "status": "ok", "outage.end_error_m": float(v)} for v in (1, 2, 3, 4)]
    rows.append({**rows[0], "status": "failed", "outage.end_error_m": None})
    (rec,) = summarise(rows, [])
    assert (rec["metric"], rec["runs"], rec["failed"]) == ("outage.end_error_m", 4, 1)
    assert rec["mean"] == 2.5 and rec["sd"] == pytest.approx(np.std([1, 2, 3, 4], ddof=1))
    assert rec["p50"] == 2.5 and rec["p90"] == pytest.approx(3.7)
