"""A run's figures drawn beside the run, in processes of their own (Linux).

:class:`FigureProcess` forks a process as a command starts. That process imports matplotlib and
the figure code (:mod:`bodyfusion.evaluation.plots`) and draws a figure into memory while the run
computes — half a second or more that would otherwise follow the run — and, handed what the
figures show of the result (:class:`~bodyfusion.evaluation.scored_run.ScoredTracks`), draws them
(:func:`~bodyfusion.evaluation.plots.write_run_plots`) in two halves, one in a process it forks
for the purpose, while the calling process writes the other outputs.
The files are the bytes the calling process would write itself. Forking is only safe from a
process with a single thread on Linux: :meth:`FigureProcess.start` returns None elsewhere, and
the caller draws in-process."""

from __future__ import annotations

import io
import multiprocessing
import os
from multiprocessing.connection import Connection
from pathlib import Path
from typing import NamedTuple

from bodyfusion.base.forking import Forked, child_signals, fork_is_safe, holding_signals, outcome, raised_or_value
from bodyfusion.base.sections import FiguresConfig
from bodyfusion.evaluation.scored_run import ScoredRun, ScoredTracks


class FigureJob(NamedTuple):
    """What the figure process is sent: where to draw, the run's figures' content, the formats."""

    out_dir: Path
    run: ScoredTracks
    figures: FiguresConfig


def _draw_in_two(job: FigureJob) -> list[Path]:
    """Draw the run's figures (:func:`~bodyfusion.evaluation.plots.write_run_plots`): the first
    half here, the second in a forked process; the files in
    :data:`~bodyfusion.evaluation.plots.RUN_FIGURES` order."""
    from bodyfusion.evaluation.plots import run_figure_names, write_run_plots

    names = run_figure_names(job.run)
    second = Forked(lambda: write_run_plots(job.out_dir, job.run, job.figures, names[len(names) // 2:]),
                    fork=len(names) > 1)
    first = write_run_plots(job.out_dir, job.run, job.figures, names[:len(names) // 2])
    return [*first, *second.result()]


def _ready() -> None:
    """Import the figure code and draw one small figure into memory: the first figure a process
    draws pays for what matplotlib loads and caches on first use (fonts, the PNG writer, the χ²
    quantiles of the NEES band), about a tenth of a second."""
    import numpy as np

    from bodyfusion.evaluation.consistency import NeesTrack
    from bodyfusion.evaluation.plots import plot_nees

    t = np.linspace(0.0, 1.0, 11)
    plot_nees(ScoredTracks(nees={"ready": NeesTrack(t, 1.0 + t)})).savefig(io.BytesIO(), format="png")


def _serve(conn: Connection, parent: int) -> None:
    """The figure process: ready the figure code (:func:`_ready`), then draw the one job it is
    sent (none if the caller closes its end first)."""
    child_signals(parent)
    _ready()
    try:
        job = conn.recv()
    except EOFError:
        return
    conn.send(outcome(lambda: _draw_in_two(job)))


class FigureProcess:
    """A process that readies the figure code as the run starts and draws the run's figures when
    :meth:`submit` hands them over; :meth:`written` waits for the files. Close it (or use it as a
    context manager) when the run is done or fails."""

    def __init__(self) -> None:
        context = multiprocessing.get_context("fork")
        self._conn, theirs = context.Pipe()
        self._process = context.Process(target=_serve, args=(theirs, os.getpid()), name="bodyfusion-figures",
                                        daemon=True)
        with holding_signals():
            self._process.start()
        theirs.close()

    @classmethod
    def start(cls) -> FigureProcess | None:
        """A figure process, or None where forking is not safe (not Linux, or more than one thread
        in this process)."""
        return cls() if fork_is_safe() else None

    def submit(self, out_dir: Path, run: ScoredRun, figures: FiguresConfig) -> None:
        """Hand over the run's figures: what :func:`~bodyfusion.evaluation.plots.write_run_plots`
        takes; of the run only its :class:`~bodyfusion.evaluation.scored_run.ScoredTracks` is
        sent."""
        self._conn.send(FigureJob(Path(out_dir), ScoredTracks.of(run), figures))

    def written(self) -> list[Path]:
        """The files drawn (as :func:`~bodyfusion.evaluation.plots.write_run_plots` returns them),
        once drawn; raises what drawing raised."""
        try:
            drawn = self._conn.recv()
        except EOFError:
            self._process.join()
            raise RuntimeError(f"the figure process ended with exit code {self._process.exitcode}") from None
        return raised_or_value(drawn)

    def close(self) -> None:
        """End the process, whatever it is doing."""
        self._conn.close()
        self._process.terminate()
        self._process.join()

    def __enter__(self) -> FigureProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
