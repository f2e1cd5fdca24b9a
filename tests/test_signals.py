"""Signals: SIGINT and SIGTERM stop a command cleanly (130, 143) and leave earlier outputs as they
were; a forked child (the figure process) dies with its parent, even a parent killed outright."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.paths import CONFIGS

VICON = CONFIGS / "dual_foot_vicon.yaml"


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                out.append(int(entry.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _start_run(out: Path) -> tuple[subprocess.Popen, int]:
    """``fusion run`` of the Vicon walk into ``out``, once its figure process is up: (process, child pid)."""
    proc = subprocess.Popen([sys.executable, "-m", "bodyfusion", "run", str(VICON), "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while time.time() < deadline:
        children = _children(proc.pid)
        if children:
            time.sleep(0.3)  # past the start-up imports
            return proc, children[0]
        time.sleep(0.01)
    proc.kill()
    pytest.fail("no figure process appeared")


pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and fork: Linux")


@pytest.mark.parametrize("signum, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_stops_a_run_with_its_status_and_leaves_the_earlier_outputs(tmp_path, signum, status):
    out = tmp_path / "run"
    subprocess.run([sys.executable, "-m", "bodyfusion", "run", str(VICON), "--out", str(out)], check=True,
                   capture_output=True)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    proc, child = _start_run(out)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == status, err
    assert "Traceback" not in err
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert after == before
    deadline = time.time() + 10
    while _alive(child) and time.time() < deadline:
        time.sleep(0.05)
    assert not _alive(child)


def test_the_figure_process_dies_with_a_parent_killed_outright(tmp_path):
    proc, child = _start_run(tmp_path / "run")
    proc.kill()  # SIGKILL: no handler of the parent runs
    proc.wait(timeout=30)
    deadline = time.time() + 10
    while _alive(child) and time.time() < deadline:
        time.sleep(0.05)
    assert not _alive(child)
    shutil.rmtree(tmp_path / "run", ignore_errors=True)


def test_an_interrupt_a_library_swallowed_still_ends_the_command_with_130(monkeypatch, capsys):
    """A KeyboardInterrupt raised inside a C callback (LLVM's, as numba compiles) is printed and
    dropped there; the command runs on, and its end answers the signal it took."""
    from bodyfusion import cli

    def command(**_: object) -> None:
        try:
            os.kill(os.getpid(), signal.SIGINT)
        except KeyboardInterrupt:
            pass  # what the callback does with it

    monkeypatch.setattr(cli, "app", command)
    with pytest.raises(SystemExit) as exit_:
        cli.main()
    assert exit_.value.code == 130 and "aborted" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the caller's handler back


def test_a_signal_taken_inside_a_c_callback_prints_no_traceback(monkeypatch, capsys):
    """Where Python can only drop the signal's exception (a C callback: LLVM's as numba compiles)
    it printed 'Exception ignored ... Traceback'; now nothing, and the command ends with 143."""
    import ctypes

    from bodyfusion import cli

    def command(**_: object) -> None:
        callback = ctypes.CFUNCTYPE(None)(lambda: os.kill(os.getpid(), signal.SIGTERM))
        callback()  # called through C: the handler's exception is dropped there

    printed = []  # what would be printed as "Exception ignored ... Traceback"
    monkeypatch.setattr(sys, "unraisablehook", printed.append)
    monkeypatch.setattr(cli, "app", command)
    with pytest.raises(SystemExit) as exit_:
        cli.main()
    assert exit_.value.code == 143 and "terminated" in capsys.readouterr().err
    assert printed == []
    assert sys.unraisablehook == printed.append  # the caller's hook back


def _wait_until_caught(pid: int, signum: int, timeout_s: float = 60.0) -> None:
    """Until process ``pid`` catches ``signum`` (its ``SigCgt`` mask in /proc). For SIGTERM, which
    the interpreter leaves alone: until bodyfusion.__main__ has taken the signals, however
    loaded the machine (SIGINT the interpreter catches from its start)."""
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines())
        if int(fields["SigCgt"].strip(), 16) >> (signum - 1) & 1:
            return
        time.sleep(0.005)
    raise AssertionError(f"process {pid} did not take signal {signum} within {timeout_s} s")


@pytest.mark.parametrize("signum, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_while_the_command_line_loads_ends_it_with_its_status_and_no_traceback(tmp_path, signum, status):
    """The handlers are in place before the command line's modules load (bodyfusion.__main__):
    signalled 0 to 0.2 s after they are, while those modules load (a second or more)."""
    for delay in (0.0, 0.06, 0.2):
        proc = subprocess.Popen([sys.executable, "-m", "bodyfusion", "run", str(VICON), "--out", str(tmp_path / "run")],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        _wait_until_caught(proc.pid, signal.SIGTERM)  # both are taken at once
        time.sleep(delay)
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == status, (delay, proc.returncode, err)
        assert "Traceback" not in err


def _status_of_module(program: str, folder: Path) -> int:
    """The exit status of ``program`` run as ``python -m`` runs a module (as ``-m bodyfusion``):
    the interpreter's own exit path, where ``-c`` and a script exit straight from the error."""
    (folder / "program.py").write_text(program)
    return subprocess.run([sys.executable, "-m", "program"], cwd=folder, capture_output=True, timeout=60,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}).returncode


def test_ctrl_c_once_passed_through_code_run_from_a_string_still_exits_130(tmp_path):
    """CPython kills itself with SIGINT at exit once a KeyboardInterrupt has left code run from a
    string (SciPy's array-API layer imports so), whatever the status; the command's 130 stands."""
    program = """
import os, signal, sys
from bodyfusion.base.interrupts import as_process
def command():
    from bodyfusion import cli
    def app(**_):
        try:
            exec("os.kill(os.getpid(), signal.SIGINT); import time; time.sleep(5)")
        except KeyboardInterrupt:
            raise
    cli.app = app
    cli.command()
as_process(command)
"""
    assert _status_of_module(program, tmp_path) == 130


def test_once_the_command_has_ended_a_signal_no_longer_changes_its_status(tmp_path):
    """Ignored, not masked: the interpreter's shutdown puts Python handlers back to the default,
    which a signal delivered to a worker thread would take (death by the signal)."""
    program = """
import signal, sys
from bodyfusion.base.interrupts import as_process
try:
    as_process(lambda: sys.exit(0))
finally:
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN and signal.getsignal(signal.SIGINT) is signal.SIG_IGN
"""
    assert _status_of_module(program, tmp_path) == 0
