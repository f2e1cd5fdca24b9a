"""Studies: layouts × parameter overrides × GNSS outage windows × seeds, on a process pool or Dask.

A study file (YAML, strict; paths relative to the study file)::

    name: gnss_outage_study
    layouts:                                  # study name → a scenario or a recorded layout
      foot_hand: {scenario: foot_hand_gnss_outage.yaml}
      recorded:  {layout: my_walk.yaml, set: [truth.alignment=none]}
    parameters:                               # optional grid: any --set path → its values
      layout.fuser.method: [projection, none]
    outages:                                  # optional: one GNSS outage per run
      system: hand_phone                      # the system that loses GNSS
      start_s: 30                             # s on the system's clock (a layout may set outage_start_s)
      durations_s: [0, 10, 20, 30, 40, 60, 120]
    seeds: 20                                 # seeds 0..19, or a list of seeds

``parameters`` and ``set`` paths apply to the file the layout names: a scenario's paths
(``layout.fuser.method``, ``systems.hand_phone.gnss.white_sigma_m``) or a layout's
(``fuser.method``). The study's outage replaces the outage system's own: a scenario's
``systems.<system>.gnss.outages``, a recorded layout's ``outages`` entries for that
system; duration 0 means no outage (and the errors "at the end of the outage" are taken
at ``start_s``, with GNSS on, so the 0-s row is the baseline).

Each run is simulate-and-run (scenario: simulated into a temporary folder deleted
afterwards, then :func:`bodyfusion.core.run.run_layout` on the written ``config.yaml``) or a run of
a recorded layout, in-process, writing no trajectories or plots. Its key is the SHA-256
of the canonical JSON of the fully resolved file (after every override and the outage)
and the seed: a run done once is never done again in the same output folder.

Output folder (CONTRACT.md): ``results.parquet`` (one row per run: :data:`HEAD_COLUMNS`,
``param.<path>`` per parameter, the ``outage.*`` errors (:func:`bodyfusion.evaluation.metrics.outage_errors`),
metrics.json flattened with dots, ``runtime.*``: timings, CPU seconds and the worker's process
id), ``summary.csv`` (:func:`summarise`), PNG plots of the outage
errors against the outage duration, and ``study.json`` (counts and throughput).
Finished rows go to ``parts/`` in small Parquet files, each written whole and renamed
into place, and are compacted into ``results.parquet`` (deduplicated by run key) at the
end: a study killed at any moment loses no saved row, duplicates none, and resumes.
A failed run is saved too (``status`` ``failed``, ``error``) and, being deterministic, is
not retried on resume.

Executors: ``local``, a process pool of spawned workers; ``dask``, a Dask distributed
``LocalCluster`` (one process per worker, one thread each) or an existing cluster's
scheduler, whose workers must have this package installed. Workers run single-threaded
BLAS in both, so a run gives the same bits wherever it runs; only the ``runtime.*`` and
``constraints.solve_time_us.*`` columns (:func:`is_timing_column`) differ. Each worker
loads the compiled kernels from Numba's on-disk cache, which writes each entry to a
temporary file and renames it, so workers compiling at once do not corrupt it.
"""

from __future__ import annotations

import contextlib
import csv
import enum
import hashlib
import itertools
import json
import math
import os
import shutil
import sys
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import yaml
from pydantic import BaseModel, Field, ValidationError, field_validator, model_validator

from bodyfusion.core.layout import DataPath, Layout, StrictModel, apply_overrides, load_layout, read_yaml, validate_section
from bodyfusion.core.errors import ConfigError, FusionError

__all__ = [
    "Executor",
    "HEAD_COLUMNS",
    "ResultStore",
    "RunSpec",
    "StudyReport",
    "StudySpec",
    "execute_run",
    "expand_grid",
    "is_timing_column",
    "load_study",
    "run_study",
    "summarise",
]

