"""Trajectory files for other tools, and their reader.

Every file holds positions in the navigation frame (ENU, m; docs/conventions.md) before any
evaluation alignment, times in seconds of the input's clock (the run has no absolute epoch,
so no calendar time is written):

- ``trajectories.csv``: the long format of docs/contract.md (:func:`write_trajectories_csv`).
- ``trajectories.parquet``: the same columns, float64 at full precision, plus
  ``cov_east_north_m2`` (the east–north position covariance, null where the system gives
  none); every field carries its unit in its metadata and the schema carries the frame,
  the geodetic origin, the bodyfusion version, the config's SHA-256 and
  :data:`TRAJECTORY_FORMAT_VERSION` (:func:`write_trajectories_parquet`).
- ``tum/<system>.txt`` and, where truth exists, ``tum/<system>_truth.txt``: the TUM RGB-D
  format ``timestamp tx ty tz qx qy qz qw`` read by evo (``evo_ape tum tum/x_truth.txt
  tum/x.txt -a``). The orientation is the system's attitude (body to ENU) where it estimates
  one (:func:`system_attitudes`: the foot INS), else the identity quaternion, as for every
  truth track (a :class:`~bodyfusion.base.types.Trajectory` or a truth holds no attitude): compare
  positions (evo's default APE ``--pose_relation trans_part``). A truth without heights is
  written with ``tz`` 0; compare it with ``--project_to_plane xy`` (:func:`write_tum`).
- ``track.geojson`` (runs with a geodetic origin only; without one no file is written): a
  WGS84 FeatureCollection, one LineString per system with per-vertex ``times`` (s) and
  one-sigma ``sd_east_m``/``sd_north_m``/``sd_up_m``, and the truth of each system, a
  LineString with its ``times`` or, for surveyed points, one Point per point with its ``t``;
  lines keep at most one vertex in each :data:`GEOJSON_STEP_S` (:func:`write_geojson`).

:func:`read_trajectories` reads the CSV or the Parquet file back into trajectories.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from bodyfusion.base.errors import InputError
from bodyfusion.base.types import Trajectory, TruthTrack
from bodyfusion.core.system import SensorSystem
from bodyfusion.io.gnss import enu_to_geodetic

TRAJECTORY_COLUMNS = ("system", "t", "east_m", "north_m", "up_m", "sd_east_m", "sd_north_m", "sd_up_m")
"""The columns of ``trajectories.csv`` (docs/contract.md), in order."""

TRAJECTORY_HEADER = ",".join(TRAJECTORY_COLUMNS)

COV_EN_COLUMN = "cov_east_north_m2"
"""The Parquet file's east–north position covariance column (m²)."""

TRAJECTORY_FORMAT_VERSION = "1"
"""Version of the Parquet trajectory layout (``bodyfusion.format_version`` in its schema)."""

_UNITS = {"t": "s", "east_m": "m", "north_m": "m", "up_m": "m", "sd_east_m": "m", "sd_north_m": "m",
          "sd_up_m": "m", COV_EN_COLUMN: "m^2"}
_DESCRIPTIONS = {
    "system": "system name", "t": "time of the input's clock",
    "east_m": "east position", "north_m": "north position", "up_m": "up position",
    "sd_east_m": "one-sigma east position", "sd_north_m": "one-sigma north position",
    "sd_up_m": "one-sigma up position", COV_EN_COLUMN: "east-north position covariance (null: not given)",
}


def _rows(traj: Trajectory, decimate: int) -> np.ndarray:
    """(N, 7) t, position, σ of every ``decimate``-th epoch."""
    return np.column_stack([traj.t, traj.pos_n, traj.pos_sd])[::decimate]


def write_trajectories_csv(path: Path, trajectories: Mapping[str, Trajectory], decimate: int = 1) -> None:
    """``trajectories.csv``: long format, times s (µs printed), positions and σ m (10 µm printed)."""
    with path.open("w") as fh:
        fh.write(TRAJECTORY_HEADER + "\n")
        for name, traj in trajectories.items():
            np.savetxt(fh, _rows(traj, decimate), fmt=name + ",%.6f,%.5f,%.5f,%.5f,%.5f,%.5f,%.5f")


