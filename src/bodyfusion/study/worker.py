"""One run of a study, in a worker process: one grid point in, one results row out.

A scenario is simulated in memory (:func:`bodyfusion.sim.simulated`) and
:func:`bodyfusion.core.run.run_layout` runs its layout on the tables the files would hold (the
same bits as the written files, none written); a recorded layout is run as it is. Both
in-process, writing no trajectories or plots. The row holds the run's
head columns (:meth:`bodyfusion.study.grid.RunSpec.head`), ``system_names``, the ``outage.*``
errors (:func:`bodyfusion.evaluation.metrics.outage_errors`), metrics.json flattened with dots
(lists as typed list cells, :func:`bodyfusion.study.results.cell`) and the ``runtime.*``
columns (timings, CPU seconds, the worker's process id). A failing run
becomes a row with ``status`` ``failed`` and its error's first line.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from bodyfusion.base.errors import FusionError
from bodyfusion.core.layout import load_layout, validate_layout
from bodyfusion.core.output import metrics_document
from bodyfusion.core.run import run_layout
from bodyfusion.evaluation.metrics import outage_errors
from bodyfusion.sim import simulated
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


def _run_result(spec: RunSpec) -> tuple[Any, float]:
    """(RunResult, simulation seconds) of one run; a scenario is simulated in memory."""
    if spec.source == "layout":
        return run_layout(load_layout(spec.file, list(spec.overrides)), spec.seed), 0.0
    t0 = time.perf_counter()
    sim = simulated(Path(spec.file), seed=spec.seed, overrides=list(spec.overrides))
    sim_s = time.perf_counter() - t0
    layout, tables = sim.in_memory()
    return run_layout(validate_layout(layout, None, Path(spec.file).parent, tables=tables), spec.seed), sim_s


def execute_run(spec: RunSpec) -> dict[str, Any]:
    """Run one grid point in this process and return its row; a failure becomes a row with
    ``status`` ``failed`` and the error's first line."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    row = spec.head()
    try:
        result, sim_s = _run_result(spec)
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
        row.update(status="ok", error=None)
        row.update({k: v for k, v in body.items() if k not in row})
    except Exception as err:  # noqa: BLE001 - a failing run is recorded and the study goes on
        row.update(status="failed", error=error_text(err))
    row["runtime.run_s"] = time.perf_counter() - t0
    row["runtime.cpu_s"] = time.process_time() - cpu0
    row["runtime.pid"] = os.getpid()
    return row
