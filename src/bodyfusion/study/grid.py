"""The study's grid: every run (layout × parameter values × outage duration × seed), its key,
and the tasks that carry the runs to the workers.

Each run is the file its layout names with KEY=VALUE overrides: the layout's fixed ``set``,
the parameter values, then the study's outage (which replaces the outage system's own).
Its key is the SHA-256 of the canonical JSON of the fully resolved file (after every
override and the outage) and the seed: a run done once is never done again in the same
output folder, and two grid points that resolve to the same run are refused.

Runs of a scenario that differ only in the scenario's ``layout`` section and in the study's
outage simulate the same walk and data (:func:`data_key`): :func:`plan_tasks` puts them into
the same task, where the first simulates and the others reuse its data
(:meth:`bodyfusion.sim.Simulated.relaid`).
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import yaml

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout_io import apply_overrides, read_yaml
from bodyfusion.study.results import cell
from bodyfusion.study.spec import LoadedStudy


@dataclass(frozen=True)
class RunSpec:
    """One run of the grid: everything a worker needs, nothing it must look up.

    ``file``: the scenario or layout (absolute path); ``overrides``: KEY=VALUE, the
    parameters then the outage; ``params``: parameter path → value; ``outage``: (system,
    start s, duration s) or None; ``label``: the file as the study names it; ``data_key``:
    runs with the same one simulate the same data (:func:`data_key`; None: a recorded
    layout); ``run_dir``: where the run writes its files (None: it writes none).
    """

    key: str
    layout: str
    source: str
    file: str
    label: str
    overrides: tuple[str, ...]
    seed: int
    params: tuple[tuple[str, Any], ...] = ()
    outage: tuple[str, float, float] | None = None
    data_key: str | None = None
    run_dir: str | None = None

    def head(self) -> dict[str, Any]:
        """The row's leading columns (no status yet)."""
        system, start, duration = self.outage if self.outage is not None else (None, None, None)
        row: dict[str, Any] = {"run_key": self.key, "layout": self.layout, "source": self.source,
                               "config": self.label, "seed": self.seed, "outage.system": system,
                               "outage.start_s": start, "outage.duration_s": duration}
        row.update({f"param.{k}": cell(v) for k, v in self.params})
        return row


def canonical_json(value: Any) -> str:
    """Sorted keys, no spaces, shortest float repr: the same text for the same config in every process."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=False, default=str)


def run_key(source: str, resolved: dict[str, Any], seed: int) -> str:
    """SHA-256 (hex) of the fully resolved config and the seed."""
    return hashlib.sha256(canonical_json({"source": source, "config": resolved, "seed": seed}).encode()).hexdigest()


def data_key(source: str, resolved: dict[str, Any], outage: tuple[str, float, float] | None,
             seed: int) -> str | None:
    """SHA-256 (hex) of what a scenario run simulates: the resolved scenario without its
    ``layout`` section (merged over the simulated layout, never read by the simulation) and
    without the outage system's ``gnss.outages`` (they only mask its fixes in the layout), and
    the seed. None for a recorded layout (nothing is simulated)."""
    if source != "scenario":
        return None
    data = copy.deepcopy({k: v for k, v in resolved.items() if k != "layout"})
    if outage is not None:
        gnss = ((data.get("systems") or {}).get(outage[0]) or {}).get("gnss")
        if isinstance(gnss, dict):
            gnss.pop("outages", None)
    return hashlib.sha256(canonical_json({"data": data, "seed": seed}).encode()).hexdigest()


def _yaml_text(value: Any) -> str:
    """``value`` as one line of YAML that :func:`bodyfusion.core.layout.parse_override` reads back as it is."""
    return yaml.safe_dump(value, default_flow_style=True, width=2**31).removesuffix("\n...\n").strip()


def override_text(path: str, value: Any) -> str:
    """The KEY=VALUE override that sets ``path`` to ``value``."""
    return f"{path}={_yaml_text(value)}"


def outage_override(source: str, raw: dict[str, Any], system: str, start_s: float, duration_s: float) -> str:
    """The override that gives ``system`` exactly one outage (none for duration 0)."""
    window = [{"start_s": start_s, "duration_s": duration_s}] if duration_s > 0 else []
    if source == "scenario":
        return override_text(f"systems.{system}.gnss.outages", window)
    others = [o for o in raw.get("outages") or [] if not (isinstance(o, dict) and o.get("system") == system)]
    return override_text("outages", others + [{"system": system, **w} for w in window])


def _params_grid(parameters: dict[str, list[Any]]) -> list[tuple[tuple[str, Any], ...]]:
    paths = list(parameters)
    return [tuple(zip(paths, values)) for values in itertools.product(*(parameters[p] for p in paths))]


def expand_grid(study: LoadedStudy) -> list[RunSpec]:
    """Every run of the study, in grid order: layout, parameters, outage duration, seed."""
    spec = study.spec
    runs: list[RunSpec] = []
    seen: dict[str, str] = {}
    for name, entry in spec.layouts.items():
        source = entry.source
        raw = read_yaml(entry.file)
        label = os.path.relpath(entry.file, study.path.resolve().parent)
        outages: list[tuple[str, float, float] | None] = [*spec.outage_windows(entry)] or [None]
        for params in _params_grid(spec.parameters):
            base = [*entry.set, *(override_text(p, v) for p, v in params)]
            base_raw = apply_overrides(raw, base)
            for outage in outages:
                overrides = base if outage is None else [*base, outage_override(source, base_raw, *outage)]
                resolved = apply_overrides(raw, overrides)
                for seed in spec.seed_list:
                    key = run_key(source, resolved, seed)
                    where = f"layouts.{name} ({dict(params)}, outage {outage}, seed {seed})"
                    if key in seen:
                        raise ConfigError("layouts", f"{where} is the same run as {seen[key]}", study.path)
                    seen[key] = where
                    runs.append(RunSpec(key, name, source, str(entry.file.resolve()), label, tuple(overrides),
                                        seed, params, outage, data_key(source, resolved, outage, seed)))
    return runs


DEFAULT_RUNS_PER_TASK = 8
"""At most this many runs per task unless the study says otherwise (``runs_per_task``): the
seven outage durations of one seed of the shipped study share one simulation in one task;
fewer when the study has fewer than two tasks per worker."""


def plan_tasks(runs: Sequence[RunSpec], runs_per_task: int | None, workers: int) -> list[list[RunSpec]]:
    """The runs in tasks of at most ``runs_per_task`` (None: :data:`DEFAULT_RUNS_PER_TASK`,
    or fewer so that each worker gets two tasks): runs that simulate the same data (the same
    :attr:`RunSpec.data_key`) together, in the order their first run has in ``runs``; such
    a group larger than a task fills tasks of its own, smaller ones share a task. Every run
    is in exactly one task."""
    if runs_per_task is None:
        runs_per_task = max(1, min(DEFAULT_RUNS_PER_TASK, math.ceil(len(runs) / (2 * max(workers, 1)))))
    groups: dict[Any, list[RunSpec]] = {}
    for i, run in enumerate(runs):
        groups.setdefault(run.data_key if run.data_key is not None else i, []).append(run)
    tasks: list[list[RunSpec]] = []
    current: list[RunSpec] = []
    for group in groups.values():
        for lo in range(0, len(group), runs_per_task):
            part = group[lo:lo + runs_per_task]
            if current and len(current) + len(part) > runs_per_task:
                tasks.append(current)
                current = []
            current = current + part
    if current:
        tasks.append(current)
    return tasks
