"""Progress of long work: a run's fusion over its data, a simulation's systems, a study's runs.

The library reports through a :data:`ProgressCallback` when one is given and shows nothing
otherwise; :func:`progress_bar` turns a callback into a rich bar on stderr (the command line's,
or the library's with ``progress=True``).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator

ProgressCallback = Callable[[float, float], None]
"""``callback(done, total)``: how much of the work is done, in the unit the work counts (seconds
of data fused, systems simulated, runs finished)."""

REFRESH_S = 0.25
"""Least wall time (s) between two reports of one piece of work (the last one is always made)."""


@contextlib.contextmanager
def progress_bar(description: str, unit: str = "") -> Iterator[ProgressCallback]:
    """A rich progress bar on stderr, redrawn at most four times a second, as a callback; it stays
    on screen, complete, when the work ends (one line in a file or pipe). Its drawing thread runs
    from the first report to the last (``done >= total``) only: before and after it the process
    has one thread and may fork (:func:`~bodyfusion.base.forking.fork_is_safe`: a first run's
    kernels compiled ahead, outputs written beside each other)."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    suffix = f" {unit}" if unit else ""
    bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.fields[amount]}"),
                   TimeElapsedColumn(), console=Console(stderr=True), refresh_per_second=4)
    task = bar.add_task(description, total=None, amount="")
    drawing, finished = [False], [False]

    def update(done: float, total: float) -> None:
        if finished[0] and done >= total:  # told again that it is done: the bar stands complete already
            return
        if not drawing[0]:
            bar.start()
            drawing[0] = True
        bar.update(task, completed=done, total=total, amount=f"{done:.0f}/{total:.0f}{suffix}")
        finished[0] = done >= total
        if finished[0]:
            bar.stop()
            drawing[0] = False

    try:
        yield update
    finally:
        if drawing[0]:
            bar.stop()


@contextlib.contextmanager
def reporting(progress: bool | ProgressCallback | None, description: str,
              unit: str = "") -> Iterator[ProgressCallback | None]:
    """The callback a library call's ``progress`` argument asks for: the caller's own, a bar
    (``True``), or none."""
    if callable(progress):
        yield progress
    elif progress:
        with progress_bar(description, unit) as bar:
            yield bar
    else:
        yield None


class Throttled:
    """``callback`` called at most once per :data:`REFRESH_S` (and always for the last report,
    ``done == total``): cheap to call from a loop."""

    def __init__(self, callback: ProgressCallback) -> None:
        self.callback = callback
        self._last = -float("inf")

    def __call__(self, done: float, total: float) -> None:
        now = time.monotonic()
        if done >= total or now - self._last >= REFRESH_S:
            self._last = now
            self.callback(done, total)