def frame_metadata(geodetic_origin: tuple[float, float, float] | None) -> dict:
    """The navigation frame as the Parquet schema records it (``bodyfusion.frame``)."""
    origin = None if geodetic_origin is None else dict(zip(("lat_deg", "lon_deg", "height_m"),
                                                           map(float, geodetic_origin)))
    return {"name": "ENU", "axes": ["east", "north", "up"], "unit": "m",
            "origin": "the geodetic origin" if origin else "the start of the run (no geodetic origin)",
            "geodetic_origin": origin, "alignment": "none (before any evaluation alignment)",
            "time": {"unit": "s", "epoch": "the input's clock (no absolute epoch)"}}


def _numbers(values: np.ndarray, mask: np.ndarray | None = None) -> pa.Array:
    """A float64 (int32 for int32 ``values``) Arrow array on a copy of ``values``, null where
    ``mask``; as ``pa.array`` makes it, which imports pandas (0.3 s) to ask whether the values
    are a pandas object."""
    data = np.array(values, dtype=np.int32 if np.asarray(values).dtype == np.int32 else np.float64)  # a C-order copy
    validity = None if mask is None or not mask.any() else pa.py_buffer(np.packbits(~mask, bitorder="little"))
    return pa.Array.from_buffers(pa.from_numpy_dtype(data.dtype), len(data), [validity, pa.py_buffer(data)],
                                 null_count=0 if validity is None else int(mask.sum()))


def _strings(values: list[str]) -> pa.Array:
    """A string Arrow array of ``values``, without ``pa.array`` (see :func:`_numbers`)."""
    encoded = [v.encode() for v in values]
    offsets = np.concatenate(([0], np.cumsum([len(e) for e in encoded]))).astype(np.int32)
    return pa.Array.from_buffers(pa.string(), len(values), [None, pa.py_buffer(offsets), pa.py_buffer(b"".join(encoded))])


def trajectory_table(trajectories: Mapping[str, Trajectory], decimate: int = 1) -> pa.Table:
    """The long-format table: ``system`` dictionary-encoded, the numbers float64, the covariance
    null for a system that gives none; field metadata ``unit`` and ``description``."""
    trajs = list(trajectories.values())
    sizes = [len(tr.t[::decimate]) for tr in trajs]
    columns = [np.concatenate([tr.t[::decimate] for tr in trajs]),
               *(np.concatenate([getattr(tr, a)[::decimate, k] for tr in trajs])
                 for a in ("pos_n", "pos_sd") for k in range(3)),
               np.concatenate([np.full(n, np.nan) if tr.pos_cov_en is None else np.asarray(tr.pos_cov_en)[::decimate]
                               for tr, n in zip(trajs, sizes)])]
    missing = np.repeat([tr.pos_cov_en is None for tr in trajs], sizes)
    system = pa.DictionaryArray.from_arrays(_numbers(np.repeat(np.arange(len(trajs), dtype=np.int32), sizes)),
                                            _strings(list(trajectories)))
    arrays = [system, *(_numbers(c) for c in columns[:-1]), _numbers(columns[-1], mask=missing)]
    fields = [pa.field(c, a.type, nullable=c == COV_EN_COLUMN,
                       metadata={"description": _DESCRIPTIONS[c], **({"unit": _UNITS[c]} if c in _UNITS else {})})
              for c, a in zip((*TRAJECTORY_COLUMNS, COV_EN_COLUMN), arrays)]
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))


def write_trajectories_parquet(path: Path, trajectories: Mapping[str, Trajectory], *, config_sha256: str,
                               geodetic_origin: tuple[float, float, float] | None, decimate: int = 1) -> None:
    """``trajectories.parquet``: :func:`trajectory_table` with the schema metadata
    ``bodyfusion.format_version``, ``bodyfusion.version``, ``bodyfusion.config_sha256`` and
    ``bodyfusion.frame`` (JSON, :func:`frame_metadata`)."""
    from bodyfusion import __version__

    table = trajectory_table(trajectories, decimate)
    meta = {"bodyfusion.format_version": TRAJECTORY_FORMAT_VERSION, "bodyfusion.version": __version__,
            "bodyfusion.config_sha256": config_sha256,
            "bodyfusion.frame": json.dumps(frame_metadata(geodetic_origin))}
    pq.write_table(table.replace_schema_metadata(meta), path, compression="zstd", use_dictionary=["system"])


