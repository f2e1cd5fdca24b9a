"""Writing a run's outputs loses nothing: the set of files replaces the previous set once all are
written, a write that fails part-way (a full disk) keeps every file of the earlier run whole and
says so in one line, and a second run cannot mix its files into a folder another run is writing."""

from __future__ import annotations

import errno
import multiprocessing
from pathlib import Path

import pytest

from bodyfusion.base.errors import FusionError
from bodyfusion.base.files import STAGING_PREFIX, replaced_atomically, sole_writer, staged_outputs
from bodyfusion.core.layout import load_layout
from bodyfusion.outputs import write
from bodyfusion.outputs.write import write_outputs
from bodyfusion.runner import run_layout

WALKER = {"systems": {"walker": {"plugin": "random_walk", "duration_s": 5.0}}, "output": {"plots": False}}


@pytest.fixture()
def result(write_yaml):
    return run_layout(load_layout(write_yaml(WALKER)))


def _no_partial_files(folder: Path) -> bool:
    return not [p for p in folder.rglob("*") if ".partial" in p.name or p.name.endswith(".old")
                or p.name.startswith(STAGING_PREFIX)]


def test_a_run_writes_its_files_whole_and_leaves_nothing_partial(result, tmp_path):
    write_outputs(result, tmp_path, "walk", 1.0)
    assert {p.name for p in tmp_path.iterdir()} >= {"metrics.json", "trajectories.csv", "trajectories.parquet", "tum"}
    assert _no_partial_files(tmp_path)


@pytest.mark.parametrize("failing", ["write_trajectories_csv", "write_trajectories_parquet",
                                     "write_covariances_parquet"])
def test_a_disk_that_fills_part_way_keeps_every_file_of_the_previous_run_and_says_so_in_one_line(
        result, tmp_path, monkeypatch, failing):
    write_outputs(result, tmp_path, "walk", 1.0)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}

    def full_disk(path, *args, **kwargs):
        Path(path).write_bytes(b"PAR1 half a file")
        raise OSError(errno.ENOSPC, "No space left on device")

    def new_file(path, *args, **kwargs):  # the new run's files differ from the earlier ones
        Path(path).write_bytes(b"the new run's")

    for writer in ("write_trajectories_csv", "write_trajectories_parquet", "write_covariances_parquet"):
        monkeypatch.setattr(write, writer, full_disk if writer == failing else new_file)
    with pytest.raises(FusionError) as err:
        write_outputs(result, tmp_path, "walk again", 1.0)
    assert "No space left on device" in str(err.value) and "\n" not in str(err.value)
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before  # the files written first too
    assert _no_partial_files(tmp_path)


def test_a_staged_set_replaces_the_earlier_one_whole_and_clears_what_a_killed_writer_left(tmp_path):
    (tmp_path / "a.txt").write_text("old a")
    (tmp_path / "gone.txt").write_text("an earlier set's file this set does not make")
    (tmp_path / "notes.txt").write_text("the user's own")
    dead = multiprocessing.get_context("fork").Process(target=lambda: None)
    dead.start()
    dead.join()
    (tmp_path / f"{STAGING_PREFIX}{dead.pid}").mkdir()  # a writer killed while staging
    with pytest.raises(RuntimeError), staged_outputs(tmp_path, owned=lambda n: n in ("a.txt", "gone.txt")) as stage:
        (stage / "a.txt").write_text("new a")
        raise RuntimeError("a writer that fails half way")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "gone.txt", "notes.txt"]
    assert (tmp_path / "a.txt").read_text() == "old a"
    with staged_outputs(tmp_path, last=("a.txt",), owned=lambda n: n in ("a.txt", "gone.txt")) as stage:
        (stage / "a.txt").write_text("new a")
        (stage / "tum").mkdir()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "notes.txt", "tum"]
    assert (tmp_path / "a.txt").read_text() == "new a"


def _hold(folder: str, ready, release) -> None:
    with sole_writer(Path(folder)):
        ready.set()
        release.wait(30)


def test_a_second_run_into_a_folder_being_written_is_refused_not_mixed(result, tmp_path):
    context = multiprocessing.get_context("fork")
    ready, release = context.Event(), context.Event()
    other = context.Process(target=_hold, args=(str(tmp_path), ready, release))
    other.start()
    try:
        assert ready.wait(30)
        with pytest.raises(FusionError, match="another run is writing into this folder"):
            write_outputs(result, tmp_path, "walk", 1.0)
        assert not (tmp_path / "metrics.json").exists()
    finally:
        release.set()
        other.join()
    write_outputs(result, tmp_path, "walk", 1.0)  # the folder is free again
    assert (tmp_path / "metrics.json").is_file()


