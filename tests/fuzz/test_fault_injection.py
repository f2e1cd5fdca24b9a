"""Fault injection: ``fusion run`` killed, interrupted or terminated at a random moment, two runs
into one folder at once, a write limit that fills the disk, special files as data. The folder
always holds whole files — each the earlier run's or the new one's, never a torn one — no
process outlives the run, and a refusal is one line with exit status 2.

Cases per fault class: ``BODYFUSION_FAULT_CASES`` (default 1; the long mode,
``benchmarks/faults_long.py``, runs many), drawn from one seed: the same cases every time. With
``BODYFUSION_FAULT_TABLE`` set, each case's outcome is appended to that CSV (class, case,
outcome, detail): ``previous`` / ``new`` (every file the earlier or the new run's), ``mixed``
(each file whole, some of each: a run stopped between two files), ``refused``, or ``defect``.
"""

from __future__ import annotations

import csv
import os
import random
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.paths import ROOT

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc: Linux")]

CASES = int(os.environ.get("BODYFUSION_FAULT_CASES", "1"))
TABLE = os.environ.get("BODYFUSION_FAULT_TABLE")
VICON = ROOT / "configs" / "dual_foot_vicon.yaml"
NEW = ["--set", "smoother.kind=rts"]
"""What the faulted run changes, so that its files differ from the earlier run's."""
DATA_FILES = ("trajectories.csv", "trajectories.parquet", "covariances.parquet", "strides.csv")
TIMEOUT_S = 120


