"""Faults during a study: the parent killed, a worker killed, an unwritable output folder.
Whatever happens, a rerun completes the study with no row lost or twice, and no process of
the study outlives it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pyarrow.parquet as pq
import pytest

from bodyfusion.base.errors import FusionError
from bodyfusion.study import expand_grid, load_study, run_study
from tests.paths import ROOT
from tests.study.test_study import write_study

STUDY = """\
    layouts:
      walk: {scenario: walk.yaml}
    outages: {system: hand_phone, start_s: 8, durations_s: [0, 5, 10]}
    seeds: 4
    """


def start_study(study: Path, out: Path, workers: int) -> subprocess.Popen:
    """The study in a new process, each run its own task and its row saved at once: when the
    first rows are on disk the workers still have runs to do (with runs batched per task, a
    fast worker could finish them all while the study writes the first batch's rows, and a
    kill would then find it idle with nothing left to lose)."""
    code = (f"from bodyfusion.study import run_study; "
            f"run_study({str(study)!r}, {str(out)!r}, workers={workers}, batch_rows=1, runs_per_task=1)")
    return subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def wait_for_parts(out: Path, count: int, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and len(list((out / "parts").glob("part-*.parquet"))) < count:
        time.sleep(0.05)


def assert_complete(study: Path, out: Path) -> None:
    table = pq.read_table(out / "results.parquet")
    keys = table.column("run_key").to_pylist()
    assert sorted(keys) == sorted(r.key for r in expand_grid(load_study(study)))  # none lost, none twice


@pytest.mark.slow
def test_a_killed_parent_leaves_no_worker_behind(tmp_path):
    """``kill -9`` of the study process alone (not its group): its pool workers and the
    multiprocessing helpers it started end within seconds instead of living on as orphans."""
    study = write_study(tmp_path, STUDY)
    out = tmp_path / "out"
    proc = start_study(study, out, workers=2)
    wait_for_parts(out, 2)
    children = psutil.Process(proc.pid).children(recursive=True)
    assert children, "the study started no worker"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    gone, alive = psutil.wait_procs(children, timeout=10)
    assert not alive, f"{len(alive)} process(es) of the study outlived it: {[p.pid for p in alive]}"
    run_study(study, out, workers=1)
    assert_complete(study, out)


@pytest.mark.slow
def test_a_killed_worker_stops_the_study_and_a_rerun_completes_it(tmp_path):
    study = write_study(tmp_path, STUDY)
    out = tmp_path / "out"
    proc = start_study(study, out, workers=1)
    wait_for_parts(out, 2)
    workers = psutil.Process(proc.pid).children(recursive=True)
    victim = next(p for p in workers if "resource_tracker" not in " ".join(p.cmdline()))
    victim.kill()
    assert proc.wait(timeout=60) != 0  # the study stops, saying so
    run_study(study, out, workers=1)
    assert_complete(study, out)


def test_an_unwritable_output_folder_is_one_line_and_a_rerun_completes(tmp_path):
    """The folder for the saved rows cannot be made (a file stands in its place, as a full or
    read-only disk would refuse it): the study stops with one line; once it can write, a
    rerun completes."""
    study = write_study(tmp_path, STUDY.replace("seeds: 4", "seeds: 1"))
    out = tmp_path / "out"
    out.mkdir()
    (out / "parts").write_text("in the way")
    with pytest.raises(FusionError, match="cannot create"):
        run_study(study, out, workers=1)
    (out / "parts").unlink()
    run_study(study, out, workers=1)
    assert_complete(study, out)


def test_parts_of_runs_with_and_without_findings_concatenate_with_one_findings_type():
    """A run with no finding and one with a whole-run finding (no times) and a timed one write
    parts of the same schema: their cells alone would type as lists of null, or of structs whose
    times are null, which do not concatenate."""
    import pyarrow as pa

    from bodyfusion.base.findings import Finding
    from bodyfusion.study.results import FINDINGS_TYPE, _table

    timed = Finding("nis_high", "warning", "foot", 0.0, 60.0, "m", "c", "a").to_dict()
    whole = Finding("large_error", "warning", None, None, None, "m", "c", "a").to_dict()
    parts = [_table([{"run_key": "a", "health.findings": []}]),
             _table([{"run_key": "b", "health.findings": [whole]}]),
             _table([{"run_key": "c", "health.findings": [timed, whole]}])]
    assert all(p.schema.field("health.findings").type == FINDINGS_TYPE for p in parts)
    joined = pa.concat_tables(parts)
    assert [len(v) for v in joined.column("health.findings").to_pylist()] == [0, 1, 2]
