"""Tables from robot recordings: a topic of a ROS 1 bag, a ROS 2 bag (sqlite3 or MCAP storage) or
an MCAP file read as a table whose columns are its messages' field paths
(``linear_acceleration.x``, ``header.stamp``), with rosbags (an optional dependency:
``pip install "bodyfusion[ros]"``).

A field that is a time (``builtin_interfaces/Time``, ROS 1 ``time``: ``sec`` and ``nanosec``)
reads as seconds; the pseudo-column :data:`RECEIVE_TIME` is the time the recorder stored the
message (s). Every other column must be a number. A layout reads a topic by giving a table
section ``topic`` beside its ``path`` (:class:`~bodyfusion.base.sections.TableSection`); the
section's column names are then field paths, e.g. an IMU's
``time_column: header.stamp``, ``acc_columns: [linear_acceleration.x, linear_acceleration.y,
linear_acceleration.z]``, ``gyro_columns: [angular_velocity.x, angular_velocity.y,
angular_velocity.z]`` (ROS's REP 103: m/s², rad/s).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.base.extras import import_optional

RECEIVE_TIME = "receive_time"
"""The pseudo-column of the time each message was recorded (the bag's own stamp), s."""


def _reader(path: Path) -> Any:
    """rosbags' reader of any of its recordings (a ROS 1 ``.bag``, a ROS 2 bag folder, an MCAP file)."""
    highlevel = import_optional("rosbags.highlevel", "ros", "reading a ROS bag or MCAP recording")
    typesys = import_optional("rosbags.typesys", "ros", "reading a ROS bag or MCAP recording")
    if not path.exists():
        raise InputError(path, "file not found")
    return highlevel.AnyReader([path], default_typestore=typesys.get_typestore(typesys.Stores.ROS2_HUMBLE))


def _field(message: Any, column: str) -> float:
    """The number at the field path ``column`` of a message; a time as seconds."""
    value = message
    for part in column.split("."):
        value = getattr(value, part)
    if hasattr(value, "sec") and hasattr(value, "nanosec"):
        return value.sec + 1e-9 * value.nanosec
    return float(value)


def read_topic(path: str | Path, topic: str, columns: Sequence[str]) -> dict[str, np.ndarray]:
    """``columns`` (field paths, or :data:`RECEIVE_TIME`) of every message of ``topic`` in the
    recording ``path``, in the order recorded. Errors name the file and topic: a topic not in the
    recording (the ones it has listed), a field its messages lack, a field that is no number."""
    path = Path(path)
    rows: list[list[float]] = []
    with _reader(path) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        if not connections:
            have = sorted({c.topic for c in reader.connections})
            raise InputError(path, f"no topic {topic!r} (it has {', '.join(have) or 'none'})")
        for connection, stamp_ns, raw in reader.messages(connections=connections):
            message = reader.deserialize(raw, connection.msgtype)
            try:
                rows.append([stamp_ns * 1e-9 if c == RECEIVE_TIME else _field(message, c) for c in columns])
            except AttributeError as err:
                raise InputError(path, f"topic {topic!r} ({connection.msgtype}): no field {err.name!r} in "
                                       f"{', '.join(columns)}") from None
            except (TypeError, ValueError):
                raise InputError(path, f"topic {topic!r} ({connection.msgtype}): a column of {', '.join(columns)} "
                                       "is not a number") from None
    data = np.array(rows, dtype=float).reshape(-1, len(columns))
    return {c: np.ascontiguousarray(data[:, k]) for k, c in enumerate(columns)}
