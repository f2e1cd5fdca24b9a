"""Work done beside this process, in a forked copy of it (Linux): output files that do not
depend on each other written at the same time, a first run's kernels compiled ahead, the two
halves of a run's figures drawn — on two cores instead of one.

A forked copy shares this process's memory until either writes to it, so a job needs no
arguments sent; it hands back its value (or the exception it raised) through a pipe. Forking
is only safe from a process with one thread on Linux: elsewhere :class:`Forked` runs the job at
once, here, and :meth:`Forked.result` is the same either way.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import pickle
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterator
from typing import Any

Outcome = tuple[str, Any]
"""``("ok", value)`` or ``("error", exception)``: what a job hands back."""


def fork_is_safe() -> bool:
    """Whether this process may fork: on Linux, with no thread but this one."""
    return sys.platform == "linux" and threading.active_count() == 1


PR_SET_PDEATHSIG = 1
"""prctl(2) option: the signal a process gets when its parent dies (Linux)."""


def child_signals(parent: int) -> None:
    """In a copy forked from process ``parent``: SIGTERM ends it at once and SIGINT is left to the
    parent (Ctrl-C reaches the whole process group; the parent ends its children), whatever
    handlers the parent had installed to close its own files first (:func:`bodyfusion.cli.main`);
    and it dies with its parent, even one killed outright (SIGKILL: no handler runs there), by
    the kernel's parent-death signal (prctl ``PR_SET_PDEATHSIG``)."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform == "linux":
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent:  # the parent died before the request took
            os._exit(0)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, HELD)


HELD = {signal.SIGINT, signal.SIGTERM}
"""Signals held back while a process forks (:func:`holding_signals`): the parent takes them once
it has recorded the child, the child once it has its own handlers (:func:`child_signals`)."""


@contextlib.contextmanager
def holding_signals() -> Iterator[None]:
    """In the parent, around a fork: SIGINT and SIGTERM wait until the child is recorded (none
    lands between the fork and that record: a child no one would end); the child, forked inside,
    keeps them held until :func:`child_signals`."""
    parent = os.getpid()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, HELD)
    try:
        yield
    finally:
        if os.getpid() == parent:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def outcome(job: Callable[[], Any]) -> Outcome:
    """``job()``'s value, or the exception it raised, its traceback as a note (an exception that
    cannot be pickled becomes a RuntimeError of its text)."""
    try:
        return "ok", job()
    except Exception as err:  # noqa: BLE001 - any failure is handed back to the caller to raise
        err.add_note("".join(traceback.format_exception(err)).rstrip())
        try:
            pickle.dumps(err)
        except Exception:  # noqa: BLE001
            err = RuntimeError(f"{type(err).__name__}: {err}\n{err.__notes__[-1]}")
        return "error", err


def raised_or_value(result: Outcome) -> Any:
    """The value of an :data:`Outcome`; raises its exception."""
    kind, value = result
    if kind == "error":
        raise value
    return value


class Forked:
    """``job()`` run in a forked copy of this process (where :func:`fork_is_safe` and ``fork``),
    else at once, here; :meth:`result` waits for its value and raises what it raised. A fork
    costs a process of a run's size (a few hundred MB resident) about 10 ms — the copy's page
    tables, its first writes to shared pages, its exit —, so a job of about that is not worth
    one (``fork=False``)."""

    def __init__(self, job: Callable[[], Any], fork: bool = True) -> None:
        self._pid: int | None = None
        if not (fork and fork_is_safe()):
            self._outcome = outcome(job)
            return
        read_fd, write_fd = os.pipe()
        parent = os.getpid()
        with holding_signals():
            pid = os.fork()
        if pid == 0:  # the copy: the outcome down the pipe, then gone without this process's exit handlers
            try:
                child_signals(parent)
                os.close(read_fd)
                result = outcome(job)
                with os.fdopen(write_fd, "wb") as pipe:
                    pickle.dump(result, pipe)
            finally:
                os._exit(0)
        os.close(write_fd)
        self._pid, self._read_fd = pid, read_fd

    def result(self) -> Any:
        """The job's value, once done."""
        if self._pid is not None:
            with os.fdopen(self._read_fd, "rb") as pipe:
                data = pipe.read()
            _, status = os.waitpid(self._pid, 0)
            self._pid = None
            self._outcome = pickle.loads(data) if data else (
                "error", RuntimeError(f"the forked process ended with exit code {os.waitstatus_to_exitcode(status)}"))
        return raised_or_value(self._outcome)
