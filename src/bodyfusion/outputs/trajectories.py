"""Trajectory files for other tools, and their reader.

Every file holds positions in the navigation frame (ENU, m; docs/conventions.md) before any
evaluation alignment, times in seconds of the input's clock (the run has no absolute epoch,
so no calendar time is written):

- ``trajectories.csv``: the long format of docs/contract.md (:func:`write_trajectories_csv`):
  positions and their σ, then velocity and attitude (quaternion and ZYX Euler angles) where
  the system has them and their σ where it gives them
  (:data:`~bodyfusion.io.trajectory_files.TRAJECTORY_COLUMNS`).
- ``trajectories.parquet``: the same columns, float64 at full precision, plus
  ``cov_east_north_m2`` (the east–north position covariance, null where the system gives
  none); every field carries its unit in its metadata and the schema carries the frame,
  the geodetic origin, the bodyfusion version, the config's SHA-256 and
  :data:`TRAJECTORY_FORMAT_VERSION` (:func:`write_trajectories_parquet`).
- ``tum/<system>.txt`` and, where truth exists, ``tum/<system>_truth.txt``: the TUM RGB-D
  format ``timestamp tx ty tz qx qy qz qw`` read by evo (``evo_ape tum tum/x_truth.txt
  tum/x.txt -a``). The orientation is the trajectory's attitude (body to ENU) where it has
  one (the foot INS), else the identity quaternion, as for every truth track (a truth holds
  no attitude): compare positions (evo's default APE ``--pose_relation trans_part``). A truth
  without heights is written with ``tz`` 0; compare it with ``--project_to_plane xy``
  (:func:`write_tum`).
- ``track.geojson`` (runs with a geodetic origin only; without one no file is written): a
  WGS84 FeatureCollection, one LineString per system with per-vertex ``times`` (s) and
  one-sigma ``sd_east_m``/``sd_north_m``/``sd_up_m``, and the truth of each system, a
  LineString with its ``times`` or, for surveyed points, one Point per point with its ``t``;
  lines keep at most one vertex in each :data:`GEOJSON_STEP_S` (:func:`write_geojson`).

:func:`bodyfusion.io.trajectory_files.read_trajectories` reads the CSV or the Parquet file back.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import TextIO

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
from scipy.spatial.transform import Rotation

from bodyfusion.base.types import NavigationFrame, Trajectory, TruthTrack
from bodyfusion.io.gnss import enu_to_geodetic
from bodyfusion.nav.attitude_uncertainty import euler_sd_deg, quaternion_sd, unpack_covariance
from bodyfusion.io.trajectory_files import (
    COV_EN_COLUMN,
    MOTION_COLUMNS,
    POSITION_COLUMNS,
    TRAJECTORY_COLUMNS,
    TRAJECTORY_HEADER,
    UNITS,
)

TRAJECTORY_FORMAT_VERSION = "2"
"""Version of the Parquet trajectory layout (``bodyfusion.format_version`` in its schema): 2
added velocity, attitude and their 1σ."""

_DESCRIPTIONS = {
    "system": "system name", "t": "time of the input's clock",
    "east_m": "east position", "north_m": "north position", "up_m": "up position",
    "sd_east_m": "one-sigma east position", "sd_north_m": "one-sigma north position",
    "sd_up_m": "one-sigma up position",
    "v_east_mps": "east velocity", "v_north_mps": "north velocity", "v_up_mps": "up velocity",
    "qw": "attitude quaternion, scalar part (body to ENU)", "qx": "attitude quaternion, x",
    "qy": "attitude quaternion, y", "qz": "attitude quaternion, z",
    "roll_deg": "roll (ZYX Euler angles in ENU)", "pitch_deg": "pitch (ZYX Euler angles in ENU)",
    "yaw_deg": "yaw, counter-clockwise from East (ZYX Euler angles in ENU)",
    COV_EN_COLUMN: "east-north position covariance (null: not given)",
}
_DESCRIPTIONS.update({f"sd_{c}": f"one-sigma {_DESCRIPTIONS[c]} (null: not given)" for c in MOTION_COLUMNS})
for _c in MOTION_COLUMNS:
    _DESCRIPTIONS[_c] += " (null: no such state)"


ROWS = 1 << 16
"""Epochs a trajectory writer formats at once: a file is written in pieces of this many rows
(the same bytes as at once), never holding a whole long track's rows, strings or tables."""


