"""Loading a study file and checking everything in it before the first run starts.

Every layout is loaded with its fixed overrides and the longest outage, then with every
parameter value: an unknown layout file, an override path that does not exist, an outage
system without GNSS or an outage past the end of the walk stop the study with one
:class:`~bodyfusion.base.errors.ConfigError` naming the study file, the study key and the
layout file's own key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from bodyfusion.base.errors import ConfigError, FusionError
from bodyfusion.core.layout import Layout, load_layout
from bodyfusion.core.layout_io import apply_overrides, read_yaml, validate_section
from bodyfusion.core.registry import get_registry
from bodyfusion.sim.gait import plan_gait
from bodyfusion.sim.scenario import load_scenario
from bodyfusion.study.grid import outage_override, override_text
from bodyfusion.study.spec import LoadedStudy, StudyLayout, StudySpec


def _refuse(study: LoadedStudy, key: str, err: FusionError) -> ConfigError:
    return ConfigError(key, str(err), study.path)


def _check_scenario(study: LoadedStudy, name: str, entry: StudyLayout, overrides: list[str], blame: str,
                    outage: tuple[str, float, float] | None) -> None:
    """Load the scenario with ``overrides`` (and the outage's), its ``layout`` section checked
    against the layout model; the outage's system must have GNSS and the outage fit the walk."""
    try:
        loaded = load_scenario(entry.file, overrides)
    except FusionError as err:
        raise _refuse(study, blame, err) from None
    if outage is not None:
        system, start, duration = outage
        cfg = loaded.systems.get(system)
        if cfg is None or getattr(cfg, "gnss", None) is None:
            raise ConfigError("outages.system", f"layouts.{name}: {entry.file.name} has no system {system!r} "
                              "with GNSS", study.path)
        if any(isinstance(o, dict) and o.get("system") == system for o in loaded.scenario.layout.get("outages") or []):
            raise ConfigError("outages.system", f"layouts.{name}: {entry.file.name} sets layout.outages for "
                              f"{system!r}; the study's outages replace them", study.path)
        walk_s = float(plan_gait(loaded.path.build(), loaded.scenario.gait, loaded.scenario.rate_hz).t[-1])
        if start + duration > walk_s:
            raise ConfigError("outages.durations_s", f"layouts.{name}: an outage from {start:g} s for {duration:g} s "
                              f"ends after the walk ({walk_s:.1f} s)", study.path)
        raw = apply_overrides(read_yaml(entry.file), overrides)
        overrides = [*overrides, outage_override("scenario", raw, *outage)]
    try:
        loaded = load_scenario(entry.file, overrides)
        lay = loaded.scenario.layout
        systems = lay.get("systems") or {}
        skeleton = {**lay, "systems": {n: {"plugin": "-", **(systems.get(n) or {})} for n in loaded.systems}}
        validate_section(Layout, skeleton, key="layout", path=entry.file, base_dir=entry.file.parent)
        for system, section in systems.items():
            plugin = loaded.kinds[system].plugin
            check_partial_section(get_registry().system_class(plugin).Config, section or {},
                                  f"layout.systems.{system}", entry.file)
    except FusionError as err:
        raise _refuse(study, blame, err) from None


def check_partial_section(model: type[BaseModel], section: dict[str, Any], key: str, path: Path) -> None:
    """Check the keys and values a scenario's ``layout.systems.<name>`` gives for a plugin
    section the simulator completes: unknown keys and bad values are refused; fields the
    simulator fills in (missing here) are not."""
    try:
        model.model_validate(section)
    except ValidationError as err:
        for e in err.errors():
            if e["type"] != "missing" and e["loc"]:  # whole-section checks need the completed section
                loc = ".".join(str(p) for p in e["loc"])
                raise ConfigError(f"{key}.{loc}", e["msg"], path) from None


def _check_layout(study: LoadedStudy, name: str, entry: StudyLayout, overrides: list[str], blame: str,
                  outage: tuple[str, float, float] | None) -> None:
    """Load the layout with ``overrides`` and the outage's (both validation stages)."""
    try:
        raw = apply_overrides(read_yaml(entry.file), overrides)
        if outage is not None and outage[0] not in (raw.get("systems") or {}):
            raise ConfigError("outages.system", f"layouts.{name}: {entry.file.name} has no system {outage[0]!r}",
                              study.path)
        extra = [] if outage is None else [outage_override("layout", raw, *outage)]
        load_layout(entry.file, [*overrides, *extra])
    except ConfigError as err:
        raise err if err.path == str(study.path) else _refuse(study, blame, err) from None
    except FusionError as err:
        raise _refuse(study, blame, err) from None


def validate_study(study: LoadedStudy) -> None:
    """Check every layout with its fixed overrides and the longest outage, then every
    parameter value on every layout, before any run: a bad key is refused naming the
    study file, the study key and the layout file's own key."""
    spec = study.spec
    for name, entry in spec.layouts.items():
        if not entry.file.is_file():
            raise ConfigError(f"layouts.{name}.{entry.source}", f"file not found: {entry.file}", study.path)
        check = _check_scenario if entry.source == "scenario" else _check_layout
        outage = max(spec.outage_windows(entry), key=lambda w: w[2], default=None)
        check(study, name, entry, list(entry.set), f"layouts.{name}", outage)
        for path, values in spec.parameters.items():
            for value in values:
                check(study, name, entry, [*entry.set, override_text(path, value)], f"parameters.{path}", outage)


def load_study(path: str | Path) -> LoadedStudy:
    """Read and validate a study file, every layout and override in it (no run starts)."""
    path = Path(path)
    spec = validate_section(StudySpec, read_yaml(path), key="", path=path, base_dir=path.resolve().parent)
    study = LoadedStudy(path, spec)
    validate_study(study)
    return study