HEAD_COLUMNS: dict[str, pa.DataType] = {
    "run_key": pa.string(),
    "layout": pa.string(),
    "source": pa.string(),
    "config": pa.string(),
    "seed": pa.int64(),
    "outage.system": pa.string(),
    "outage.start_s": pa.float64(),
    "outage.duration_s": pa.float64(),
    "status": pa.string(),
    "error": pa.string(),
}
"""The first columns of every row and their types (``param.<path>`` columns follow)."""

TIMING_PREFIXES = ("runtime.", "constraints.solve_time_us.")
"""Columns that measure time: they differ between runs of the same key; every other column
is a deterministic function of the run key."""

SUMMARY_METRICS = ("outage.end_error_m", "outage.max_error_m")
"""Summarised for every study with outages; each system's horizontal RMSE is added."""

RESULTS_FILE = "results.parquet"
SUMMARY_FILE = "summary.csv"
PARTS_DIR = "parts"


def is_timing_column(name: str) -> bool:
    """Whether a results column is a timing (see :data:`TIMING_PREFIXES`)."""
    return name.startswith(TIMING_PREFIXES)


# --------------------------------------------------------------------------- the study file


class StudyLayout(StrictModel):
    """One layout of the study: exactly one of ``scenario`` (simulated per run) or ``layout``
    (recorded data); ``set``: fixed overrides (KEY=VALUE); ``outage_start_s``: this layout's
    outage start, s (default the study's ``outages.start_s``)."""

    scenario: DataPath | None = None
    layout: DataPath | None = None
    set: list[str] = Field(default_factory=list)
    outage_start_s: float | None = Field(default=None, ge=0)

    @model_validator(mode="after")
    def _one_source(self) -> "StudyLayout":
        if (self.scenario is None) == (self.layout is None):
            raise ValueError("give exactly one of scenario or layout")
        return self

    @property
    def source(self) -> str:
        """``scenario`` or ``layout``: the key that names the file."""
        return "scenario" if self.scenario is not None else "layout"

    @property
    def file(self) -> Path:
        return self.scenario if self.scenario is not None else self.layout  # type: ignore[return-value]


class StudyOutages(StrictModel):
    """GNSS outage windows: the ``system`` loses GNSS at ``start_s`` (s) for each of ``durations_s`` (s; 0: none)."""

    system: str
    start_s: float = Field(ge=0)
    durations_s: list[float] = Field(min_length=1)

    @field_validator("durations_s")
    @classmethod
    def _durations(cls, v: list[float]) -> list[float]:
        if any(not math.isfinite(d) or d < 0 for d in v):
            raise ValueError("durations must be finite and >= 0 s")
        if len(set(v)) != len(v):
            raise ValueError("durations repeat")
        return v


class StudySpec(StrictModel):
    """The study file (module docstring)."""

    name: str | None = None
    layouts: dict[str, StudyLayout] = Field(min_length=1)
    parameters: dict[str, list[Any]] = Field(default_factory=dict)
    outages: StudyOutages | None = None
    seeds: int | list[int]

    @field_validator("parameters")
    @classmethod
    def _parameters(cls, v: dict[str, list[Any]]) -> dict[str, list[Any]]:
        for path, values in v.items():
            if not values:
                raise ValueError(f"{path}: give at least one value")
        return v

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, v: int | list[int]) -> int | list[int]:
        seeds = list(range(v)) if isinstance(v, int) else v
        if not seeds:
            raise ValueError("at least one seed is needed")
        if any(s < 0 for s in seeds):
            raise ValueError("seeds must be >= 0")
        if len(set(seeds)) != len(seeds):
            raise ValueError("seeds repeat")
        return v

    @property
    def seed_list(self) -> list[int]:
        return list(range(self.seeds)) if isinstance(self.seeds, int) else list(self.seeds)

    def outage_windows(self, entry: StudyLayout) -> list[tuple[str, float, float]]:
        """(system, start s, duration s) of each outage duration for one layout; empty without outages."""
        if self.outages is None:
            return []
        start = float(entry.outage_start_s if entry.outage_start_s is not None else self.outages.start_s)
        return [(self.outages.system, start, float(d)) for d in self.outages.durations_s]


