"""The study's grid: every run (layout × parameter values × outage duration × seed) and its key.

Each run is the file its layout names with KEY=VALUE overrides: the layout's fixed ``set``,
the parameter values, then the study's outage (which replaces the outage system's own).
Its key is the SHA-256 of the canonical JSON of the fully resolved file (after every
override and the outage) and the seed: a run done once is never done again in the same
output folder, and two grid points that resolve to the same run are refused.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
from dataclasses import dataclass
from typing import Any

import yaml

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import apply_overrides, read_yaml
from bodyfusion.study.results import cell
from bodyfusion.study.spec import LoadedStudy


@dataclass(frozen=True)
class RunSpec:
    """One run of the grid: everything a worker needs, nothing it must look up.

    ``file``: the scenario or layout (absolute path); ``overrides``: KEY=VALUE, the
    parameters then the outage; ``params``: parameter path → value; ``outage``: (system,
    start s, duration s) or None; ``label``: the file as the study names it.
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
                                        seed, params, outage))
    return runs
