"""Where a live run's rows come from: a replay of the layout's own recordings, or a line stream.

* Replay (:func:`replay_rows`, :func:`replay`): every system's recording read as its data
  section reads it (the same columns and units), merged in time order and pushed at the
  recording's pace × ``speed`` (None: as fast as the run takes them).
* Line stream (:func:`line_rows`): lines over TCP (the run listens; one client) or UDP (one or
  more lines per datagram), each one row, as JSON or CSV (:class:`LineReader`; the two may mix):

  - JSON: ``{"system": NAME, COLUMN: VALUE, ...}``, the columns those the system's data section
    names (a foot INS: its ``time_column``, ``acc_columns``, ``gyro_columns`` and
    ``stance_column``, in the section's units); a row of an aiding section adds ``"section":
    SECTION`` (a phone's fix: ``"section": "gnss"`` with the ``gnss`` section's ``time_column``,
    ``lat_column``...).
  - CSV: ``STREAM,VALUE,...``, the stream a system's name (its data section) or
    ``NAME.SECTION`` (``hand.gnss``), the values in the order of a header line ``#STREAM,COLUMN,...``
    sent before (any order, every column the section reads), or without one in the order of the
    section's columns (:meth:`~bodyfusion.base.sections.TableSection.required_columns`: an IMU
    section's ``acc_columns``, ``gyro_columns``, ``stance_column``, ``time_column``; a GNSS
    section's ``time_column``, ``lat_column``, ``lon_column``, ``height_column``,
    ``accuracy_column``, ``speed_column``, ``course_column``; those set).

  A line that is neither is refused with its number. The stream ends when the client closes
  (TCP) or an end line arrives (``{"end": true}`` or ``end``).
"""

from __future__ import annotations

import csv
import heapq
import json
import socket
import time
from collections.abc import Callable, Iterator

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.io.tables import source_chunks
from bodyfusion.live.engine import LiveRun, RowBuffer

Row = tuple[float, str, dict[str, float]]
"""(t s, system, column → value)."""


def _recording_rows(order: int, name: str, buffer: RowBuffer) -> Iterator[tuple[float, int, str, dict[str, float]]]:
    """System ``name``'s recording as its data section reads it, a chunk of the file at a time
    (:func:`~bodyfusion.io.tables.source_chunks`): (t, order, name, column → value), each row made
    as it is asked for."""
    first = 0
    for arrays in source_chunks(buffer.section, buffer.columns):
        times = np.asarray(buffer.times(arrays, first), dtype=float)
        table = np.column_stack([np.asarray(arrays[c], dtype=float) for c in buffer.columns])
        columns = list(buffer.columns)
        for t, values in zip(times.tolist(), table):
            yield t, order, name, dict(zip(columns, values.tolist()))
        first += len(times)


def _text_recording_rows(order: int, name: str, buffer: RowBuffer) -> Iterator[tuple[float, int, str, dict]]:
    """As :func:`_recording_rows`, for a section with text columns (a UWB tag's ids): its file read
    a line at a time with :mod:`csv` (the cells as text, which the row buffer reads as its section
    does), or its in-memory table's rows."""
    section = buffer.section
    if section.table is not None:
        columns = {c: np.asarray(section.table[c]) for c in buffer.columns}
        lines = (dict(zip(columns, values)) for values in zip(*columns.values()))
        numbers = ((k, row) for k, row in enumerate(lines, start=1))
        where = buffer.key
    else:
        where = str(section.path)
        numbers = _csv_rows(section.path, buffer.columns, getattr(section, "delimiter", ","))
    for k, (line, row) in enumerate(numbers):
        t = buffer.time_of(row, k)
        if t is None:
            raise InputError(where, f"row {line}: its time is no finite number")
        yield t, order, name, row


def _csv_rows(path, columns: list[str], delimiter: str) -> Iterator[tuple[int, dict[str, str]]]:
    """(line number, column → cell) of every row of a CSV file with a header line."""
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.reader(f, delimiter=delimiter)
        header = [h.strip() for h in next(reader, [])]
        missing = [c for c in columns if c not in header]
        if missing:
            raise InputError(path, f"missing column(s) {', '.join(missing)}; the header has {', '.join(header)}", 1)
        idx = [header.index(c) for c in columns]
        for cells in reader:
            if not any(cell.strip() for cell in cells):
                continue
            if len(cells) <= max(idx):
                raise InputError(path, f"row has {len(cells)} fields, the header has {len(header)}", reader.line_num)
            yield reader.line_num, {c: cells[j].strip() for c, j in zip(columns, idx)}


def replay_rows(run: LiveRun) -> Iterator[Row]:
    """Every system's recording, row by row in time order (ties: the layout's system order), read
    as its data section reads it (its columns, units, delimiter and header rows) a chunk of the
    file at a time: a replay of a recording of any length holds one chunk of each, not the
    recording."""
    streams = [(_text_recording_rows if buffer.text_columns else _recording_rows)(order, name, buffer)
               for order, (name, buffer) in enumerate(run.buffers.items())]
    for t, _, name, row in heapq.merge(*streams, key=lambda r: (r[0], r[1])):
        yield t, name, row


def replay(run: LiveRun, rows: Iterator[Row], speed: float | None = None,
           every_s: float = 5.0, status: Callable[[LiveRun, float], None] | None = None) -> None:
    """Push ``rows`` into ``run`` at the recording's pace × ``speed`` (None: at once), telling
    ``status(run, t)`` every ``every_s`` of wall time."""
    wall0 = time.perf_counter()
    t0 = None
    last_status = wall0
    for t, name, row in rows:
        if t0 is None:
            t0 = t
        if speed is not None:
            wait = wall0 + (t - t0) / speed - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
        run.push(name, row)
        if status is not None and time.perf_counter() - last_status >= every_s:
            last_status = time.perf_counter()
            status(run, t)


