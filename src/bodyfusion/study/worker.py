"""The runs of a study, in a worker process: a task of grid points in, one results row per run out.

A scenario is simulated in memory (:func:`bodyfusion.sim.simulated`) and
:func:`bodyfusion.runner.batch.run_layout` runs its layout on the tables the files would hold (the
same bits as the written files, none written); a recorded layout is run as it is. Both
in-process, writing no trajectories or plots unless the study asks for each run's files
(``run_outputs``: :attr:`~bodyfusion.study.grid.RunSpec.run_dir`). Within a task
(:func:`execute_runs`), runs that simulate the same data (the same
:attr:`~bodyfusion.study.grid.RunSpec.data_key`: they differ only in the scenario's
``layout`` section and the outage) simulate once: the others take the same walk and data
under their own layout and outage (:meth:`bodyfusion.sim.Simulated.relaid`), with the same
bits as their own simulation; the shared tables are read-only, so a run cannot change
another's input. The row holds the run's head columns
(:meth:`bodyfusion.study.grid.RunSpec.head`), ``system_names``, the ``outage.*`` errors
(:func:`bodyfusion.evaluation.metrics.outage_errors`), metrics.json flattened with dots
(lists as typed list cells, :func:`bodyfusion.study.results.cell`) and the ``runtime.*``
columns (timings, CPU seconds, the worker's process id, whether the run reused another's
simulation). A failing run becomes a row with ``status`` ``failed`` and its error's first line.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bodyfusion.base.errors import FusionError
from bodyfusion.core.layout import load_layout, validate_layout
from bodyfusion.outputs.write import metrics_document, write_outputs
from bodyfusion.runner import run_layout
from bodyfusion.evaluation.metrics import outage_errors
from bodyfusion.sim import Simulated, load_scenario, simulated
from bodyfusion.study.grid import RunSpec
from bodyfusion.study.results import cell


def flatten(doc: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dicts → one level with dotted keys; lists become typed list cells (:func:`cell`)."""
    out: dict[str, Any] = {}
    for key, value in doc.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten(value, f"{name}."))
        elif isinstance(value, (list, tuple)):
            out[name] = cell(value)
        else:
            out[name] = value
    return out


def error_text(err: BaseException) -> str:
    """The ``error`` cell of a failed run: the first line, with the exception type unless it is a FusionError."""
    text = str(err).strip().splitlines()
    first = text[0] if text else ""
    return first if isinstance(err, FusionError) else f"{type(err).__name__}: {first}"


class SharedSimulation:
    """The simulation the runs of a task share: the last one made, under its data key."""

    def __init__(self) -> None:
        self.key: str | None = None
        self.sim: Simulated | None = None

    def get(self, spec: RunSpec) -> tuple[Simulated, bool]:
        """``spec``'s simulated walk and whether it was reused: simulated afresh, or the shared
        one under ``spec``'s own layout and outage when it has the same data key."""
        overrides = list(spec.overrides)
        if spec.data_key is None or spec.data_key != self.key or self.sim is None:
            self.key, self.sim = None, None  # a failure below leaves nothing half made
            sim = simulated(Path(spec.file), seed=spec.seed, overrides=overrides)
            for out in sim.outputs.values():
                for file in out.files:
                    for column in file.columns.values():
                        column.flags.writeable = False
            self.key, self.sim = spec.data_key, sim
            return sim, False
        loaded = load_scenario(Path(spec.file), overrides)
        outages = {}
        if spec.outage is not None:
            system = spec.outage[0]
            outages[system] = [(o.start_s, o.duration_s) for o in loaded.systems[system].gnss.outages]
        return self.sim.relaid(loaded, overrides, outages), True


def _run_result(spec: RunSpec, shared: SharedSimulation) -> tuple[Any, float, bool, Simulated | None]:
    """(RunResult, simulation seconds, simulation reused, the simulated walk) of one run."""
    if spec.source == "layout":
        return run_layout(load_layout(spec.file, list(spec.overrides)), spec.seed), 0.0, False, None
    t0 = time.perf_counter()
    sim, reused = shared.get(spec)
    sim_s = time.perf_counter() - t0
    layout, tables = sim.in_memory()
    loaded = validate_layout(layout, None, Path(spec.file).parent, tables=tables)
    return run_layout(loaded, spec.seed), sim_s, reused, sim


def _write_run(spec: RunSpec, result: Any, sim: Simulated | None, wall_s: float) -> None:
    """The run's files in ``spec.run_dir``: the simulated data, truth and config.yaml (a
    scenario), then what ``fusion run`` writes (trajectories, metrics.json, plots)."""
    run_dir = Path(spec.run_dir or ".")
    if sim is not None:
        sim.write(run_dir, overwrite=True)  # the study's own run folder: a resumed run writes it again
    write_outputs(result, run_dir, spec.label, wall_s)


def execute_run(spec: RunSpec, shared: SharedSimulation | None = None) -> dict[str, Any]:
    """Run one grid point in this process and return its row (``shared``: the task's shared
    simulation); a failure becomes a row with ``status`` ``failed`` and the error's first line."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    row = spec.head()
    reused = False
    try:
        result, sim_s, reused, sim = _run_result(spec, shared if shared is not None else SharedSimulation())
        run_s = time.perf_counter() - t0 - sim_s
        body: dict[str, Any] = {}
        if spec.outage is not None:
            system, start, duration = spec.outage
            truth = result.truths.get(system)
            errs = (outage_errors(result.trajectories[system], truth, result.transform, start, duration)
                    if truth is not None and system in result.trajectories else {})
            body.update({f"outage.{k}": errs.get(k, float("nan")) for k in ("end_error_m", "max_error_m", "end_t_s")})
        doc = metrics_document(result, spec.label, run_s)
        body["system_names"] = list(doc["systems"])
        body.update(flatten(doc))
        body["runtime.simulate_s"] = sim_s
        if spec.run_dir is not None:
            _write_run(spec, result, sim, time.perf_counter() - t0)
        row.update(status="ok", error=None)
        row.update({k: v for k, v in body.items() if k not in row})
    except Exception as err:  # noqa: BLE001 - a failing run is recorded and the study goes on
        row.update(status="failed", error=error_text(err))
    row["runtime.run_s"] = time.perf_counter() - t0
    row["runtime.cpu_s"] = time.process_time() - cpu0
    row["runtime.pid"] = os.getpid()
    row["runtime.simulation_reused"] = reused
    return row


def execute_runs(specs: Sequence[RunSpec]) -> list[dict[str, Any]]:
    """Run a task's grid points in this process, in order, and return their rows; runs with the
    same data key simulate once (the module docstring)."""
    shared = SharedSimulation()
    return [execute_run(spec, shared) for spec in specs]
