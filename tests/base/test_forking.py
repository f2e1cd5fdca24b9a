"""Work in a forked copy of the process: its value or its exception comes back; beside other
threads the job runs here instead."""

from __future__ import annotations

import os
import threading

import pytest

from bodyfusion.base.forking import Forked, fork_is_safe


def test_a_forked_job_runs_in_another_process_and_hands_back_its_value(tmp_path):
    assert fork_is_safe()
    job = Forked(lambda: ((tmp_path / "a.txt").write_text("written beside"), os.getpid())[1])
    assert job.result() != os.getpid()
    assert (tmp_path / "a.txt").read_text() == "written beside"


def test_a_forked_jobs_exception_is_raised_here_with_its_traceback():
    def failing() -> None:
        raise KeyError("no such system")

    job = Forked(failing)
    with pytest.raises(KeyError, match="no such system") as raised:
        job.result()
    assert "in failing" in raised.value.__notes__[-1]


def test_a_job_that_kills_its_process_is_an_error_naming_the_exit_code():
    with pytest.raises(RuntimeError, match="exit code 3"):
        Forked(lambda: os._exit(3)).result()


def test_beside_another_thread_the_job_runs_here_at_once():
    gate = threading.Event()
    other = threading.Thread(target=gate.wait)
    other.start()
    try:
        assert not fork_is_safe()
        job = Forked(os.getpid)
    finally:
        gate.set()
        other.join()
    assert job.result() == os.getpid()