def epoch_pieces(n: int, decimate: int, rows: int = ROWS) -> Iterator[slice]:
    """Slices of the epochs 0..n that keep every ``decimate``-th, ``rows`` kept epochs each."""
    step = rows * decimate
    for a in range(0, n, step):
        yield slice(a, min(a + step, n), decimate)


_CSV_DECIMALS = {c: 7 for c in ("qw", "qx", "qy", "qz", "sd_qw", "sd_qx", "sd_qy", "sd_qz")}
"""Decimals of a CSV column where not 5 (quaternion components: 1e-7, about 0.00001°)."""


def write_trajectories_csv(path: Path, trajectories: Mapping[str, Trajectory], decimate: int = 1) -> None:
    """``trajectories.csv``: long format (:data:`TRAJECTORY_COLUMNS`), times s rounded to the µs,
    positions and σ m, velocities m/s and angles deg rounded to 1e-5, quaternions to 1e-7, each
    printed as the shortest decimal that reads back as that rounded number (``0.5``, not
    ``0.50000``), empty where not given; written :data:`ROWS` rows at a time by Arrow's CSV
    writer."""
    with path.open("wb") as fh:
        fh.write((TRAJECTORY_HEADER + "\n").encode())
        schema = pa.schema([(c, pa.string() if c == "system" else pa.float64()) for c in TRAJECTORY_COLUMNS])
        plain = not any(set(name) & set(',"\r\n') for name in trajectories)  # else quoted, as CSV needs
        options = pacsv.WriteOptions(include_header=False, quoting_style="none" if plain else "needed")
        with pacsv.CSVWriter(fh, schema, write_options=options) as writer:
            for piece in _trajectory_pieces(trajectories, decimate):
                system, t, *numbers = piece[:len(TRAJECTORY_COLUMNS)]
                writer.write_batch(pa.RecordBatch.from_arrays(
                    [system.dictionary_decode(), pc.round(t, 6),
                     *(pc.round(v, _CSV_DECIMALS.get(c, 5)) for c, v in zip(TRAJECTORY_COLUMNS[2:], numbers))],
                    schema=schema))


def arrow_numbers(values: np.ndarray, mask: np.ndarray | None = None) -> pa.Array:
    """A float64 (int32 for int32 ``values``) Arrow array on a copy of ``values``, null where
    ``mask``; as ``pa.array`` makes it, which imports pandas (0.3 s) to ask whether the values
    are a pandas object."""
    data = np.array(values, dtype=np.int32 if np.asarray(values).dtype == np.int32 else np.float64)  # a C-order copy
    validity = None if mask is None or not mask.any() else pa.py_buffer(np.packbits(~mask, bitorder="little"))
    return pa.Array.from_buffers(pa.from_numpy_dtype(data.dtype), len(data), [validity, pa.py_buffer(data)],
                                 null_count=0 if validity is None else int(mask.sum()))


def arrow_strings(values: list[str]) -> pa.Array:
    """A string Arrow array of ``values``, without ``pa.array`` (see :func:`arrow_numbers`)."""
    encoded = [v.encode() for v in values]
    offsets = np.concatenate(([0], np.cumsum([len(e) for e in encoded]))).astype(np.int32)
    return pa.Array.from_buffers(pa.string(), len(values), [None, pa.py_buffer(offsets), pa.py_buffer(b"".join(encoded))])


def euler_deg(q_nb: np.ndarray) -> np.ndarray:
    """(N, 3) roll, pitch, yaw (deg) of quaternions q_nb (N, 4; scalar first, body to ENU): the
    ZYX Euler angles in ENU, yaw counter-clockwise from East in (−180°, 180°]."""
    if not len(q_nb):
        return np.empty((0, 3))
    yaw, pitch, roll = Rotation.from_quat(q_nb, scalar_first=True).as_euler("ZYX", degrees=True).T
    return np.column_stack([roll, pitch, yaw])


def _columns(block: np.ndarray | None, width: int) -> list[np.ndarray | None]:
    return [None] * width if block is None else [block[:, j] for j in range(width)]


