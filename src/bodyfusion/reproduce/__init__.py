"""``fusion reproduce PAPER``: each source paper's experiment where its mechanism acts, the
paper's table beside ours (:mod:`bodyfusion.reproduce.table`), and what matches and why.

- ``s000`` [Deng2026], ``s001`` [Xu2024]: :mod:`bodyfusion.reproduce.dual_foot`;
- ``s002`` [KFSC2015]: :mod:`bodyfusion.reproduce.kfsc2015`;
- ``s004`` [Shen2025]: :mod:`bodyfusion.reproduce.shen2025`.

Every seed is simulated and run in memory; same seeds, same table.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.files import refuse_to_replace
from bodyfusion.reproduce.table import REPRODUCTION_FILES, Cell, write_reproduction

PAPERS = ("s000", "s001", "s002", "s004")
MAX_SEEDS = 1000
"""More seeds than this are refused (``--seeds``)."""
log = logging.getLogger(__name__)


def reproduce_paper(paper: str, seeds: int = 10, jobs: int = 1) -> tuple[list[Cell], str]:
    """``paper``'s cells and comparison text over ``seeds`` seeds on ``jobs`` processes."""
    if paper in ("s000", "s001"):
        from bodyfusion.reproduce.dual_foot import reproduce
        return reproduce(paper, seeds, jobs)
    if paper == "s002":
        from bodyfusion.reproduce.kfsc2015 import reproduce
        return reproduce(seeds, jobs)
    from bodyfusion.reproduce.shen2025 import reproduce
    return reproduce(seeds, jobs)


def reproduce(paper: str, out: str | Path, seeds: int = 10, jobs: int = 1, overwrite: bool = False) -> list[Cell]:
    """Reproduce ``paper`` (one of :data:`PAPERS`, or ``all``: each in turn) into ``out``:
    table.csv and README.md (:func:`~bodyfusion.reproduce.table.write_reproduction`; a folder
    holding either refused before the work unless ``overwrite``). Returns the cells."""
    if paper != "all" and paper not in PAPERS:
        raise ConfigError("PAPER", f"must be one of {', '.join(PAPERS)} or all, got {paper!r}")
    if not 1 <= seeds <= MAX_SEEDS:
        raise ConfigError("--seeds", f"must be 1 to {MAX_SEEDS}, got {seeds}")
    if jobs < 1:
        raise ConfigError("--jobs", f"must be at least 1, got {jobs}")
    refuse_to_replace(Path(out), REPRODUCTION_FILES, overwrite, "the reproduction")
    cells: list[Cell] = []
    texts = []
    for name in PAPERS if paper == "all" else (paper,):
        t0 = time.perf_counter()
        log.info("reproducing %s over %d seeds", name, seeds)
        paper_cells, text = reproduce_paper(name, seeds, jobs)
        cells += paper_cells
        texts.append(text + f"\n({name} took {time.perf_counter() - t0:.0f} s on {jobs} process(es).)\n")
    write_reproduction(Path(out), cells, "\n".join(texts))
    return cells
