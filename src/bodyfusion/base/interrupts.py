"""Signals the command line takes (SIGINT, SIGTERM), kept where their exception may be lost.

The command line's handlers (:func:`bodyfusion.cli.main`) record each signal here and raise its
exception (KeyboardInterrupt, :class:`Terminated`). Raised inside a C callback — LLVM's, as
numba compiles a kernel — the exception cannot propagate: Python drops it and the work goes on.
:func:`answer_pending` raises it again at a point where it can stop the work: a run calls it
before it writes its outputs, so that a run interrupted while it compiled leaves the earlier
outputs as they were.
"""

from __future__ import annotations

import signal

RECEIVED: set[int] = set()
"""The signals this process took since the command began."""


class Terminated(Exception):
    """SIGTERM, raised where the process is, so that every ``finally`` runs (files closed whole)."""


def answer_pending() -> None:
    """Raise the exception of a signal taken (:data:`RECEIVED`): :class:`Terminated` for SIGTERM,
    KeyboardInterrupt for SIGINT; nothing when none was."""
    if signal.SIGTERM in RECEIVED:
        raise Terminated
    if signal.SIGINT in RECEIVED:
        raise KeyboardInterrupt
