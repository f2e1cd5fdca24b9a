"""A run's figures drawn beside the run, in processes of their own (Linux).

:class:`FigureProcess` forks a process as a command starts. That process imports matplotlib and
the figure code (:mod:`bodyfusion.evaluation.plots`) while the run computes — a third of a second
or more that would otherwise follow the run — and, handed the run's result, draws the figures
(:func:`~bodyfusion.evaluation.plots.write_run_plots`) in two halves, one in a process it forks
for the purpose, while the calling process writes the other outputs. The files are the bytes the
calling process would write itself. Forking is only safe from a process with a single thread on
Linux: :meth:`FigureProcess.start` returns None elsewhere, and the caller draws in-process.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import sys
import threading
import traceback
from collections.abc import Callable, Mapping
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

Outcome = tuple[str, Any]
"""``("ok", value)`` or ``("error", exception)``: what a drawing process sends back."""


def _outcome(job: Callable[[], Any]) -> Outcome:
    """``job()``'s value, or the exception it raised (its traceback as a note; an exception that
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


def _draw_in_two(kwargs: Mapping[str, Any]) -> list[Path]:
    """Draw the run's figures (``write_run_plots(**kwargs)``): the first half here, the second
    in a forked process; the files in :data:`~bodyfusion.evaluation.plots.RUN_FIGURES`
    order."""
    from bodyfusion.evaluation.plots import run_figure_names, write_run_plots

    names = run_figure_names(kwargs["scores"])
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # the second drawer: its outcome down the pipe, then gone without cleanup
        try:
            os.close(read_fd)
            outcome = _outcome(lambda: write_run_plots(**kwargs, names=names[len(names) // 2:]))
            with os.fdopen(write_fd, "wb") as pipe:
                pickle.dump(outcome, pipe)
        finally:
            os._exit(0)
    os.close(write_fd)
    mine = _outcome(lambda: write_run_plots(**kwargs, names=names[:len(names) // 2]))
    with os.fdopen(read_fd, "rb") as pipe:
        data = pipe.read()
    _, status = os.waitpid(pid, 0)
    if not data:
        raise RuntimeError(f"the second figure process ended with exit code {os.waitstatus_to_exitcode(status)}")
    written = []
    for kind, value in (mine, pickle.loads(data)):
        if kind == "error":
            raise value
        written += value
    return sorted(written, key=lambda path: names.index(path.stem))


def _serve(conn: Connection) -> None:
    """The figure process: import the figure code, then draw the one job it is sent (none if the
    caller closes its end first)."""
    import bodyfusion.evaluation.plots  # noqa: F401 - the import is what this process does ahead of the run

    try:
        kwargs = conn.recv()
    except EOFError:
        return
    conn.send(_outcome(lambda: _draw_in_two(kwargs)))


class FigureProcess:
    """A process that readies the figure code as the run starts and draws the run's figures when
    :meth:`submit` hands them over; :meth:`written` waits for the files. Close it (or use it as a
    context manager) when the run is done or fails."""

    def __init__(self) -> None:
        context = multiprocessing.get_context("fork")
        self._conn, theirs = context.Pipe()
        self._process = context.Process(target=_serve, args=(theirs,), name="bodyfusion-figures", daemon=True)
        self._process.start()
        theirs.close()

    @classmethod
    def start(cls) -> FigureProcess | None:
        """A figure process, or None where forking is not safe (not Linux, or more than one thread
        in this process)."""
        if sys.platform != "linux" or threading.active_count() > 1:
            return None
        return cls()

    def submit(self, **kwargs: Any) -> None:
        """Hand over the run's figures: the arguments of
        :func:`~bodyfusion.evaluation.plots.write_run_plots` (without ``names``)."""
        self._conn.send(kwargs)

    def written(self) -> list[Path]:
        """The files drawn (as :func:`~bodyfusion.evaluation.plots.write_run_plots` returns them),
        once drawn; raises what drawing raised."""
        try:
            status, value = self._conn.recv()
        except EOFError:
            self._process.join()
            raise RuntimeError(f"the figure process ended with exit code {self._process.exitcode}") from None
        if status == "error":
            raise value
        return value

    def close(self) -> None:
        """End the process, whatever it is doing."""
        self._conn.close()
        self._process.terminate()
        self._process.join()

    def __enter__(self) -> FigureProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