def read_trajectories(path: str | Path) -> dict[str, Trajectory]:
    """Trajectories from ``trajectories.parquet`` or ``trajectories.csv`` (by the suffix), one
    per system in file order: ENU m, s; ``pos_cov_en`` from the Parquet file's covariance
    column where given (the CSV has none)."""
    path = Path(path)
    try:
        if path.suffix == ".parquet":
            table = pq.read_table(path)
        else:
            types = {c: pa.string() if c == "system" else pa.float64() for c in TRAJECTORY_COLUMNS}
            table = pacsv.read_csv(path, convert_options=pacsv.ConvertOptions(column_types=types))
    except (OSError, pa.ArrowInvalid) as err:
        raise InputError(path, f"not a trajectory file: {str(err).splitlines()[0]}") from None
    missing = [c for c in TRAJECTORY_COLUMNS if c not in table.column_names]
    if missing:
        raise InputError(path, f"missing column(s) {missing}")
    system = pc.dictionary_encode(table.column("system").cast(pa.string()).combine_chunks())  # first-seen order
    codes = system.indices.to_numpy(zero_copy_only=False)
    cols = {c: table.column(c).to_numpy() for c in TRAJECTORY_COLUMNS[1:]}
    cov = table.column(COV_EN_COLUMN) if COV_EN_COLUMN in table.column_names else None
    out: dict[str, Trajectory] = {}
    for code, name in enumerate(system.dictionary.to_pylist()):
        rows = np.flatnonzero(codes == code)
        c = None if cov is None else cov.take(pa.array(rows))
        out[name] = Trajectory(cols["t"][rows], np.column_stack([cols[k][rows] for k in TRAJECTORY_COLUMNS[2:5]]),
                               np.column_stack([cols[k][rows] for k in TRAJECTORY_COLUMNS[5:8]]),
                               None if c is None or c.null_count == len(c) else c.to_numpy(zero_copy_only=False))
    return out


QUATERNION_STATES = ("qw", "qx", "qy", "qz")
"""The attitude columns of :meth:`~bodyfusion.core.system.SensorSystem.states` (scalar first, body to ENU)."""


def system_attitudes(systems: Mapping[str, SensorSystem]) -> dict[str, np.ndarray]:
    """(N, 4) attitude quaternions ``[w, x, y, z]`` (body to ENU) at the trajectory's epochs of
    every system whose :meth:`~bodyfusion.core.system.SensorSystem.states` give one."""
    out = {}
    for name, system in systems.items():
        states = system.states()
        if all(k in states for k in QUATERNION_STATES):
            out[name] = np.column_stack([states[k] for k in QUATERNION_STATES])
    return out