@dataclass(frozen=True)
class LoadedStudy:
    """A validated study: its file, model and name."""

    path: Path
    spec: StudySpec

    @property
    def name(self) -> str:
        return self.spec.name or self.path.stem


# --------------------------------------------------------------------------- runs


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
        row.update({f"param.{k}": _param_cell(v) for k, v in self.params})
        return row


def _param_cell(value: Any) -> Any:
    """A parameter value as a Parquet cell: scalars as they are, anything else as JSON text."""
    return value if value is None or isinstance(value, (bool, int, float, str)) else json.dumps(value, sort_keys=True)


def canonical_json(value: Any) -> str:
    """Sorted keys, no spaces, shortest float repr: the same text for the same config in every process."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=False, default=str)


def run_key(source: str, resolved: dict[str, Any], seed: int) -> str:
    """SHA-256 (hex) of the fully resolved config and the seed."""
    return hashlib.sha256(canonical_json({"source": source, "config": resolved, "seed": seed}).encode()).hexdigest()


def _outage_override(source: str, raw: dict[str, Any], system: str, start_s: float, duration_s: float) -> str:
    """The override that gives ``system`` exactly one outage (none for duration 0)."""
    window = [{"start_s": start_s, "duration_s": duration_s}] if duration_s > 0 else []
    if source == "scenario":
        return _override_text(f"systems.{system}.gnss.outages", window)
    others = [o for o in raw.get("outages") or [] if not (isinstance(o, dict) and o.get("system") == system)]
    return _override_text("outages", others + [{"system": system, **w} for w in window])


def _params_grid(parameters: dict[str, list[Any]]) -> list[tuple[tuple[str, Any], ...]]:
    paths = list(parameters)
    return [tuple(zip(paths, values)) for values in itertools.product(*(parameters[p] for p in paths))]


def _yaml_text(value: Any) -> str:
    """``value`` as one line of YAML that :func:`bodyfusion.core.layout.parse_override` reads back as it is."""
    return yaml.safe_dump(value, default_flow_style=True, width=2**31).removesuffix("\n...\n").strip()


def _override_text(path: str, value: Any) -> str:
    return f"{path}={_yaml_text(value)}"


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
            base = [*entry.set, *(_override_text(p, v) for p, v in params)]
            base_raw = apply_overrides(raw, base)
            for outage in outages:
                overrides = base if outage is None else [*base, _outage_override(source, base_raw, *outage)]
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


# --------------------------------------------------------------------------- validation


def _refuse(study: LoadedStudy, key: str, err: FusionError) -> ConfigError:
    return ConfigError(key, str(err), study.path)


def _check_scenario(study: LoadedStudy, name: str, entry: StudyLayout, overrides: list[str], blame: str,
                    outage: tuple[str, float, float] | None) -> None:
    """Load the scenario with ``overrides`` (and the outage's), its ``layout`` section checked
    against the layout model; the outage's system must have GNSS and the outage fit the walk."""
    from bodyfusion.core.registry import get_registry
    from bodyfusion.sim.gait import plan_gait
    from bodyfusion.sim.scenario import SYSTEM_KINDS, load_scenario

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
        overrides = [*overrides, _outage_override("scenario", raw, *outage)]
    try:
        loaded = load_scenario(entry.file, overrides)
        lay = loaded.scenario.layout
        systems = lay.get("systems") or {}
        skeleton = {**lay, "systems": {n: {"plugin": "-", **(systems.get(n) or {})} for n in loaded.systems}}
        validate_section(Layout, skeleton, key="layout", path=entry.file, base_dir=entry.file.parent)
        for system, section in systems.items():
            plugin = SYSTEM_KINDS[loaded.systems[system].kind].plugin
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
        extra = [] if outage is None else [_outage_override("layout", raw, *outage)]
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
                check(study, name, entry, [*entry.set, _override_text(path, value)], f"parameters.{path}", outage)


def load_study(path: str | Path) -> LoadedStudy:
    """Read and validate a study file, every layout and override in it (no run starts)."""
    path = Path(path)
    spec = validate_section(StudySpec, read_yaml(path), key="", path=path, base_dir=path.resolve().parent)
    study = LoadedStudy(path, spec)
    validate_study(study)
    return study


# --------------------------------------------------------------------------- one run (in a worker)


def flatten(doc: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dicts → one level with dotted keys; lists become JSON text."""
    out: dict[str, Any] = {}
    for key, value in doc.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten(value, f"{name}."))
        elif isinstance(value, (list, tuple)):
            out[name] = json.dumps(value)
        else:
            out[name] = value
    return out


def _error_text(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    first = text[0] if text else ""
    return first if isinstance(err, FusionError) else f"{type(err).__name__}: {first}"


def _run_result(spec: RunSpec, tmp: Path) -> tuple[Any, float]:
    """(RunResult, simulation seconds) of one run; a scenario is simulated into ``tmp``."""
    from bodyfusion.core.run import run_layout

    if spec.source == "layout":
        return run_layout(load_layout(spec.file, list(spec.overrides)), spec.seed), 0.0
    from bodyfusion.sim import simulate

    t0 = time.perf_counter()
    sim = simulate(Path(spec.file), tmp, seed=spec.seed, overrides=list(spec.overrides))
    sim_s = time.perf_counter() - t0
    return run_layout(load_layout(sim.config_path), spec.seed), sim_s


def execute_run(spec: RunSpec) -> dict[str, Any]:
    """Run one grid point in this process and return its row; a failure becomes a row with
    ``status`` ``failed`` and the error's first line."""
    from bodyfusion.evaluation.metrics import outage_errors
    from bodyfusion.core.output import metrics_document

    t0, cpu0 = time.perf_counter(), time.process_time()
    row = spec.head()
    tmp = tempfile.mkdtemp(prefix="fusion-study-")
    try:
        try:
            result, sim_s = _run_result(spec, Path(tmp))
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        run_s = time.perf_counter() - t0 - sim_s
        body: dict[str, Any] = {}
        if spec.outage is not None:
            system, start, duration = spec.outage
            truth = result.truths.get(system)
            errs = (outage_errors(result.trajectories[system], truth, result.transform, start, duration)
                    if truth is not None and system in result.trajectories else {})
            body.update({f"outage.{k}": errs.get(k, float("nan")) for k in ("end_error_m", "max_error_m", "end_t_s")})
        body.update(flatten(metrics_document(result, spec.label, run_s)))
        body["runtime.simulate_s"] = sim_s
        row.update(status="ok", error=None)
        row.update({k: v for k, v in body.items() if k not in row})
    except Exception as err:  # noqa: BLE001 - a failing run is recorded and the study goes on
        row.update(status="failed", error=_error_text(err).replace(tmp, "<simulated>"))  # same text everywhere
    row["runtime.run_s"] = time.perf_counter() - t0
    row["runtime.cpu_s"] = time.process_time() - cpu0
    row["runtime.pid"] = os.getpid()
    return row


# --------------------------------------------------------------------------- storage


def _table(rows: list[dict[str, Any]]) -> pa.Table:
    """Rows → a table: head columns with fixed types, the others inferred, missing cells null."""
    names = list(HEAD_COLUMNS)
    for row in rows:
        names.extend(k for k in row if k not in names)
    arrays = []
    for name in names:
        cells = [row.get(name) for row in rows]
        arrays.append(pa.array(cells, type=HEAD_COLUMNS.get(name)))
    return pa.Table.from_arrays(arrays, names=names)


def _write_atomic(table: pa.Table, path: Path) -> None:
    """Write whole, fsync, then rename into place: a reader sees the old file or the new one."""
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    with tmp.open("wb") as fh:
        pq.write_table(table, fh)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


class ResultStore:
    """The rows of a study folder: ``parts/`` (one file per batch) and ``results.parquet``."""

    def __init__(self, out_dir: Path) -> None:
        self.out_dir = Path(out_dir)
        self.parts_dir = self.out_dir / PARTS_DIR
        self.results_path = self.out_dir / RESULTS_FILE
        self._seq = 0
        try:
            self.parts_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise FusionError(f"{self.out_dir}: cannot create output folder: {err.strerror}") from None

    def _files(self) -> list[Path]:
        """Saved files, oldest first: results.parquet, then the parts by name (time-stamped)."""
        for stale in self.parts_dir.glob(".*.tmp"):  # half-written by a killed study
            stale.unlink(missing_ok=True)
        parts = sorted(self.parts_dir.glob("part-*.parquet"))
        return ([self.results_path] if self.results_path.is_file() else []) + parts

    def keys(self) -> set[str]:
        """Run keys already saved."""
        return {k for f in self._files() for k in pq.read_table(f, columns=["run_key"]).column(0).to_pylist()}

    def append(self, rows: list[dict[str, Any]]) -> None:
        """Save a batch of rows as one new part file."""
        if not rows:
            return
        self._seq += 1
        stamp = time.strftime("%Y%m%dT%H%M%S", time.gmtime())
        _write_atomic(_table(rows), self.parts_dir / f"part-{stamp}-{os.getpid()}-{self._seq:06d}.parquet")

    def compact(self, order: dict[str, int]) -> pa.Table:
        """Merge every saved file into results.parquet: one row per run key (the first saved),
        sorted by ``order`` (run key → grid index; other keys last), timing columns last;
        then remove the merged parts."""
        files = self._files()
        if not files:
            return _table([])
        table = pa.concat_tables([pq.read_table(f) for f in files], promote_options="permissive")
        keys = table.column("run_key").to_pylist()
        first: dict[str, int] = {}
        for i, k in enumerate(keys):
            first.setdefault(k, i)
        rank = sorted(first, key=lambda k: (order.get(k, len(order)), k))
        table = table.take(pa.array([first[k] for k in rank], type=pa.int64()))
        names = table.column_names
        head = [n for n in names if n in HEAD_COLUMNS or n.startswith("param.")]
        rest = [n for n in names if n not in head and not is_timing_column(n)]
        table = table.select(head + rest + [n for n in names if is_timing_column(n)])
        _write_atomic(table, self.results_path)
        for f in files:
            if f != self.results_path:
                f.unlink(missing_ok=True)
        return table


# --------------------------------------------------------------------------- executors


class Executor(str, enum.Enum):
    """Where runs execute: a local process pool or a Dask distributed cluster."""

    local = "local"
    dask = "dask"


_SINGLE_THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
"""Worker processes run single-threaded BLAS, as Dask's nanny starts its workers, so both
executors compute the same bits."""


@contextlib.contextmanager
def _worker_environment() -> Iterator[None]:
    saved = {k: os.environ.get(k) for k in _SINGLE_THREAD_ENV}
    os.environ.update(_SINGLE_THREAD_ENV)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _run_local(specs: list[RunSpec], workers: int, on_row: Callable[[dict[str, Any]], None]) -> None:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        with _worker_environment():  # workers are spawned as the first runs are submitted
            futures = [pool.submit(execute_run, s) for s in specs]
        for fut in as_completed(futures):
            on_row(fut.result())
    except BrokenProcessPool:
        raise FusionError("a worker process died; the finished runs are saved: run the study again to resume") \
            from None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _run_dask(specs: list[RunSpec], workers: int, scheduler: str | None,
              on_row: Callable[[dict[str, Any]], None]) -> None:
    import logging

    import dask
    from distributed import Client, LocalCluster, as_completed

    with contextlib.ExitStack() as stack:
        if scheduler is None:
            # the same worker environment as the local pool: Dask's default also sets
            # MALLOC_TRIM_THRESHOLD_=65536, which makes these runs ~30 % slower
            stack.enter_context(dask.config.set({"distributed.nanny.pre-spawn-environ": _SINGLE_THREAD_ENV}))
            cluster = stack.enter_context(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                       dashboard_address=None, silence_logs=logging.ERROR))
            client = stack.enter_context(Client(cluster))
        else:
            try:
                client = stack.enter_context(Client(scheduler, timeout="30s"))
            except (OSError, TimeoutError) as err:
                raise FusionError(f"--scheduler {scheduler}: cannot connect: {err}") from None
        futures = client.map(execute_run, specs, key=[f"fusion-run-{s.key}" for s in specs])
        by_key = {f.key: s for f, s in zip(futures, specs)}
        for fut in as_completed(futures):
            if fut.status == "finished":
                on_row(fut.result())
            else:  # the worker itself died running it (e.g. out of memory)
                row = by_key[fut.key].head()
                row.update(status="failed", error=_error_text(fut.exception()))
                on_row(row)
            fut.release()


# --------------------------------------------------------------------------- summary


def _group_key(row: dict[str, Any], params: list[str]) -> tuple:
    return (row["layout"], *(row.get(p) for p in params), row.get("outage.duration_s"))


def summarise(rows: list[dict[str, Any]], params: list[str]) -> list[dict[str, Any]]:
    """Per layout, parameter values and outage duration, per metric (:data:`SUMMARY_METRICS`
    and every ``systems.<name>.horizontal_error_m.rmse``): runs, failed, mean, sd (n − 1),
    p50, p90 of the finite values of the runs that succeeded (m)."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(_group_key(row, params), []).append(row)
    out = []
    for key, members in groups.items():
        ok = [r for r in members if r["status"] == "ok"]
        rmse = sorted({k for r in ok for k in r if k.startswith("systems.") and k.endswith(".horizontal_error_m.rmse")})
        metrics = [m for m in [*SUMMARY_METRICS, *rmse] if any(r.get(m) is not None for r in ok)]
        for metric in metrics:
            v = np.array([r.get(metric) for r in ok], dtype=float)
            v = v[np.isfinite(v)]
            stats = {"mean": float(np.mean(v)), "sd": float(np.std(v, ddof=1)) if v.size > 1 else float("nan"),
                     "p50": float(np.percentile(v, 50)), "p90": float(np.percentile(v, 90))} if v.size else \
                dict.fromkeys(("mean", "sd", "p50", "p90"), float("nan"))
            first = members[0]
            out.append({"layout": key[0], **{p: first.get(p) for p in params},
                        "outage_system": first.get("outage.system"), "outage_start_s": first.get("outage.start_s"),
                        "outage_duration_s": key[-1], "metric": metric, "runs": int(v.size),
                        "failed": len(members) - len(ok), **stats})
    return out


def _write_summary(path: Path, summary: list[dict[str, Any]]) -> None:
    if not summary:
        path.write_text("")
        return
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(summary[0]))
        writer.writeheader()
        for rec in summary:
            writer.writerow({k: ("" if v is None or (isinstance(v, float) and math.isnan(v)) else v)
                             for k, v in rec.items()})


def _write_plots(out_dir: Path, rows: list[dict[str, Any]], params: list[str]) -> list[Path]:
    """One PNG per outage metric: its value against the outage duration, one curve per layout
    and parameter set."""
    from bodyfusion.evaluation.plots import plot_against_outage_duration

    written = []
    for metric, title in (("outage.end_error_m", "Horizontal error at the end of the GNSS outage"),
                          ("outage.max_error_m", "Largest horizontal error during the GNSS outage")):
        curves: dict[str, dict[float, list[float]]] = {}
        for row in rows:
            if row["status"] != "ok" or row.get("outage.duration_s") is None or row.get(metric) is None:
                continue
            label = " ".join([row["layout"], *(f"{p[len('param.'):]}={row.get(p)}" for p in params)])
            curves.setdefault(label, {}).setdefault(float(row["outage.duration_s"]), []).append(float(row[metric]))
        if curves:
            path = out_dir / f"{metric.split('.', 1)[1].removesuffix('_m')}_vs_outage.png"
            system = next(r["outage.system"] for r in rows if r.get("outage.system"))
            plot_against_outage_duration(path, curves, f"{title} ({system})")
            written.append(path)
    return written


# --------------------------------------------------------------------------- the study


@dataclass
class StudyReport:
    """What a study did: counts, wall time (s), throughput of the runs executed (runs/s), files."""

    out_dir: Path
    total: int
    done: int = 0
    failed: int = 0
    skipped: int = 0
    wall_s: float = 0.0
    executor: str = "local"
    workers: int = 1
    files: list[Path] = field(default_factory=list)

    @property
    def runs_per_s(self) -> float:
        executed = self.done + self.failed
        return executed / self.wall_s if self.wall_s > 0 else 0.0


def _progress(total: int) -> Any:
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    console = Console(stderr=True)
    return Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TextColumn("{task.fields[done]} done · {task.fields[failed]} failed · {task.fields[skipped]} "
                               "skipped"), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                    console=console, disable=not sys.stderr.isatty(), transient=False)


def run_study(study_path: str | Path, out_dir: str | Path, executor: Executor | str = Executor.local,
              workers: int | None = None, scheduler: str | None = None, batch_rows: int = 16,
              flush_s: float = 5.0) -> StudyReport:
    """Validate the study, run every run not yet saved in ``out_dir``, compact, summarise, plot.

    ``workers``: processes (local pool or LocalCluster; default all cores); ``scheduler``: a
    Dask scheduler address (``tcp://host:port``; only with ``executor='dask'``). Finished rows
    are saved every ``batch_rows`` rows or ``flush_s`` seconds, whichever comes first.
    """
    executor = Executor(executor)
    workers = workers if workers is not None else os.cpu_count() or 1
    if workers < 1:
        raise ConfigError("--workers", f"must be >= 1, got {workers}")
    if scheduler is not None and executor is not Executor.dask:
        raise ConfigError("--scheduler", "only with --executor dask")
    study = load_study(study_path)
    grid = expand_grid(study)
    order = {s.key: i for i, s in enumerate(grid)}
    store = ResultStore(Path(out_dir))
    saved = store.keys()
    todo = [s for s in grid if s.key not in saved]
    report = StudyReport(Path(out_dir), len(grid), skipped=len(grid) - len(todo), executor=executor.value,
                         workers=workers)
    pending: list[dict[str, Any]] = []
    last_flush = time.monotonic()
    t0 = time.perf_counter()
    with _progress(len(grid)) as progress:
        task = progress.add_task(study.name, total=len(grid), completed=report.skipped, done=0, failed=0,
                                 skipped=report.skipped)

        def on_row(row: dict[str, Any]) -> None:
            nonlocal last_flush
            pending.append(row)
            if row["status"] == "ok":
                report.done += 1
            else:
                report.failed += 1
            progress.update(task, advance=1, done=report.done, failed=report.failed)
            if len(pending) >= batch_rows or time.monotonic() - last_flush >= flush_s:
                store.append(pending)
                pending.clear()
                last_flush = time.monotonic()

        try:
            if todo and executor is Executor.local:
                _run_local(todo, min(workers, len(todo)), on_row)
            elif todo:
                _run_dask(todo, workers, scheduler, on_row)
        finally:
            store.append(pending)  # also when interrupted: nothing finished is lost
    report.wall_s = time.perf_counter() - t0
    table = store.compact(order)
    in_grid = [r for r in table.to_pylist() if r["run_key"] in order]
    params = [f"param.{p}" for p in study.spec.parameters]
    out = Path(out_dir)
    _write_summary(out / SUMMARY_FILE, summarise(in_grid, params))
    report.files = [store.results_path, out / SUMMARY_FILE, *_write_plots(out, in_grid, params)]
    (out / "study.json").write_text(json.dumps({
        "study": str(study_path), "name": study.name, "runs": report.total, "done": report.done,
        "failed": report.failed, "skipped": report.skipped, "executor": report.executor, "workers": workers,
        "wall_s": report.wall_s, "runs_per_s": report.runs_per_s}, indent=2) + "\n")
    return report
