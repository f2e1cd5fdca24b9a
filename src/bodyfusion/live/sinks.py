"""Where a live run's output epochs go (:class:`~bodyfusion.core.epoch_state.EpochSink`): JSON
lines (a file, stdout or a TCP socket), a growing CSV, Parquet row groups, and MCAP.

Every sink writes each epoch as it comes and leaves a complete file when closed, which the
live run does on any exit, Ctrl-C included (:func:`open_sinks` returns them for a ``finally``).
The records:

* JSON lines: one object per epoch, :meth:`~bodyfusion.core.epoch_state.EpochState.to_dict`
  (``t``; ``systems``: name → ``t``, ``east_m``, ``north_m``, ``up_m``, ``sd_east_m``,
  ``sd_north_m``, ``sd_up_m``; ``health``: the fuser's counts since the epoch before; a
  smoothed epoch also ``smoothed_lag_s``).
* CSV and Parquet: one row per epoch and system, columns :data:`COLUMNS` (flushed each epoch;
  Parquet in row groups of :data:`ROWS_PER_GROUP`).
* MCAP (:mod:`mcap`, JSON encoding): per system a ``/bodyfusion/<system>/pose`` channel of
  ``foxglove.PoseInFrame`` messages (frame ``enu``; position only, the orientation is the
  identity), so that Foxglove and similar viewers draw the tracks as they grow, and one
  ``/bodyfusion/epoch`` channel with the whole epoch (its JSON line's object); the smoothed
  stream of a live fixed-lag smoother on ``/bodyfusion/<system>/pose_smoothed`` and
  ``/bodyfusion/epoch_smoothed``.

A live run with ``smoother.kind: fixed-lag`` writes two streams to the same sinks, interleaved in
the order they are made: the filtered epochs, and the smoothed epochs of the same grid some
seconds later (:mod:`bodyfusion.live.smoothed`).
"""

from __future__ import annotations

import json
import signal
import socket
import sys
from pathlib import Path
from typing import IO

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.extras import import_optional
from bodyfusion.base.interrupts import deferred
from bodyfusion.core.epoch_state import EpochSink, EpochState

COLUMNS = ("t", "system", "t_state", "east_m", "north_m", "up_m", "sd_east_m", "sd_north_m", "sd_up_m", "stream")
"""The CSV and Parquet sinks' columns: epoch time (s), system, the state's own time (s), ENU
position (m) and its one-sigma (m), and the stream: ``filtered``, or ``smoothed`` (a live
fixed-lag smoother's, :attr:`~bodyfusion.core.epoch_state.EpochState.smoothed_lag_s`)."""
TEXT_COLUMNS = ("system", "stream")
ROWS_PER_GROUP = 4096
"""Rows a Parquet row group holds."""
POSE_SCHEMA = {
    "title": "foxglove.PoseInFrame", "type": "object",
    "properties": {
        "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
        "frame_id": {"type": "string"},
        "pose": {"type": "object", "properties": {
            "position": {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}},
            "orientation": {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}}}}}}
"""JSON schema of Foxglove's PoseInFrame, as its viewers recognise it by title."""