def fusion_run(out: Path, *extra: str, **popen) -> subprocess.Popen:
    """``fusion run`` of the Vicon walk into ``out``, an earlier run's outputs there replaced."""
    return subprocess.Popen([sys.executable, "-m", "bodyfusion", "run", str(VICON), "--out", str(out), "--overwrite",
                             *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)


def files_of(out: Path) -> dict[str, bytes]:
    return {name: (out / name).read_bytes() for name in DATA_FILES if (out / name).exists()}


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict:
    """The earlier run's folder and files, the new run's files, and how long a run takes (s)."""
    root = tmp_path_factory.mktemp("faults")
    t0 = time.perf_counter()
    for name, extra in (("previous", []), ("new", NEW)):
        proc = fusion_run(root / name, *extra)
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err
    return {"root": root, "previous": files_of(root / "previous"), "new": files_of(root / "new"),
            "run_s": (time.perf_counter() - t0) / 2}


def judge(runs: dict, out: Path) -> str:
    """previous, new or mixed: each data file whole; a torn or missing one is a defect."""
    got = files_of(out)
    owners = []
    for name in DATA_FILES:
        if name not in got:
            raise AssertionError(f"{name} missing")
        owner = [k for k in ("previous", "new") if got[name] == runs[k][name]]
        if not owner:
            raise AssertionError(f"{name} is neither run's: torn")
        owners.append(owner[0] if len(owner) == 1 else "either")
    kinds = set(owners) - {"either"}
    return kinds.pop() if len(kinds) == 1 else "previous" if not kinds else "mixed"


def no_survivor(out: Path) -> None:
    """No process whose command line names ``out`` (the run, its figure or writer processes)."""
    deadline = time.time() + 10
    while time.time() < deadline:
        alive = []
        for proc in Path("/proc").iterdir():
            if proc.name.isdigit():
                try:
                    if str(out).encode() in (proc / "cmdline").read_bytes():
                        alive.append(proc.name)
                except OSError:
                    pass
        if not alive:
            return
        time.sleep(0.1)
    raise AssertionError(f"processes outlived the run: {alive}")


def one_line_refusal(code: int, err: str) -> None:
    assert code == 2 and "Traceback" not in err, (code, err)
    assert len([line for line in err.splitlines() if line.startswith("error:")]) == 1, err


def record(cls: str, case: str, outcome: str, detail: str = "") -> None:
    if TABLE:
        new = not Path(TABLE).exists()
        with open(TABLE, "a", newline="") as fh:
            writer = csv.writer(fh)
            if new:
                writer.writerow(["class", "case", "outcome", "detail"])
            writer.writerow([cls, case, outcome, detail])


def case_folder(runs: dict, k: int, cls: str) -> Path:
    out = runs["root"] / f"{cls}_{k}"
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(runs["root"] / "previous", out)
    return out


def draws(cls: str) -> list[random.Random]:
    return [random.Random(f"{cls}-{k}") for k in range(CASES)]


def checked(cls: str, case: str, check) -> None:
    try:
        outcome = check()
    except BaseException as err:
        record(cls, case, "defect", f"{type(err).__name__}: {str(err)[-600:]}")
        raise
    record(cls, case, outcome)


@pytest.mark.parametrize("signum, status", [(signal.SIGKILL, -9), (signal.SIGINT, 130), (signal.SIGTERM, 143)],
                         ids=["kill", "interrupt", "terminate"])
def test_a_run_stopped_at_any_moment_leaves_whole_files_and_no_process(runs, signum, status):
    cls = signal.Signals(signum).name
    for k, rng in enumerate(draws(cls)):
        delay = rng.uniform(0.0, 1.2 * runs["run_s"])
        out = case_folder(runs, k, cls)

        def check() -> str:
            proc = fusion_run(out, *NEW)
            time.sleep(delay)
            proc.send_signal(signum)
            _, err = proc.communicate(timeout=TIMEOUT_S)
            # 130 / 143; the signal's own death (a shell shows the same status) only where it came before
            # the interpreter ran the command's first instruction (~30 ms); 0 where the run had finished
            early = delay < 0.03 and signum != signal.SIGKILL
            assert proc.returncode in (status, 0) or (early and proc.returncode == -signum), (proc.returncode, err)
            assert "Traceback" not in err or early, err
            no_survivor(out)
            outcome = judge(runs, out)
            if signum != signal.SIGKILL:  # stopped cleanly: the earlier files, or all new ones written first
                assert outcome != "mixed", f"{cls} left some files replaced and some not"
            return outcome

        checked(cls, f"after {delay:.2f} s", check)


def test_two_runs_into_one_folder_at_once_are_one_then_the_other_or_one_refused(runs):
    for k, rng in enumerate(draws("concurrent")):
        offset = rng.uniform(0.0, 0.5 * runs["run_s"])
        out = case_folder(runs, k, "concurrent")

        def check() -> str:
            first = fusion_run(out, *NEW)
            time.sleep(offset)
            second = fusion_run(out, *NEW)
            results = [p.communicate(timeout=TIMEOUT_S) for p in (first, second)]
            for proc, (_, err) in zip((first, second), results):
                if proc.returncode != 0:
                    one_line_refusal(proc.returncode, err)
            assert 0 in (first.returncode, second.returncode)
            no_survivor(out)
            return judge(runs, out)

        checked("concurrent", f"second after {offset:.2f} s", check)


def test_a_disk_that_fills_while_writing_keeps_the_earlier_files_and_says_so(runs):
    for k, rng in enumerate(draws("disk_full")):
        limit = int(10 ** rng.uniform(3.0, 6.5))  # 1 kB to 3 MB a file
        out = case_folder(runs, k, "disk_full")

        def check() -> str:
            def cap() -> None:
                resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
                signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails (EFBIG), as a full disk

            proc = fusion_run(out, *NEW, "--set", "output.plots=false", preexec_fn=cap)
            _, err = proc.communicate(timeout=TIMEOUT_S)
            if proc.returncode != 0:
                one_line_refusal(proc.returncode, err)
                assert judge(runs, out) == "previous"
                return "refused"
            return judge(runs, out)

        checked("disk_full", f"files capped at {limit} B", check)


@pytest.mark.parametrize("make", ["fifo", "dev_zero", "folder", "symlink_to_dev_zero"])
def test_a_special_file_as_data_is_refused_unopened(runs, tmp_path, make):
    data = tmp_path / "imu.csv"
    if make == "fifo":
        os.mkfifo(data)
    elif make == "folder":
        data.mkdir()
    elif make == "dev_zero":
        data = Path("/dev/zero")
    else:
        data.symlink_to("/dev/zero")
    layout = tmp_path / "layout.yaml"
    layout.write_text(VICON.read_text().replace("../examples/data/dual_foot_vicon_hu2025/imuMeasLeft.csv", str(data))
                      .replace("../examples/data/", str(ROOT / "examples" / "data") + "/"))

    def check() -> str:
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "bodyfusion", "run", str(layout), "--out",
                               str(tmp_path / "out")], capture_output=True, text=True, timeout=60)
        one_line_refusal(proc.returncode, proc.stderr)
        assert time.perf_counter() - t0 < 30
        return "refused"

    checked("special_file", make, check)