def _motion(traj: Trajectory, epochs: slice) -> list[np.ndarray | None]:
    """Velocity, quaternion and Euler columns at ``epochs`` (None where the system has no such
    state), then their 1σ (None where it gives no covariance: ``Trajectory.motion_cov``;
    :mod:`bodyfusion.nav.attitude_uncertainty`)."""
    vel = None if traj.vel_n is None else np.asarray(traj.vel_n)[epochs]
    q = None if traj.q_nb is None else np.asarray(traj.q_nb)[epochs]
    euler = None if q is None else euler_deg(q)
    cov = None if traj.motion_cov is None else np.asarray(traj.motion_cov)[epochs]
    vel_sd = None if cov is None or vel is None else np.sqrt(np.maximum(cov[:, :3], 0.0))
    att = None if cov is None or q is None else unpack_covariance(cov[:, 3:9])
    return [*_columns(vel, 3), *_columns(q, 4), *_columns(euler, 3), *_columns(vel_sd, 3),
            *_columns(None if att is None else quaternion_sd(q, att), 4),
            *_columns(None if att is None else euler_sd_deg(q, att), 3)]


def _trajectory_columns(names: list[str], k: int, traj: Trajectory, epochs: slice) -> list[pa.Array]:
    """The long-format table's columns (:data:`TRAJECTORY_COLUMNS`, then the east–north
    covariance) for the ``epochs`` of system ``k`` of ``names``; null where not given."""
    t = traj.t[epochs]
    none = np.ones(len(t), dtype=bool)
    missing = np.full(len(t), np.nan)
    cov = missing if traj.pos_cov_en is None else np.asarray(traj.pos_cov_en)[epochs]
    system = pa.DictionaryArray.from_arrays(arrow_numbers(np.full(len(t), k, dtype=np.int32)), arrow_strings(names))
    return [system, arrow_numbers(t), *(arrow_numbers(getattr(traj, a)[epochs, j]) for a in ("pos_n", "pos_sd") for j in range(3)),
            *(arrow_numbers(missing, mask=none) if v is None else arrow_numbers(v, mask=~np.isfinite(v))
              for v in _motion(traj, epochs)),
            arrow_numbers(cov, mask=np.full(len(t), traj.pos_cov_en is None))]


def _trajectory_schema(columns: list[pa.Array]) -> pa.Schema:
    """The table's schema: field metadata ``unit`` and ``description``; velocity, attitude, their
    σ and the covariance nullable."""
    return pa.schema([pa.field(c, a.type, nullable=c not in POSITION_COLUMNS,
                               metadata={"description": _DESCRIPTIONS[c], **({"unit": UNITS[c]} if c in UNITS else {})})
                      for c, a in zip((*TRAJECTORY_COLUMNS, COV_EN_COLUMN), columns)])


def _trajectory_pieces(trajectories: Mapping[str, Trajectory], decimate: int) -> Iterator[list[pa.Array]]:
    """The long-format table's columns, :data:`ROWS` epochs of one system at a time (at least
    one piece, empty for no trajectories)."""
    names = list(trajectories)
    empty = True
    for k, traj in enumerate(trajectories.values()):
        for epochs in epoch_pieces(len(traj.t), decimate):
            empty = False
            yield _trajectory_columns(names, k, traj, epochs)
    if empty:
        yield _trajectory_columns(names, 0, Trajectory(np.empty(0), np.empty((0, 3)), np.empty((0, 3))), slice(None))


def trajectory_table(trajectories: Mapping[str, Trajectory], decimate: int = 1) -> pa.Table:
    """The long-format table: ``system`` dictionary-encoded, the numbers float64, the covariance
    null for a system that gives none; field metadata ``unit`` and ``description``."""
    pieces = list(_trajectory_pieces(trajectories, decimate))
    schema = _trajectory_schema(pieces[0])
    return pa.Table.from_batches([pa.RecordBatch.from_arrays(p, schema=schema) for p in pieces], schema=schema)


