"""A study's rows on disk: resumable part files, results.parquet, the per-system view and the
summary table.

``results.parquet`` holds one row per run: :data:`HEAD_COLUMNS`, ``param.<path>`` per
parameter, the ``outage.*`` errors, metrics.json flattened with dots and the ``runtime.*``
columns. Cells are typed (:func:`cell`): numbers, text, lists of numbers as ``list<double>``,
lists of text as ``list<string>``, a parameter that is a mapping as a struct.
``results_by_system.parquet`` (:func:`by_system`) holds one row per run and system, that
system's metrics under their own names (``horizontal_error_m.rmse``...), so that
``pandas.read_parquet(path).groupby(["system", "param.<path>"])`` needs no reshaping.
Finished rows go to ``parts/`` in small Parquet files, each written whole and
renamed into place, and are compacted into ``results.parquet`` (deduplicated by run key)
at the end: a study killed at any moment loses no saved row, duplicates none, and
resumes; a saved file found corrupt (every Parquet page carries its checksum) is moved aside with
a warning and its runs run again. A failed run is saved too (``status`` ``failed``, ``error``) and, being
deterministic, is not retried on resume. ``summary.csv`` (:func:`summarise`) gives the
statistics of the outage errors and RMSEs per layout, parameter values and outage duration.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from bodyfusion.base.errors import FusionError
from bodyfusion.base.files import replaced_atomically
from bodyfusion.base.findings import Finding
from bodyfusion.base.types import LOG

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
    "system_names": pa.list_(pa.string()),
}
"""The first columns of every row and their types (``param.<path>`` columns follow);
``system_names``: the run's navigation systems (null for a failed run)."""

TIMING_PREFIXES = ("runtime.", "constraints.solve_time_us.")
"""Columns that measure time: they differ between runs of the same key; every other column
is a deterministic function of the run key."""

SUMMARY_METRICS = ("outage.end_error_m", "outage.max_error_m")
"""Summarised for every study with outages; each system's horizontal RMSE is added."""

RESULTS_FILE = "results.parquet"
BY_SYSTEM_FILE = "results_by_system.parquet"
SUMMARY_FILE = "summary.csv"
PARTS_DIR = "parts"
STUDY_NAMES = frozenset({BY_SYSTEM_FILE, SUMMARY_FILE, "runs", "report.html"})
"""What a study writes into its folder, beside its plots, results.parquet and parts/ (which make
the folder a study's)."""
PLOT_SUFFIX = "_vs_outage"
"""The end of a study plot's file stem (:mod:`bodyfusion.study.plots`)."""


def is_timing_column(name: str) -> bool:
    """Whether a results column is a timing (see :data:`TIMING_PREFIXES`)."""
    return name.startswith(TIMING_PREFIXES)


# --------------------------------------------------------------------------- storage