END = ("\0end", {})
"""What :meth:`LineReader.row` gives for the stream's end line (no stream has a NUL in its name)."""


class LineReader:
    """The lines of a stream ``where`` as rows of ``run``'s streams (module docstring: a JSON
    object, or CSV values after a ``#`` header or in the section's column order); a line that is
    neither is refused naming its number."""

    def __init__(self, run: LiveRun, where: str) -> None:
        self.run, self.where = run, where
        self.orders: dict[str, list[str]] = {}
        """Per stream, the order of its CSV values (from its ``#`` header; else its section's columns)."""

    def row(self, raw: bytes, number: int) -> tuple[str, dict[str, float]] | None:
        """(stream, column → value) of line ``number``; None for a blank line or a header;
        :data:`END` for the end line."""
        at = f"{self.where}: line {number}"
        try:
            line = raw.decode("utf-8").strip()
        except UnicodeDecodeError:
            raise InputError(at, "not UTF-8 text") from None
        if not line:
            return None
        if line.startswith(("{", "[")):  # JSON (an array is refused as no object)
            return self._json(line, at)
        parts = [p.strip() for p in line.split(",")]
        if parts[0].startswith("#"):
            name, buffer = self._buffer(parts[0][1:].strip(), None, at)
            missing = [c for c in buffer.columns if c not in parts[1:]]
            if missing:
                raise InputError(at, f"the header of {name} lacks column(s) {', '.join(missing)}")
            self.orders[name] = parts[1:]
            return None
        if parts == ["end"]:
            return END
        name, buffer = self._buffer(parts[0], None, at)
        order = self.orders.get(name, buffer.columns)
        if len(parts) - 1 != len(order):
            raise InputError(at, f"{name} takes {len(order)} values ({', '.join(order)}), not {len(parts) - 1}")
        return name, self._numbers(dict(zip(order, parts[1:])), name, buffer, at)

    def _json(self, line: str, at: str) -> tuple[str, dict[str, float]]:
        try:
            obj = json.loads(line)
        except json.JSONDecodeError as err:
            raise InputError(at, f"not JSON ({err.msg})") from None
        if not isinstance(obj, dict):
            raise InputError(at, "not a JSON object")
        if obj.get("end") is True:
            return END
        system, section = obj.pop("system", None), obj.pop("section", None)
        name, buffer = self._buffer(str(system), None if section is None else str(section), at)
        return name, self._numbers(obj, name, buffer, at)

    def _buffer(self, system: str, section: str | None, at: str) -> tuple[str, RowBuffer]:
        """The stream's name and buffer, else refused naming the line."""
        name = self.run.stream_name(system, section)
        if name not in self.run.buffers:
            raise InputError(at, f"system {system!r}{'' if section is None else f' section {section!r}'} is no "
                                 f"stream of this layout ({', '.join(self.run.buffers)})")
        return name, self.run.buffers[name]

    @staticmethod
    def _numbers(cells: dict, name: str, buffer: RowBuffer, at: str) -> dict[str, float | str]:
        """The section's columns of ``cells``: finite floats (NaN or empty too in a gap column: a
        failed ranging), text in a text column (an anchor's id); else refused naming them."""
        try:
            row = {c: buffer.cell(c, cells[c]) for c in buffer.columns}
        except KeyError:  # a column missing
            row = {}
        if len(row) < len(buffer.columns) or None in row.values():
            raise InputError(at, f"{name} needs finite numbers in columns {', '.join(buffer.number_columns)}"
                             + (f" and names in {', '.join(buffer.text_columns)}" if buffer.text_columns else ""))
        return row


def line_rows(run: LiveRun, address: str, *, timeout_s: float = 60.0) -> Iterator[Row]:
    """Rows from a line stream at ``tcp://HOST:PORT`` or ``udp://HOST:PORT`` (module docstring);
    ``timeout_s``: the longest wait for a client or a datagram."""
    scheme, _, rest = address.partition("://")
    host, _, port = rest.rpartition(":")
    kind = {"tcp": socket.SOCK_STREAM, "udp": socket.SOCK_DGRAM}.get(scheme)
    if kind is None or not port.isdigit():
        raise InputError(address, "give tcp://HOST:PORT or udp://HOST:PORT")
    server = socket.socket(socket.AF_INET, kind)
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.settimeout(timeout_s)
    try:
        server.bind((host or "127.0.0.1", int(port)))
    except (OSError, OverflowError) as err:  # a name that does not resolve, a port beyond 65535, one taken
        server.close()
        raise InputError(address, f"cannot listen there ({err})") from None
    try:
        if scheme == "tcp":
            server.listen(1)
            connection, _ = server.accept()
            connection.settimeout(timeout_s)
            lines = iter(connection.makefile("rb"))
        else:
            lines = (line for packet in iter(lambda: server.recv(65536), b"") for line in packet.splitlines())
        reader = LineReader(run, address)
        for number, line in enumerate(lines, start=1):
            got = reader.row(line, number)
            if got is None:
                continue
            if got is END:
                return
            yield float("nan"), got[0], got[1]
    except socket.timeout:
        raise InputError(address, f"nothing arrived for {timeout_s:g} s") from None
    finally:
        server.close()
