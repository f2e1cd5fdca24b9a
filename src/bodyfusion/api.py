"""The library's entry points, re-exported at the package root: a layout from a YAML file, a dict
or pydantic models (:func:`load_layout`), a run in-process (:func:`run`), a simulation
(:func:`simulate`) and a study (:func:`run_study`). A run's result has its tables as pandas
DataFrames (:class:`~bodyfusion.core.result.RunResult`)::

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
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import (
    LoadedLayout,
    apply_overrides,
    plain,
    read_yaml,
    validate_layout,
)
from bodyfusion.core.output import write_outputs
from bodyfusion.core.result import RunResult
from bodyfusion.core.run import run_layout
from bodyfusion.study.runner import StudyReport
from bodyfusion.study.runner import run_study as _run_study

LayoutSource = str | Path | Mapping[str, Any] | BaseModel | LoadedLayout
"""What a layout is made from: a YAML file, a dict (its values may be pydantic section models),
a :class:`~bodyfusion.core.layout.Layout` model, or a loaded layout."""
Overrides = Mapping[str, Any] | Sequence[str] | None
"""Dotted keys set on the layout: ``{"fuser.method": "qp"}`` or ``["fuser.method=qp"]``."""


def load_layout(source: LayoutSource, overrides: Overrides = None, *, base_dir: str | Path | None = None) -> LoadedLayout:
    """A validated layout from ``source`` with ``overrides`` set, both validation stages done.

    Relative data paths resolve against the YAML file's folder, else ``base_dir`` (default: the
    current folder; a loaded layout keeps its own). The result is edited in place with every field
    validated (``layout.fuser.method = "qp"``, ``layout.systems["left_foot"].filter.kind = "ckf"``);
    a run checks the whole layout again."""
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
    except ConfigError as err:
        raise ConfigError(err.key, err.reason, path) from None
    tables = source.tables if isinstance(source, LoadedLayout) else {}
    return validate_layout(raw, path, folder, tables=tables)


def run(layout: LayoutSource, overrides: Overrides = None, *, seed: int = 0,
        out_dir: str | Path | None = None) -> RunResult:
    """Run a layout in this process and return its result; with ``out_dir``, also write the
    outputs ``fusion run`` writes there (metrics.json, trajectories, plots). ``seed`` seeds every
    random choice of the run (ensembles)."""
    t0 = time.perf_counter()
    loaded = layout if isinstance(layout, LoadedLayout) and not overrides else load_layout(layout, overrides)
    result = run_layout(loaded, seed)
    if out_dir is not None:
        write_outputs(result, Path(out_dir), str(loaded.path or loaded.name), total_wall_s=time.perf_counter() - t0)
    return result


def run_study(study: str | Path, out_dir: str | Path, *, executor: str = "local", workers: int | None = None,
              scheduler: str | None = None) -> StudyReport:
    """Run a study file (layouts × overrides × GNSS outages × seeds) into ``out_dir`` as ``fusion
    study`` does: ``results.parquet`` (read it with :func:`pandas.read_parquet`), ``summary.csv``,
    plots; a study already there is resumed. ``executor``: ``local`` (a process pool of
    ``workers``) or ``dask`` (a LocalCluster, or the cluster at ``scheduler``)."""
    return _run_study(study, out_dir, executor, workers, scheduler)
