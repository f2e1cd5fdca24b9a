"""Faults during a study: the parent killed, a worker killed, an unwritable output folder.
Whatever happens, a rerun completes the study with no row lost or twice, and no process of
the study outlives it."""

from __future__ import annotations

import os
import shutil
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


def _corrupt(path: Path, kind: str) -> None:
    """Damage a saved results file as a disk, a crash or a hand might."""
    data = path.read_bytes()
    if kind == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind == "garbage":
        path.write_bytes(bytes(range(256)) * 8)
    elif kind == "bits_flipped":  # in the first data page, past the magic number: its checksum catches it
        flipped = bytearray(data)
        for k in range(40, 48):
            flipped[k] ^= 0xFF
        path.write_bytes(bytes(flipped))
    elif kind == "no_run_key":
        pq.write_table(pq.read_table(path).drop_columns(["run_key"]), path)


@pytest.fixture(scope="module")
def finished_study(tmp_path_factory) -> Path:
    """A small study run to its end once: its folder (study.yaml, walk.yaml, out/)."""
    folder = tmp_path_factory.mktemp("finished_study")
    run_study(write_study(folder, STUDY.replace("seeds: 4", "seeds: 1").replace("[0, 5, 10]", "[0, 5]")),
              folder / "out", workers=1)
    return folder


@pytest.mark.parametrize("kind", ["truncated", "empty", "garbage", "bits_flipped", "no_run_key"])
def test_a_corrupt_results_file_is_moved_aside_with_a_warning_and_its_runs_run_again(finished_study, tmp_path, kind,
                                                                                    caplog):
    shutil.copytree(finished_study, tmp_path / "study")
    study, out = tmp_path / "study" / "study.yaml", tmp_path / "study" / "out"
    clean = pq.read_table(out / "results.parquet")
    _corrupt(out / "results.parquet", kind)
    with caplog.at_level("WARNING", logger="bodyfusion"):
        run_study(study, out, workers=1)
    assert any("results.parquet is corrupt" in r.getMessage() and "run again" in r.getMessage()
               for r in caplog.records)
    assert (out / "corrupt-results.parquet").is_file()
    assert_complete(study, out)
    again = pq.read_table(out / "results.parquet")
    steady = [n for n in clean.column_names if not n.startswith(("runtime.", "constraints.solve_time_us."))]
    assert again.select(steady).equals(clean.select(steady))  # the runs run again give the same rows


def test_a_flipped_byte_in_a_saved_part_is_caught_by_its_page_checksums(tmp_path, caplog):
    """Of single-byte flips all over a saved part, Parquet's page checksums leave at most one in
    fifty unnoticed (without them about one in five changes a value silently)."""
    from bodyfusion.study.results import _table, _write_atomic, read_saved

    rows = [{"run_key": f"run-{i}", "layout": "walk", "seed": i, "status": "ok", "x": float(i) * 0.1}
            for i in range(40)]
    path = tmp_path / "part.parquet"
    _write_atomic(_table(rows), path)
    clean = path.read_bytes()
    expected = read_saved(path)
    silent = flips = 0
    for offset in range(4, len(clean) - 8, 5):
        damaged = bytearray(clean)
        damaged[offset] ^= 0xFF
        path.write_bytes(bytes(damaged))
        got = read_saved(path)
        flips += 1
        silent += got is not None and not got.equals(expected)
        (tmp_path / "corrupt-part.parquet").unlink(missing_ok=True)
    assert flips > 100 and silent <= flips // 50, (silent, flips)
