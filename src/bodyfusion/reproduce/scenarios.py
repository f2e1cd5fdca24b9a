"""The scenarios the reproductions simulate (this package's copies of the repository's configs/),
simulated and run in memory, seed by seed, on a pool of worker processes."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from concurrent.futures import as_completed
from importlib.resources import as_file, files
from pathlib import Path
from typing import Any, TypeVar

from bodyfusion.core.layout import validate_layout
from bodyfusion.core.layout_io import apply_overrides
from bodyfusion.results.run_result import RunResult
from bodyfusion.runner import run_layout
from bodyfusion.sim.scenario import Simulated, simulated

T = TypeVar("T")


def scenario_file(name: str) -> Path:
    """The packaged scenario ``name`` (``fbrts_paper_sim.yaml``...) as a file path."""
    with as_file(files("bodyfusion.examples").joinpath("files", name)) as path:
        return Path(path)


def simulate(name: str, seed: int, overrides: Sequence[str] = ()) -> Simulated:
    """The packaged scenario ``name`` simulated in memory with ``seed`` and scenario ``overrides``."""
    return simulated(scenario_file(name), seed=seed, overrides=list(overrides))


def run_simulated(sim: Simulated, overrides: Sequence[str] = (), seed: int = 0) -> RunResult:
    """The layout of ``sim`` with ``overrides`` (``--set`` syntax) run in memory (filter seed ``seed``)."""
    layout, tables = sim.in_memory()
    loaded = validate_layout(apply_overrides(layout, list(overrides)), None, scenario_file(sim.loaded.file.name).parent,
                             tables=tables)
    return run_layout(loaded, seed)


def quietly(job: Callable[[int], T], seed: int) -> T:
    """``job(seed)`` with the package's log at errors only: a reproduction runs hundreds of
    layouts, and their notes (levelling windows, a layout run without its constraint) are
    the experiment's design, not news."""
    log = logging.getLogger("bodyfusion")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        return job(seed)
    finally:
        log.setLevel(level)


def over_seeds(job: Callable[[int], T], seeds: int, jobs: int) -> list[T]:
    """``job(seed)`` for seeds 0 … ``seeds`` − 1 (:func:`quietly`), in this process (``jobs`` 1)
    or on a pool of ``jobs`` workers; in seed order either way (each seed's result is its own:
    same bits)."""
    if jobs <= 1 or seeds <= 1:
        return [quietly(job, seed) for seed in range(seeds)]
    from bodyfusion.study.executors import worker_pool

    results: dict[int, Any] = {}
    with worker_pool(min(jobs, seeds)) as pool:
        futures = {pool.submit(quietly, job, seed): seed for seed in range(seeds)}
        for fut in as_completed(futures):
            results[futures[fut]] = fut.result()
    return [results[s] for s in range(seeds)]