def _tum_table(t: np.ndarray, pos_n: np.ndarray, q_wxyz: np.ndarray | None) -> pa.Table:
    """TUM columns; the identity orientation without a quaternion, NaN heights as 0."""
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1)) if q_wxyz is None else q_wxyz
    cols = {"timestamp": t, "tx": pos_n[:, 0], "ty": pos_n[:, 1], "tz": np.nan_to_num(pos_n[:, 2], nan=0.0),
            "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3], "qw": q[:, 0]}
    return pa.table({k: _numbers(v) for k, v in cols.items()})


def write_tum(folder: Path, trajectories: Mapping[str, Trajectory], truths: Mapping[str, TruthTrack],
              decimate: int = 1, attitudes: Mapping[str, np.ndarray] | None = None) -> list[Path]:
    """``<folder>/<system>.txt`` per system and ``<system>_truth.txt`` per truth track (dense
    truth decimated like the estimate, surveyed points all): ``timestamp tx ty tz qx qy qz qw``,
    s and ENU m at full precision, space-separated, no header. ``attitudes``: a system's (N, 4)
    quaternions ``[w, x, y, z]`` (body to ENU) at its trajectory's epochs
    (:func:`system_attitudes`); the identity for the others and the truth. Returns the files written."""
    attitudes = attitudes or {}
    tracks = {name: (tr.t[::decimate], tr.pos_n[::decimate],
                     attitudes[name][::decimate] if name in attitudes else None)
              for name, tr in trajectories.items()}
    for name, tr in truths.items():
        step = 1 if tr.sparse else decimate
        tracks[f"{name}_truth"] = (tr.t[::step], tr.pos_n[::step], None)
    folder.mkdir(parents=True, exist_ok=True)
    options = pacsv.WriteOptions(include_header=False, delimiter=" ", quoting_style="none")
    written = []
    for name, (t, pos, q) in tracks.items():
        written.append(folder / f"{name}.txt")
        pacsv.write_csv(_tum_table(t, pos, q), written[-1], options)
    return written


GEOJSON_STEP_S = 0.1
"""A ``track.geojson`` line keeps at most one vertex in each interval of this length (s) from
its start: a map needs no more, and a 1-hour, 100 Hz track stays a few MB; every epoch is in
``trajectories.parquet``."""


def map_epochs(t: np.ndarray, decimate: int = 1, step_s: float = GEOJSON_STEP_S) -> np.ndarray:
    """Indices of the epochs a map line keeps: of every ``decimate``-th epoch, the first in each
    ``step_s`` interval from the start, and the last epoch."""
    idx = np.arange(0, len(t), decimate)
    if idx.size == 0:
        return idx
    bins = np.floor((t[idx] - t[idx[0]]) / step_s + 1e-9)  # 0.3 s is in the fourth 0.1-s interval
    keep = np.concatenate([[True], bins[1:] != bins[:-1]])
    keep[-1] = True
    return idx[keep]


def _lon_lat_h(pos_n: np.ndarray, origin: tuple[float, float, float]) -> list[list[float]]:
    """GeoJSON positions ``[lon, lat, h]`` (deg, deg, m above the ellipsoid; 1e-9 deg and 0.1 mm
    printed); ``[lon, lat]`` for a track without heights (NaN up)."""
    flat = np.isnan(pos_n[:, 2]).all()
    llh = enu_to_geodetic(np.nan_to_num(pos_n, nan=0.0), origin)
    cols = [np.round(llh[:, 1], 9), np.round(llh[:, 0], 9)] + ([] if flat else [np.round(llh[:, 2], 4)])
    return np.column_stack(cols).tolist()


def _feature(properties: dict, kind: str, coordinates: list) -> dict:
    return {"type": "Feature", "properties": properties, "geometry": {"type": kind, "coordinates": coordinates}}


def write_geojson(path: Path, trajectories: Mapping[str, Trajectory], truths: Mapping[str, TruthTrack],
                  geodetic_origin: tuple[float, float, float], decimate: int = 1) -> None:
    """``track.geojson`` (RFC 7946, WGS84 lon/lat/h): per system a LineString with properties
    ``system``, ``role`` ``estimate``, ``times`` (s, one per vertex) and ``sd_east_m``/
    ``sd_north_m``/``sd_up_m`` (one-sigma, m, one per vertex); per dense truth track a
    LineString (``role`` ``truth``, ``times``); per surveyed truth point a Point with its time
    ``t``. Lines keep the epochs of :func:`map_epochs`. Positions from the ENU tracks about
    ``geodetic_origin`` (lat deg, lon deg, h m)."""
    features = []
    for name, traj in trajectories.items():
        k = map_epochs(traj.t, decimate)
        sd = np.round(traj.pos_sd[k], 5)
        props = {"system": name, "role": "estimate", "times": np.round(traj.t[k], 6).tolist(),
                 "sd_east_m": sd[:, 0].tolist(), "sd_north_m": sd[:, 1].tolist(), "sd_up_m": sd[:, 2].tolist()}
        features.append(_feature(props, "LineString", _lon_lat_h(traj.pos_n[k], geodetic_origin)))
    for name, tr in truths.items():
        if tr.sparse:
            features += [_feature({"system": name, "role": "truth", "t": t}, "Point", xy)
                         for t, xy in zip(np.round(tr.t, 6).tolist(), _lon_lat_h(tr.pos_n, geodetic_origin))]
        else:
            k = map_epochs(tr.t, decimate)
            features.append(_feature({"system": name, "role": "truth", "times": np.round(tr.t[k], 6).tolist()},
                                     "LineString", _lon_lat_h(tr.pos_n[k], geodetic_origin)))
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}) + "\n")