def test_a_replaced_folder_is_the_new_one_whole(tmp_path):
    (tmp_path / "tum").mkdir()
    (tmp_path / "tum" / "old_system.txt").write_text("old")
    with replaced_atomically(tmp_path / "tum") as new:
        new.mkdir()
        (new / "walker.txt").write_text("new")
    assert [p.name for p in (tmp_path / "tum").iterdir()] == ["walker.txt"] and _no_partial_files(tmp_path)
    with pytest.raises(RuntimeError), replaced_atomically(tmp_path / "tum") as new:
        new.mkdir()
        raise RuntimeError("a writer that fails half way")
    assert [p.name for p in (tmp_path / "tum").iterdir()] == ["walker.txt"] and _no_partial_files(tmp_path)



def test_covariances_parquet_holds_every_entry_each_system_stores(tmp_path):
    """covariances.parquet: per system and recorded epoch the entries its covariance history
    holds, the same numbers; entries a system does not store are null, not columns of NaN."""
    import json

    import pyarrow.parquet as pq

    from bodyfusion.core.layout import load_layout
    from bodyfusion.outputs.write import write_outputs
    from bodyfusion.runner import run_layout
    from tests.paths import ROOT

    result = run_layout(load_layout(ROOT / "configs" / "dual_foot_vicon.yaml"))
    write_outputs(result, tmp_path, "dual_foot_vicon.yaml", total_wall_s=0.0)
    table = pq.read_table(tmp_path / "covariances.parquet")
    stored = json.loads(table.schema.metadata[b"bodyfusion.stored"])
    assert set(stored) == {"left_foot", "right_foot"}
    import numpy as np
    import pyarrow.compute as pc

    left = table.filter(pc.equal(table.column("system").cast("string"), "left_foot"))
    history = result.covariances("left_foot")
    assert left.num_rows == len(history.t)
    np.testing.assert_array_equal(left.column("var_v_up_mps").to_numpy(), history.matrix[:, 5, 5])
    np.testing.assert_array_equal(left.column("cov_attitude_north_rad_attitude_up_rad").to_numpy(),
                                  history.matrix[:, 7, 8])
    assert "cov_east_m_up_m" not in table.column_names  # never stored: no column


def test_a_folder_holding_outputs_is_refused_before_the_run_unless_overwrite(tmp_path):
    """--out holding a trajectories.csv no run of ours wrote: one line naming it, the file kept,
    nothing run; with --overwrite replaced. A folder of an earlier run's outputs is kept as well,
    unless --overwrite, which says it replaced them."""
    import subprocess
    import sys

    from tests.paths import ROOT

    def fusion(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "bodyfusion.cli", *args], capture_output=True, text=True)

    config = str(ROOT / "configs" / "dual_foot_vicon.yaml")
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "trajectories.csv").write_text("my own\n")
    (mine / "thesis.txt").write_text("kept\n")
    proc = fusion("run", config, "--out", str(mine))
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "trajectories.csv" in proc.stderr
    assert (mine / "trajectories.csv").read_text() == "my own\n" and not (mine / "metrics.json").exists()
    assert fusion("run", config, "--out", str(mine), "--overwrite").returncode == 0
    assert (mine / "trajectories.csv").read_text() != "my own\n" and (mine / "thesis.txt").read_text() == "kept\n"
    first = (mine / "trajectories.csv").read_bytes()
    again = fusion("run", config, "--out", str(mine))  # an earlier run's outputs: kept
    assert again.returncode == 2 and "an earlier run's outputs" in again.stderr
    assert (mine / "trajectories.csv").read_bytes() == first
    replaced = fusion("run", config, "--out", str(mine), "--overwrite")  # replaced, and said
    assert replaced.returncode == 0 and "replaced" in replaced.stdout


@pytest.mark.parametrize(("make", "said"), [
    (lambda root: (root / "out").write_text("x"), "it is not a folder"),
    (lambda root: (root / "parent").write_text("x"), "parent is not a folder"),
    (lambda root: (root / "out").symlink_to(root / "missing"), "a link to the missing"),
], ids=["a file", "under a file", "a dangling link"])
def test_an_out_that_cannot_be_a_folder_is_refused_before_the_run(tmp_path, make, said):
    make(tmp_path)
    out = tmp_path / ("parent/out" if said.startswith("parent") else "out")
    with pytest.raises(FusionError, match=said) as err:
        write.check_output_folder(out)
    assert str(out) in str(err.value)
