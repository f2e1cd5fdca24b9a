"""One colour per system (or study curve), the same in every figure of a run, PNG and HTML alike.

The palette is matplotlib's ``tab10`` as hex (its ``C0`` … ``C9``); a colour is given by a name's
place in the run's whole list of systems, not in what one figure draws, so a system keeps its
colour in a figure that leaves another system out (one without truth, say).
"""

from __future__ import annotations

from collections.abc import Iterable

from bodyfusion.evaluation.scored_run import ScoredRun

PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
           "#17becf")
"""matplotlib's tab10."""


def colours(names: Iterable[str]) -> dict[str, str]:
    """Name → ``#rrggbb``, by each name's first place in ``names``."""
    return {name: PALETTE[k % len(PALETTE)] for k, name in enumerate(dict.fromkeys(names))}


def system_colours(run: ScoredRun) -> dict[str, str]:
    """Every system of ``run`` (its estimates, then what has truth, scores or a NEES track alone)
    → its colour."""
    return colours([*run.trajectories, *run.truths, *run.scores, *run.nees])