def write_trajectories_parquet(path: Path, trajectories: Mapping[str, Trajectory], *, config_sha256: str,
                               frame: NavigationFrame, decimate: int = 1) -> None:
    """``trajectories.parquet``: :func:`trajectory_table` with the schema metadata
    ``bodyfusion.format_version``, ``bodyfusion.version``, ``bodyfusion.config_sha256`` and
    ``bodyfusion.frame`` (JSON, :meth:`~bodyfusion.base.types.NavigationFrame.to_dict`); written
    :data:`ROWS` epochs of one system at a time (a row group each)."""
    from bodyfusion import __version__

    meta = {"bodyfusion.format_version": TRAJECTORY_FORMAT_VERSION, "bodyfusion.version": __version__,
            "bodyfusion.config_sha256": config_sha256,
            "bodyfusion.frame": json.dumps(frame.to_dict())}
    writer = None
    try:
        for piece in _trajectory_pieces(trajectories, decimate):
            if writer is None:
                schema = _trajectory_schema(piece).with_metadata(meta)
                import pyarrow.parquet as pq  # ~40 MB resident: loaded when Parquet is used
                writer = pq.ParquetWriter(path, schema, compression="zstd", use_dictionary=["system"])
            writer.write_batch(pa.RecordBatch.from_arrays(piece, schema=schema))
    finally:
        if writer is not None:
            writer.close()


_TUM_COLUMNS = ("timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw")


def _tum_table(t: np.ndarray, pos_n: np.ndarray, q_wxyz: np.ndarray | None, times: dict[bytes, pa.Array]) -> pa.Table:
    """TUM columns as text, each number as Arrow's CSV writer prints a float64 (its cast to
    string); the identity orientation without a quaternion, NaN heights as 0. Times printed
    before (``times``: their float64 bytes → text; a truth's times are its system's) and the
    identity's constant columns are not printed again."""
    key = t.tobytes()
    if key not in times:
        times[key] = pc.cast(arrow_numbers(t), pa.string())
    if q_wxyz is None:
        identity = pc.cast(arrow_numbers(np.array([0.0, 0.0, 0.0, 1.0])), pa.string())
        q = [pa.repeat(identity[j], len(t)) for j in range(4)]
    else:
        q = [pc.cast(arrow_numbers(q_wxyz[:, j]), pa.string()) for j in (1, 2, 3, 0)]
    xyz = [pc.cast(arrow_numbers(v), pa.string()) for v in (pos_n[:, 0], pos_n[:, 1], np.nan_to_num(pos_n[:, 2], nan=0.0))]
    return pa.table(dict(zip(_TUM_COLUMNS, [times[key], *xyz, *q])))


def write_tum(folder: Path, trajectories: Mapping[str, Trajectory], truths: Mapping[str, TruthTrack],
              decimate: int = 1) -> list[Path]:
    """``<folder>/<system>.txt`` per system and ``<system>_truth.txt`` per truth track (dense
    truth decimated like the estimate, surveyed points all): ``timestamp tx ty tz qx qy qz qw``,
    s and ENU m at full precision, space-separated, no header; the orientation is the
    trajectory's attitude ``q_nb`` (body to ENU) where it has one, else the identity (and for
    every truth). Each file is written :data:`ROWS` rows at a time. Returns the files written."""
    tracks: dict[str, tuple[np.ndarray, np.ndarray, int, np.ndarray | None]] = {
        name: (tr.t, tr.pos_n, decimate, tr.q_nb) for name, tr in trajectories.items()}
    for name, tr in truths.items():
        tracks[f"{name}_truth"] = (tr.t, tr.pos_n, 1 if tr.sparse else decimate, None)
    folder.mkdir(parents=True, exist_ok=True)
    options = pacsv.WriteOptions(include_header=False, delimiter=" ", quoting_style="none")
    schema = pa.schema([(c, pa.string()) for c in _TUM_COLUMNS])
    written = []
    times: dict[bytes, pa.Array] = {}
    for name, (t, pos, step, q) in tracks.items():
        written.append(folder / f"{name}.txt")
        with pacsv.CSVWriter(written[-1], schema, write_options=options) as writer:
            for epochs in epoch_pieces(len(t), step):
                writer.write_table(_tum_table(t[epochs], pos[epochs], None if q is None else q[epochs], times))
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


