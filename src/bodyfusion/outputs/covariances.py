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

from bodyfusion.core.system import CovarianceHistory, SensorSystem
from bodyfusion.outputs.trajectories import ROWS, arrow_numbers, arrow_strings, epoch_pieces

COVARIANCE_FORMAT_VERSION = "1"


PIECE_ROWS = ROWS // 4
"""Epochs formed and written at once: a piece of a 9-state history's matrices is 10 MB."""


def _stored_columns(history: CovarianceHistory, decimate: int) -> list[str]:
    """The history's columns that hold a number at some kept epoch (``t`` first), a piece at a time."""
    names = list(history.columns(slice(0, 0)))
    held = {"t"}
    for epochs in epoch_pieces(len(history.t), decimate, PIECE_ROWS):
        held.update(k for k, v in history.columns(epochs).items() if k not in held and not np.isnan(v).all())
    return [k for k in names if k in held]


def write_covariances_parquet(path: Path, systems: Mapping[str, SensorSystem], decimate: int = 1) -> None:
    """``covariances.parquet`` (module docstring) of every navigation system, :data:`PIECE_ROWS` epochs
    of one system at a time (a row group each): the systems' columns in the order they first
    appear, null where a system stores no such entry."""
    histories = {name: s.covariance_history() for name, s in systems.items()}
    kept = {name: _stored_columns(h, decimate) for name, h in histories.items()}
    names = list(dict.fromkeys(["t", "system", *(k for cols in kept.values() for k in cols[1:])]))
    meta = {"bodyfusion.format_version": COVARIANCE_FORMAT_VERSION,
            "bodyfusion.stored": json.dumps({name: h.stored for name, h in histories.items()})}
    schema = pa.schema([(k, pa.string() if k == "system" else pa.float64()) for k in names]).with_metadata(meta)
    import pyarrow.parquet as pq  # ~40 MB resident: loaded when Parquet is used
    with pq.ParquetWriter(path, schema, compression="zstd", use_dictionary=["system"]) as writer:
        for name, history in histories.items():
            held = set(kept[name])
            for epochs in epoch_pieces(len(history.t), decimate, PIECE_ROWS):
                columns = history.columns(epochs)
                n = len(columns["t"])
                writer.write_batch(pa.RecordBatch.from_arrays(
                    [arrow_strings([name] * n) if k == "system" else
                     arrow_numbers(columns[k]) if k in held else pa.nulls(n, pa.float64()) for k in names],
                    schema=schema))
