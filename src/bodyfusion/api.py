"""The library's entry points, re-exported at the package root: a layout from a YAML file, a dict
or pydantic models (:func:`load_layout`), a run in-process with data from files or in memory
(:func:`run`), a simulation handed over in memory (:func:`simulate`) and a study
(:func:`run_study`). A run's result has its tables as pandas
DataFrames (:class:`~bodyfusion.results.run_result.RunResult`)::

    import bodyfusion as bf

    layout = bf.load_layout("configs/dual_foot_vicon.yaml", {"fuser.method": "qp"})
    layout.smoother.kind = "rts"          # every field set is validated
    result = bf.run(layout)
    result.to_frame()                     # system, t, east_m, north_m, up_m, sd_..., v_..., heading_deg...

Errors in the input are the project's user errors (:class:`~bodyfusion.base.errors.ConfigError`,
:class:`~bodyfusion.base.errors.InputError`): one line naming the file or system and the key.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.progress import ProgressCallback, reporting
from bodyfusion.core import registry as plugin_registry
from bodyfusion.core.layout import LoadedLayout, validate_layout
from bodyfusion.core.layout_io import apply_overrides, plain, read_yaml
from bodyfusion.outputs.write import check_output_folder, write_outputs
from bodyfusion.results.run_result import RunResult
from bodyfusion.runner import run_layout
from bodyfusion.io.tables import tables_by_name

if TYPE_CHECKING:  # imported where used: pandas, the simulator and the study runner are slow to import
    import pandas as pd

    from bodyfusion.sim.scenario import SimulationResult
    from bodyfusion.study.runner import StudyReport

LayoutSource = str | Path | Mapping[str, Any] | BaseModel | LoadedLayout
"""What a layout is made from: a YAML file, a dict (its values may be pydantic section models),
a :class:`~bodyfusion.core.layout.Layout` model, or a loaded layout."""
Overrides = Mapping[str, Any] | Sequence[str] | None
"""Dotted keys set on the layout: ``{"fuser.method": "qp"}`` or ``["fuser.method=qp"]``."""


Data = Mapping[str, Any] | None
"""In-memory tables by system name: a table (a pandas DataFrame, a mapping of column name to
array, a numpy structured array) for the system's data section (the plugin's ``data_section``:
``data`` of a foot INS, ``imu`` of a hand PDR, ``ranges`` of a UWB tag), or a mapping of section
key → table (``{"imu": imu_frame, "gnss": fixes_frame}``)."""


def load_layout(source: LayoutSource, overrides: Overrides = None, *, data: Data = None, truth: Any = None,
                base_dir: str | Path | None = None) -> LoadedLayout:
    """A validated layout from ``source`` with ``overrides`` set, both validation stages done.

    Relative data paths resolve against the YAML file's folder, else ``base_dir`` (default: the
    current folder; a loaded layout keeps its own). The result is edited in place with every field
    validated (``layout.fuser.method = "qp"``, ``layout.systems["left_foot"].filter.kind = "ckf"``);
    a run checks the whole layout again.

    ``data``: in-memory tables by system (:data:`Data`), read with the layout's column names,
    units and checks as a file would be (a section given a table needs no ``path``; errors name
    the section and the row). ``truth``: one table read as the layout's truth section says (``long``
    by default: ``system``, ``t``, ``east_m``, ``north_m``, ``up_m``), or a mapping of system name →
    table (``t``, ``east_m``, ``north_m``, ``up_m``; ENU, m). A loaded layout keeps its tables."""
    if isinstance(source, (str, Path)):
        path = Path(source)
        raw, folder = read_yaml(path), path.resolve().parent
    elif isinstance(source, LoadedLayout):
        path, raw, folder = source.path, source.to_dict(), source.base_dir
    elif isinstance(source, (Mapping, BaseModel)):
        path, raw, folder = None, plain(source), Path.cwd()
    else:
        raise ConfigError("layout", f"a layout is a YAML path, a dict or a model, not {type(source).__name__}")
    folder = Path(base_dir).resolve() if base_dir is not None else folder
    try:
        raw = apply_overrides(raw, overrides or [])
        tables = {**(source.tables if isinstance(source, LoadedLayout) else {}), **_data_tables(raw, data)}
        if truth is not None:
            raw["truth"] = {**(raw.get("truth") or {"format": "long"}),
                            **({"format": "long"} if tables_by_name(truth) else {})}
            tables["truth"] = truth
    except ConfigError as err:
        raise ConfigError(err.key, err.reason, path) from None
    return validate_layout(raw, path, folder, tables=tables)


def _data_tables(raw: dict[str, Any], data: Data) -> dict[str, Any]:
    """Dotted section key → table for the in-memory ``data`` by system (:data:`Data`)."""
    systems = raw.get("systems") if isinstance(raw.get("systems"), dict) else {}
    tables: dict[str, Any] = {}
    for name, value in (data or {}).items():
        section = systems.get(name)
        if not isinstance(section, dict):
            raise ConfigError(f"data.{name}", f"not a system of the layout (have {sorted(systems)})")
        if tables_by_name(value):
            tables.update({f"systems.{name}.{key}": table for key, table in value.items()})
            continue
        cls = plugin_registry.get_registry().system_class(section.get("plugin"), key=f"systems.{name}.plugin")
        if cls.data_section is None:
            raise ConfigError(f"data.{name}", f"a {cls.plugin_name} system reads no data")
        tables[f"systems.{name}.{cls.data_section}"] = value
    return tables


def run(layout: LayoutSource, overrides: Overrides = None, *, data: Data = None, truth: Any = None, seed: int = 0,
        out_dir: str | Path | None = None, progress: bool | ProgressCallback = False,
        overwrite: bool = False) -> RunResult:
    """Run a layout in this process and return its result; ``data`` and ``truth`` in memory as
    :func:`load_layout` takes them (no file is written or read for them). With ``out_dir``, also
    write the outputs ``fusion run`` writes there (metrics.json, trajectories, plots), refusing a
    folder whose files of those names no earlier run wrote unless ``overwrite``, as ``fusion run``
    does. ``seed``
    seeds every random choice of the run (ensembles). ``progress``: ``True`` for a bar on stderr,
    or a callable told (seconds of data fused, seconds in all) as the fuser advances."""
    t0 = time.perf_counter()
    fresh = isinstance(layout, LoadedLayout) and not overrides and data is None and truth is None
    loaded = layout if fresh else load_layout(layout, overrides, data=data, truth=truth)
    if out_dir is not None:
        check_output_folder(Path(out_dir), overwrite)
    with reporting(progress, "fusing", "s of data") as told:
        result = run_layout(loaded, seed, told)
    if out_dir is not None:
        write_outputs(result, Path(out_dir), str(loaded.path or loaded.name), total_wall_s=time.perf_counter() - t0)
    return result


@dataclass
class Simulation:
    """A simulated walk held in memory (:func:`simulate`).

    ``layout``: a loaded layout whose sensor and truth sections read the tables below (run it
    with ``bodyfusion.run(sim.layout)``: no file is read or written); ``data``: system → section
    → DataFrame, the columns the sensor files would hold (10 significant digits, as printed, so
    the run equals ``fusion simulate`` + ``fusion run`` bit for bit); ``truth``: the truth.csv
    rows (``system``, ``t``, ``east_m``, ``north_m``, ``up_m``); ``distance_m`` walked in
    ``duration_s``; ``written``: what was written, when asked (:func:`simulate`'s ``out_dir``)."""

    layout: LoadedLayout
    data: dict[str, dict[str, pd.DataFrame]]
    truth: pd.DataFrame
    distance_m: float
    duration_s: float
    written: SimulationResult | None = None


def simulate(scenario: str | Path | Mapping[str, Any], overrides: Overrides = None, *, seed: int = 0,
             out_dir: str | Path | None = None, overwrite: bool = False,
             progress: bool | ProgressCallback = False) -> Simulation:
    """Simulate a scenario (a YAML file or a scenario dict; ``overrides`` as for layouts) and
    hand its streams over in memory with a layout that reads them (:class:`Simulation`). With
    ``out_dir`` the files ``fusion simulate`` writes are written there too, byte for byte (a
    folder holding files of those names refused unless ``overwrite``).
    ``progress``: ``True`` for a bar on stderr, or a callable told (systems simulated, systems)."""
    import pandas as pd

    from bodyfusion.sim.scenario import simulated

    with reporting(progress, "simulating", "systems") as told:
        sim = simulated(scenario, seed, overrides, told)
    raw, tables = sim.in_memory()
    frames = {key: pd.DataFrame(columns) for key, columns in tables.items()}
    folder = Path(scenario).resolve().parent if isinstance(scenario, (str, Path)) else Path.cwd()
    layout = validate_layout(raw, None, folder, tables=frames)
    data: dict[str, dict[str, pd.DataFrame]] = {}
    for key, frame in frames.items():
        if key != "truth":
            _, system, section = key.split(".", 2)
            data.setdefault(system, {})[section] = frame
    written = sim.write(out_dir, overwrite) if out_dir is not None else None
    return Simulation(layout, data, frames["truth"], sim.plan.distance_m, float(sim.plan.t[-1]), written)


def run_study(study: str | Path, out_dir: str | Path, *, executor: str = "local", workers: int | None = None,
              scheduler: str | None = None, progress: bool | ProgressCallback = False) -> StudyReport:
    """Run a study file (layouts × overrides × GNSS outages × seeds) into ``out_dir`` as ``fusion
    study`` does: ``results.parquet`` (read it with :func:`pandas.read_parquet`), ``summary.csv``,
    plots; a study already there is resumed. ``executor``: ``local`` (a process pool of
    ``workers``) or ``dask`` (a LocalCluster, or the cluster at ``scheduler``; ``pip install
    "bodyfusion[study]"``). ``progress``: ``True`` for a bar on stderr, or a callable told
    (runs finished, runs in all)."""
    from bodyfusion.study.runner import run_study as _run_study

    return _run_study(study, out_dir, executor, workers, scheduler, progress=progress)