def _lon_lat_h_columns(pos_n: np.ndarray, origin: tuple[float, float, float], flat: bool) -> list[np.ndarray]:
    """The coordinates of GeoJSON positions ``[lon, lat, h]`` (deg, deg, m above the ellipsoid;
    rounded to 1e-9 deg and 0.1 mm); ``[lon, lat]`` for a track without heights (``flat``: NaN
    up throughout)."""
    llh = enu_to_geodetic(np.nan_to_num(pos_n, nan=0.0), origin)
    return [np.round(llh[:, 1], 9), np.round(llh[:, 0], 9)] + ([] if flat else [np.round(llh[:, 2], 4)])


def _lon_lat_h(pos_n: np.ndarray, origin: tuple[float, float, float], flat: bool) -> list[list[float]]:
    """GeoJSON positions (:func:`_lon_lat_h_columns`) as lists."""
    return np.column_stack(_lon_lat_h_columns(pos_n, origin, flat)).tolist()


def _mask(flags: np.ndarray) -> pa.Array:
    """A boolean Arrow array of ``flags`` (see :func:`arrow_numbers`)."""
    return pa.Array.from_buffers(pa.bool_(), len(flags), [None, pa.py_buffer(np.packbits(flags, bitorder="little"))])


def _json_floats(values: np.ndarray) -> pa.Array:
    """``json.dumps`` of each of the float ``values``, as Arrow strings. Arrow prints the same
    shortest round-trip digits as Python's ``repr``, and in the same positional notation for
    1e-4 ≤ |x| < 1e9 and 0, only without the ``.0`` of a whole number; the other values
    (exponent notation, NaN, infinities) are printed by ``json.dumps``."""
    x = np.array(values, dtype=np.float64)
    text = pc.cast(arrow_numbers(x), pa.string())
    magnitude = np.abs(x)
    with np.errstate(invalid="ignore"):
        python = ~(((magnitude >= 1e-4) & (magnitude < 1e9)) | (x == 0.0))  # NaN too
        whole = ~python & (x == np.floor(x))
    if whole.any():
        text = pc.if_else(_mask(whole), pc.binary_join_element_wise(text, ".0", ""), text)
    if python.any():
        text = pc.replace_with_mask(text, _mask(python), arrow_strings([json.dumps(v) for v in x[python].tolist()]))
    return text


def _json_elements(elements: pa.Array) -> str:
    """The text of JSON array elements (strings, each an element's JSON), ``", "``-separated
    as ``json.dumps`` separates them."""
    bounds = arrow_numbers(np.array([0, len(elements)], dtype=np.int32))
    return pc.binary_join(pa.ListArray.from_arrays(bounds, elements), ", ")[0].as_py()


def _json_positions(pos_n: np.ndarray, origin: tuple[float, float, float], flat: bool) -> str:
    """The text of GeoJSON positions (:func:`_lon_lat_h_columns`) as array elements, as
    ``json.dumps`` prints the lists of :func:`_lon_lat_h`."""
    columns = [_json_floats(c) for c in _lon_lat_h_columns(pos_n, origin, flat)]
    parts = [p for c in columns for p in (", ", c)][1:]
    return _json_elements(pc.binary_join_element_wise("[", *parts, "]", ""))


class _JsonArray:
    """A JSON array :func:`_write_json` writes a piece at a time: ``pieces()`` yields the text of
    its consecutive elements (as ``json.dumps`` prints them, ``", "``-separated)."""

    def __init__(self, pieces: Callable[[], Iterator[str]]) -> None:
        self.pieces = pieces


def _write_json(fh: TextIO, value: object) -> None:
    """``json.dumps(value)`` into ``fh``, with :class:`_JsonArray` values written a piece at a
    time and the elements of an iterator (not a list) one at a time."""
    if isinstance(value, _JsonArray):
        fh.write("[")
        sep = ""
        for piece in value.pieces():
            if piece:
                fh.write(sep + piece)
                sep = ", "
        fh.write("]")
    elif isinstance(value, dict):
        fh.write("{")
        for k, (key, item) in enumerate(value.items()):
            fh.write((", " if k else "") + json.dumps(key) + ": ")
            _write_json(fh, item)
        fh.write("}")
    elif isinstance(value, Iterator):
        fh.write("[")
        for k, item in enumerate(value):
            fh.write(", " if k else "")
            _write_json(fh, item)
        fh.write("]")
    else:
        fh.write(json.dumps(value))