def cell(value: Any) -> Any:
    """A value as a typed Parquet cell: scalars and None as they are, a list of numbers as floats
    (``list<double>``), other lists and mappings item by item (``list<string>``, struct...)."""
    if isinstance(value, dict):
        return {k: cell(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        items = [cell(v) for v in value]
        if items and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in items):
            return [float(v) for v in items]
        return items
    return value


FINDINGS_TYPE = pa.list_(pa.struct([(f.name, pa.float64() if f.name in ("t_start", "t_end") else pa.string())
                                     for f in dataclasses.fields(Finding)]))
"""The type of every ``...health.findings`` column (:class:`~bodyfusion.base.findings.Finding`s):
fixed, so that runs with and without findings (whose cells alone would type as lists of null)
write parts that concatenate."""


def _column_type(name: str) -> pa.DataType | None:
    """A column's fixed type (head columns, findings), or None: inferred from its cells."""
    return HEAD_COLUMNS.get(name) or (FINDINGS_TYPE if name.endswith("health.findings") else None)


def _table(rows: list[dict[str, Any]]) -> pa.Table:
    """Rows → a table: head and findings columns with fixed types, the others inferred, missing
    cells null."""
    names = list(HEAD_COLUMNS)
    for row in rows:
        names.extend(k for k in row if k not in names)
    arrays = []
    for name in names:
        cells = [row.get(name) for row in rows]
        arrays.append(pa.array(cells, type=_column_type(name)))
    return pa.Table.from_arrays(arrays, names=names)


def _write_atomic(table: pa.Table, path: Path) -> None:
    """Write whole and fsync, then put in place in one step
    (:func:`~bodyfusion.base.files.replaced_atomically`): a reader sees the old file or the new one.
    Every data page carries its CRC (Parquet's page checksum), which :func:`read_saved` checks."""
    with replaced_atomically(path) as tmp, tmp.open("wb") as fh:
        pq.write_table(table, fh, write_page_checksum=True)
        fh.flush()
        os.fsync(fh.fileno())


def read_saved(path: Path, columns: list[str] | None = None) -> pa.Table | None:
    """A saved results file (a part or results.parquet), every page's checksum verified; None
    when it is corrupt (truncated, bytes flipped, not Parquet, no ``run_key``): it is then moved
    aside to ``corrupt-<name>`` beside it, with a warning, and the runs it held are not saved
    (a resumed study runs them again)."""
    try:
        table = pq.read_table(path, columns=columns, page_checksum_verification=True)
        if "run_key" not in table.column_names:
            raise ValueError("it has no run_key column")
        return table
    except (OSError, ValueError, pa.ArrowException) as err:
        aside = path.with_name(f"corrupt-{path.name}")
        path.replace(aside)
        LOG.warning("%s is corrupt (%s); moved to %s, its runs will run again", path, _first_line(err), aside.name)
        return None


def _first_line(err: BaseException) -> str:
    text = str(err).strip() or type(err).__name__
    return text.splitlines()[0][:200]


def by_system(table: pa.Table) -> pa.Table:
    """One row per run and system of ``table`` (results.parquet's rows): the head columns but
    ``system_names``, ``system``, the ``param.*`` columns, then the ``systems.<system>.*``
    columns of that system without their prefix; in the order of ``table``, systems in their
    run's order. A run with no systems (a failed one) gives one row, ``system`` null."""
    names = table.column_names
    head = [n for n in HEAD_COLUMNS if n in names and n != "system_names"]
    params = [n for n in names if n.startswith("param.")]
    runs = table.column("system_names").to_pylist() if "system_names" in names else [None] * table.num_rows
    pairs = [(i, s) for i, run in enumerate(runs) for s in (run or [None])]
    parts = []
    for name in dict.fromkeys(s for _, s in pairs):
        order = [k for k, (_, s) in enumerate(pairs) if s == name]
        rows = pa.array([pairs[k][0] for k in order], pa.int64())
        prefix = f"systems.{name}."
        own = {n[len(prefix):]: n for n in names if name is not None and n.startswith(prefix)}
        parts.append(pa.table({**{n: table.column(n).take(rows) for n in head},
                               "system": pa.array([name] * len(order), pa.string()),
                               **{n: table.column(n).take(rows) for n in params},
                               **{short: table.column(n).take(rows) for short, n in own.items()},
                               "_order": pa.array(order, pa.int64())}))
    if not parts:
        return pa.table({**{n: table.column(n) for n in head}, "system": pa.array([], pa.string()),
                         **{n: table.column(n) for n in params}})
    return pa.concat_tables(parts, promote_options="permissive").sort_by("_order").drop_columns(["_order"])


class ResultStore:
    """The rows of a study folder: ``parts/`` (one file per batch), ``results.parquet`` and
    ``results_by_system.parquet``."""

    def __init__(self, out_dir: Path) -> None:
        self.out_dir = Path(out_dir)
        self.parts_dir = self.out_dir / PARTS_DIR
        self.results_path = self.out_dir / RESULTS_FILE
        self.by_system_path = self.out_dir / BY_SYSTEM_FILE
        self._seq = 0
        self._check_folder()
        try:
            self.parts_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise FusionError(f"{self.out_dir}: cannot create output folder: {err.strerror}") from None

    def _check_folder(self) -> None:
        """Refuse (FusionError naming them) a folder that holds no study (no ``results.parquet``, no
        ``parts/``: nothing to resume) but files of the names a study writes: they are the user's,
        and a study would replace them."""
        if not self.out_dir.is_dir() or self.parts_dir.is_dir() or self.results_path.is_file():
            return
        taken = sorted(p.name for p in self.out_dir.iterdir() if p.name in STUDY_NAMES or p.stem.endswith(PLOT_SUFFIX))
        if taken:
            raise FusionError(f"{self.out_dir}: holds {', '.join(taken)} but no study to resume (no {RESULTS_FILE}, no "
                              f"{PARTS_DIR}/), and a study would replace them; give another --out")

    def _files(self) -> list[Path]:
        """Saved files, oldest first: results.parquet, then the parts by name (time-stamped)."""
        for stale in self.parts_dir.glob(".*.tmp"):  # half-written by a killed study
            stale.unlink(missing_ok=True)
        parts = sorted(self.parts_dir.glob("part-*.parquet"))
        return ([self.results_path] if self.results_path.is_file() else []) + parts

    def keys(self) -> set[str]:
        """Run keys already saved (a corrupt file's not: :func:`read_saved`)."""
        tables = [read_saved(f, ["run_key"]) for f in self._files()]
        return {k for t in tables if t is not None for k in t.column(0).to_pylist()}

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
        write its :func:`by_system` view; then remove the merged parts."""
        files = self._files()
        if not files:
            return _table([])
        tables = [t for f in files if (t := read_saved(f)) is not None]
        files = [f for f in files if f.is_file()]
        if not tables:
            return _table([])
        table = pa.concat_tables(tables, promote_options="permissive")
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
        _write_atomic(by_system(table), self.by_system_path)
        for f in files:
            if f != self.results_path:
                f.unlink(missing_ok=True)
        return table


# --------------------------------------------------------------------------- summary


def _text(value: Any) -> Any:
    """A list or mapping cell as JSON text (hashable, and what a CSV cell can hold); others as they are."""
    return json.dumps(value, sort_keys=True) if isinstance(value, (list, dict)) else value


def _group_key(row: dict[str, Any], params: list[str]) -> tuple:
    return (row["layout"], *(_text(row.get(p)) for p in params), row.get("outage.duration_s"))


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
            out.append({"layout": key[0], **{p: _text(first.get(p)) for p in params},
                        "outage_system": first.get("outage.system"), "outage_start_s": first.get("outage.start_s"),
                        "outage_duration_s": key[-1], "metric": metric, "runs": int(v.size),
                        "failed": len(members) - len(ok), **stats})
    return out


def write_summary(path: Path, summary: list[dict[str, Any]]) -> None:
    """Write :func:`summarise`'s records as CSV (NaN and None as empty cells; no rows: an empty file)."""
    if not summary:
        path.write_text("")
        return
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(summary[0]))
        writer.writeheader()
        for rec in summary:
            writer.writerow({k: ("" if v is None or (isinstance(v, float) and math.isnan(v)) else v)
                             for k, v in rec.items()})
