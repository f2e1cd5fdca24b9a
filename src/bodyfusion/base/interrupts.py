"""Signals the command line takes (SIGINT, SIGTERM), kept where their exception may be lost.

The command line's handlers (:func:`take_signals`, installed by :func:`bodyfusion.cli.main` and,
before any module of the command line loads, by the process entry :func:`bodyfusion.__main__.main`)
record each signal here and raise its exception (KeyboardInterrupt, :class:`Terminated`). Raised inside a C callback — LLVM's, as
numba compiles a kernel — the exception cannot propagate: Python drops it and the work goes on.
:func:`answer_pending` raises it again at a point where it can stop the work: a run calls it
before it writes its outputs, so that a run interrupted while it compiled leaves the earlier
outputs as they were.

Where an exception raised at an arbitrary point would break what it passes through — a library's
lock taken but never released while worker threads wait on it (numba's and LLVM's, as the feet
are smoothed in threads) — the work runs :func:`deferred`: the handlers only record the signal
there, and the block's end answers it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from collections.abc import Callable, Iterator
from typing import NoReturn

RECEIVED: set[int] = set()
"""The signals this process took since the command began."""


class Terminated(BaseException):
    """SIGTERM, raised where the process is, so that every ``finally`` runs (files closed whole);
    like KeyboardInterrupt not an Exception, so that no handler of failures (a smoother's, a
    solver's: "never fail a run") takes it for one."""


_DEFERRED = [0]
"""Depth of :func:`deferred` blocks the process is in."""


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Inside: a signal is recorded, not raised (:func:`deferring`); at the block's end one taken
    inside it is answered (:func:`answer_pending`), unless the block raised anyway."""
    before = set(RECEIVED)
    _DEFERRED[0] += 1
    try:
        yield
    finally:
        _DEFERRED[0] -= 1
    if not _DEFERRED[0]:
        answer_pending(RECEIVED - before)


def deferring() -> bool:
    """Whether the process is inside a :func:`deferred` block."""
    return _DEFERRED[0] > 0


def answer_pending(taken: set[int] | None = None) -> None:
    """Raise the exception of a signal taken (``taken``, default :data:`RECEIVED`): :class:`Terminated`
    for SIGTERM, KeyboardInterrupt for SIGINT; nothing when none was."""
    taken = RECEIVED if taken is None else taken
    if signal.SIGTERM in taken:
        raise Terminated
    if signal.SIGINT in taken:
        raise KeyboardInterrupt


_MAIN_PID: list[int] = []
"""The process whose SIGTERM raises :class:`Terminated` (a forked child ends at once)."""


def _terminate(signum: int, frame: object) -> None:
    if os.getpid() not in _MAIN_PID:  # a copy forked before it set its own handlers: end as by default
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGTERM)
        return
    RECEIVED.add(signum)
    if not deferring():  # else answered where the deferred work ends
        raise Terminated


def _interrupt(signum: int, frame: object) -> None:
    RECEIVED.add(signum)
    if not deferring():
        raise KeyboardInterrupt


def take_signals() -> dict[int, object]:
    """SIGINT raises KeyboardInterrupt and SIGTERM :class:`Terminated` in this process (each
    recorded in :data:`RECEIVED`, which starts empty; inside :func:`deferred` only recorded) —
    also where the shell started the command with them ignored (a background job). Returns the
    handlers they replace (:func:`restore_signals`)."""
    _MAIN_PID[:] = [os.getpid()]
    RECEIVED.clear()
    return {signum: signal.signal(signum, handler) for signum, handler in
            ((signal.SIGINT, _interrupt), (signal.SIGTERM, _terminate))}


def restore_signals(previous: dict[int, object]) -> None:
    """The handlers :func:`take_signals` replaced, put back."""
    for signum, handler in previous.items():
        signal.signal(signum, handler if handler is not None else signal.SIG_DFL)


def exit_aborted() -> NoReturn:
    """Say ``aborted`` and exit 130 (Ctrl-C). A KeyboardInterrupt that once passed out of code run
    from a string (``exec("...")``, as SciPy's array-API layer imports) leaves CPython's flag for
    an unhandled Ctrl-C set, and a process started with ``-m`` or as a script entry then kills
    itself with SIGINT at its exit whatever status it gave; a string run to its end clears the
    flag (``run_eval_code_obj``)."""
    print("aborted", file=sys.stderr)
    exec("None")  # noqa: S102 - resets the interpreter's unhandled-KeyboardInterrupt flag, see above
    sys.exit(130)


def exit_terminated() -> NoReturn:
    """Say ``terminated`` and exit 143 (SIGTERM)."""
    print("terminated", file=sys.stderr)
    sys.exit(143)


def as_process(command: Callable[[], None]) -> None:
    """Run ``command`` (it sets the exit status) as this process's whole work (the ``fusion``
    command: :mod:`bodyfusion.__main__`): the signals taken (:func:`take_signals`) before it
    starts, so that one while its modules load ends the process with 130 or 143 as the command
    would, and ignored once it has ended, so that one arriving while the interpreter shuts down
    no longer changes the status of a command whose work is done. Ignored, not masked: a mask
    holds for one thread, and the interpreter's shutdown puts every signal with a Python handler
    back to its default, which a signal delivered to any other thread (a worker pool's) would
    then take: death by the signal. An ignored one it leaves ignored."""
    take_signals()
    try:
        command()
    except KeyboardInterrupt:
        exit_aborted()
    except Terminated:
        exit_terminated()
    finally:
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_IGN)