def _feature(properties: dict, kind: str, coordinates: object) -> dict:
    return {"type": "Feature", "properties": properties, "geometry": {"type": kind, "coordinates": coordinates}}


def _line_feature(properties: dict, t: np.ndarray, pos_n: np.ndarray, sd: np.ndarray | None, k: np.ndarray,
                  origin: tuple[float, float, float]) -> dict:
    """A LineString feature through the epochs ``k`` with ``times`` (and ``sd_*_m`` from ``sd``)
    among its ``properties``, its arrays written :data:`ROWS` vertices at a time."""
    flat = bool(np.isnan(pos_n[k, 2]).all())

    def column(values: np.ndarray, decimals: int) -> _JsonArray:
        return _JsonArray(lambda: (_json_elements(_json_floats(np.round(values[k[p]], decimals)))
                                   for p in epoch_pieces(k.size, 1)))

    properties = {**properties, "times": column(t, 6)}
    if sd is not None:
        properties.update({f"sd_{axis}_m": column(sd[:, j], 5) for j, axis in enumerate(("east", "north", "up"))})
    coordinates = _JsonArray(lambda: (_json_positions(pos_n[k[p]], origin, flat) for p in epoch_pieces(k.size, 1)))
    return _feature(properties, "LineString", coordinates)


def write_geojson(path: Path, trajectories: Mapping[str, Trajectory], truths: Mapping[str, TruthTrack],
                  geodetic_origin: tuple[float, float, float], decimate: int = 1) -> None:
    """``track.geojson`` (RFC 7946, WGS84 lon/lat/h): per system a LineString with properties
    ``system``, ``role`` ``estimate``, ``times`` (s, one per vertex) and ``sd_east_m``/
    ``sd_north_m``/``sd_up_m`` (one-sigma, m, one per vertex); per dense truth track a
    LineString (``role`` ``truth``, ``times``); per surveyed truth point a Point with its time
    ``t``. Lines keep the epochs of :func:`map_epochs`. Positions from the ENU tracks about
    ``geodetic_origin`` (lat deg, lon deg, h m). Written a feature, and within a line
    :data:`ROWS` vertices, at a time."""

    def features() -> Iterator[dict]:
        for name, traj in trajectories.items():
            yield _line_feature({"system": name, "role": "estimate"}, traj.t, traj.pos_n, traj.pos_sd,
                                map_epochs(traj.t, decimate), geodetic_origin)
        for name, tr in truths.items():
            if tr.sparse:
                flat = bool(np.isnan(tr.pos_n[:, 2]).all())
                yield from (_feature({"system": name, "role": "truth", "t": t}, "Point", xy)
                            for t, xy in zip(np.round(tr.t, 6).tolist(), _lon_lat_h(tr.pos_n, geodetic_origin, flat)))
            else:
                yield _line_feature({"system": name, "role": "truth"}, tr.t, tr.pos_n, None, map_epochs(tr.t, decimate),
                                    geodetic_origin)

    with path.open("w") as fh:
        _write_json(fh, {"type": "FeatureCollection", "features": features()})
        fh.write("\n")


STRIDE_COLUMNS = ("stride", "t_start", "t_end", "length_m", "duration_s", "speed_mps", "climb_m", "clearance_m",
                  "motion")
"""strides.csv's columns after ``system`` (docs/contract.md), in order."""


def write_strides_csv(path: Path, systems: Mapping) -> bool:
    """``strides.csv``: one row per stride of every system that has strides
    (:meth:`~bodyfusion.core.system.SensorSystem.strides`); times s to the µs, lengths m to the
    mm. Writes nothing and returns False when no system has any."""
    rows = []
    for name, system in systems.items():
        cols = system.strides()
        if not cols or len(cols["stride"]) == 0:
            continue
        for k in range(len(cols["stride"])):
            values = []
            for c in STRIDE_COLUMNS:
                v = cols[c][k] if c in cols else ""
                values.append(str(v) if c in ("stride", "motion") or v == "" else
                              f"{float(v):.6f}".rstrip("0").rstrip(".") if c.startswith("t_") else
                              f"{float(v):.3f}")
            rows.append(",".join([name, *values]))
    if not rows:
        return False
    path.write_text("system," + ",".join(STRIDE_COLUMNS) + "\n" + "\n".join(rows) + "\n")
    return True