class JsonLinesSink:
    """One JSON object per epoch on ``stream`` (a text file, stdout, a socket's file), flushed
    each epoch; ``owns``: close the stream at the end."""

    def __init__(self, stream: IO[str], owns: bool = True) -> None:
        self.stream = stream
        self.owns = owns

    def write(self, state: EpochState) -> None:
        self.stream.write(json.dumps(state.to_dict(), separators=(",", ":")) + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.owns:
            self.stream.close()
        else:
            self.stream.flush()


def _stream(state: EpochState) -> str:
    """The stream an epoch belongs to (:data:`COLUMNS`)."""
    return "filtered" if state.smoothed_lag_s is None else "smoothed"


def _rows(state: EpochState) -> list[tuple]:
    stream = _stream(state)
    return [(state.t, name, s.t, *map(float, s.position_n), *map(float, s.position_sd_m), stream)
            for name, s in state.systems.items()]


class CsvSink:
    """A growing CSV at ``path``: the header, then a row per epoch and system (:data:`COLUMNS`),
    flushed each epoch."""

    def __init__(self, path: Path) -> None:
        self.file = open(path, "w", encoding="utf-8", newline="")
        self.file.write(",".join(COLUMNS) + "\n")

    def write(self, state: EpochState) -> None:
        self.file.write("".join(",".join(repr(v) if isinstance(v, float) else str(v) for v in row) + "\n"
                                for row in _rows(state)))
        self.file.flush()

    def close(self) -> None:
        self.file.close()


class ParquetSink:
    """Parquet at ``path`` (:data:`COLUMNS`), a row group every :data:`ROWS_PER_GROUP` rows."""

    def __init__(self, path: Path) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        self._pa = pa
        self.schema = pa.schema([(c, pa.string() if c in TEXT_COLUMNS else pa.float64()) for c in COLUMNS])
        self.writer = pq.ParquetWriter(str(path), self.schema)
        self.rows: list[tuple] = []

    def write(self, state: EpochState) -> None:
        self.rows += _rows(state)
        if len(self.rows) >= ROWS_PER_GROUP:
            self._flush()

    def _flush(self) -> None:
        if self.rows:
            columns = list(zip(*self.rows))
            self.writer.write_table(self._pa.table(dict(zip(COLUMNS, columns)), schema=self.schema))
            self.rows = []

    def close(self) -> None:
        self._flush()
        self.writer.close()


class McapSink:
    """MCAP at ``path`` (module docstring): Foxglove poses per system and the whole epoch."""

    def __init__(self, path: Path) -> None:
        Writer = import_optional("mcap.writer", "live", "an .mcap sink", package="mcap").Writer
        self.file = open(path, "wb")
        self.writer = Writer(self.file)
        self.writer.start(profile="", library="bodyfusion")
        self._pose_schema = self.writer.register_schema(name="foxglove.PoseInFrame", encoding="jsonschema",
                                                        data=json.dumps(POSE_SCHEMA).encode())
        epoch_schema = self.writer.register_schema(name="bodyfusion.EpochState", encoding="jsonschema",
                                                   data=json.dumps({"type": "object"}).encode())
        self._epoch_schema = epoch_schema
        self._channels: dict[str, int] = {}

    def _channel(self, topic: str, schema: int) -> int:
        """The channel of ``topic``, registered when first used."""
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._channels[topic] = self.writer.register_channel(topic, "json", schema)
        return channel

    def write(self, state: EpochState) -> None:
        ns = int(round(state.t * 1e9))
        stamp = {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}
        suffix = "" if state.smoothed_lag_s is None else "_smoothed"
        for name, s in state.systems.items():
            channel = self._channel(f"/bodyfusion/{name}/pose{suffix}", self._pose_schema)
            x, y, z = (float(v) for v in s.position_n)
            pose = {"timestamp": stamp, "frame_id": "enu", "pose": {"position": {"x": x, "y": y, "z": z},
                                                                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0,
                                                                                    "w": 1.0}}}
            self.writer.add_message(channel, log_time=ns, publish_time=ns, data=json.dumps(pose).encode())
        self.writer.add_message(self._channel(f"/bodyfusion/epoch{suffix}", self._epoch_schema), log_time=ns,
                                publish_time=ns, data=json.dumps(state.to_dict()).encode())

    def close(self) -> None:
        self.writer.finish()
        self.file.close()


class EverySink:
    """Writes each epoch to all of ``sinks`` with SIGINT and SIGTERM held back meanwhile, so that an
    interrupted run leaves every sink at the same epoch, none with part of one: blocked in this
    thread, and only recorded by the command line's handlers (:func:`~bodyfusion.base.interrupts.deferred`)
    where another thread took the signal (the kernel gives a process's signal to any thread not
    blocking it, and Python runs its handler in the main thread, here)."""

    def __init__(self, sinks: list[EpochSink]) -> None:
        self.sinks = sinks
        self._held = {signal.SIGINT, signal.SIGTERM}

    def write(self, state: EpochState) -> None:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, self._held)
        try:
            with deferred():
                for sink in self.sinks:
                    sink.write(state)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)

    def close(self) -> None:
        for sink in self.sinks:
            sink.close()


def open_sink(target: str, overwrite: bool = False) -> EpochSink:
    """A sink by its target: ``-`` (JSON lines on stdout), ``tcp://HOST:PORT`` (JSON lines to a
    listening socket), else a file by its suffix: ``.jsonl``, ``.csv``, ``.parquet``, ``.mcap``.
    A target it cannot open, or a file that exists already (unless ``overwrite``), is refused
    (ConfigError naming ``--sink``)."""
    if target == "-":
        return JsonLinesSink(sys.stdout, owns=False)
    if target.startswith("tcp://"):
        host, _, port = target[len("tcp://"):].rpartition(":")
        try:
            connection = socket.create_connection((host or "127.0.0.1", int(port)), timeout=5.0)
        except (OSError, ValueError) as err:
            raise ConfigError("--sink", f"{target}: cannot connect ({err})") from None
        return JsonLinesSink(connection.makefile("w", encoding="utf-8"))
    path = Path(target)
    kinds = {".jsonl": lambda p: JsonLinesSink(open(p, "w", encoding="utf-8")), ".csv": CsvSink,
             ".parquet": ParquetSink, ".mcap": McapSink}
    make = kinds.get(path.suffix.lower())
    if make is None:
        raise ConfigError("--sink", f"{target}: unknown sink; give -, tcp://HOST:PORT or a file ending in "
                                    + ", ".join(kinds))
    if not path.parent.is_dir():
        raise ConfigError("--sink", f"{target}: no folder {path.parent}")
    if path.is_file() and not overwrite:
        raise ConfigError("--sink", f"{target}: exists; give another file, or --overwrite to replace it")
    try:
        return make(path)
    except OSError as err:
        raise ConfigError("--sink", f"{target}: cannot write ({err.strerror or err})") from None
