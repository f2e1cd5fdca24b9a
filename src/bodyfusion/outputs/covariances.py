"""``covariances.parquet``: every system's error-state covariance over time, as it stores it.

One row per recorded epoch and system (every ``output.decimate``-th, as the trajectories): ``t``
(s), ``system``, then ``var_<state>`` and ``cov_<a>_<b>`` for the entries any system stores
(:meth:`~bodyfusion.core.system.SensorSystem.covariance_history`: the foot INS its position,
velocity and attitude blocks after every sample; the hand PDR its whole error state at each step
and update), in the states' units squared; null where a system does not store the entry. The
schema metadata gives ``bodyfusion.format_version`` (``1``) and ``bodyfusion.stored`` (JSON:
system → what it keeps).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from bodyfusion.core.system import SensorSystem

COVARIANCE_FORMAT_VERSION = "1"


def covariance_table(name: str, system: SensorSystem, decimate: int = 1) -> pa.Table:
    """One system's rows: ``t``, ``system`` and every entry it stores (a column that is NaN
    throughout is left out)."""
    history = system.covariance_history()
    columns = {key: np.asarray(value)[::decimate] for key, value in history.columns().items()}
    kept = {key: value for key, value in columns.items() if key == "t" or not np.isnan(value).all()}
    n = len(kept["t"])
    return pa.table({"t": kept.pop("t"), "system": pa.array([name] * n, pa.string()), **kept})


def write_covariances_parquet(path: Path, systems: Mapping[str, SensorSystem], decimate: int = 1) -> None:
    """``covariances.parquet`` (module docstring) of every navigation system."""
    tables = [covariance_table(name, s, decimate) for name, s in systems.items()]
    table = pa.concat_tables(tables, promote_options="permissive")
    meta = {"bodyfusion.format_version": COVARIANCE_FORMAT_VERSION,
            "bodyfusion.stored": json.dumps({name: s.covariance_history().stored for name, s in systems.items()})}
    pq.write_table(table.replace_schema_metadata(meta), path, compression="zstd", use_dictionary=["system"])
