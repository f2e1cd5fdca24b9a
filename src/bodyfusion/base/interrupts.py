"""Signals the command line takes (SIGINT, SIGTERM), kept where their exception may be lost.

The command line's handlers (:func:`bodyfusion.cli.main`) record each signal here and raise its
exception (KeyboardInterrupt, :class:`Terminated`). Raised inside a C callback — LLVM's, as
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
import signal
from collections.abc import Iterator

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
