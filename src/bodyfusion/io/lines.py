"""Text files a chunk of lines at a time: a reader holds one chunk's text (about
:data:`CHUNK_BYTES`), never all the lines of a long recording at once.

Lines are split at ``\\n``, one ``\\r`` before it dropped (CR LF files); the text must be UTF-8
(a byte order mark at the start is dropped); an error names the file and the line.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from bodyfusion.base.errors import InputError
from bodyfusion.base.files import file_problem

CHUNK_BYTES = 1 << 20
"""A file is read and parsed this many bytes (whole lines) at a time: reading it holds the numbers
(in arrays sized once from its line count) and one chunk's text, never all its lines at once."""


def regular_file(path: Path) -> Path:
    """``path``, once it names a regular file (:func:`~bodyfusion.base.files.file_problem`: not a
    FIFO, device or folder); else an :class:`InputError` naming it."""
    problem = file_problem(path)
    if problem is not None:
        raise InputError(path, problem)
    return path


def _opened(path: Path) -> BinaryIO:
    try:
        return regular_file(path).open("rb")
    except OSError as err:
        raise InputError(path, f"cannot read file: {err.strerror or err}") from None


def _blocks(path: Path) -> Iterator[bytes]:
    """The file's bytes in blocks of about :data:`CHUNK_BYTES`, each ending at a line end (the
    last at the end of the file)."""
    with _opened(path) as fh:
        rest = b""
        while True:
            try:
                block = fh.read(CHUNK_BYTES)
            except OSError as err:
                raise InputError(path, f"cannot read file: {err.strerror or err}") from None
            if not block:
                break
            block = rest + block
            cut = block.rfind(b"\n") + 1
            rest = block[cut:]
            if cut:
                yield block[:cut]
        if rest:
            yield rest


def _decoded(path: Path, block: bytes, first: bool, line: int) -> str:
    """A block as text (UTF-8, a byte order mark dropped at the file's start); an error names
    the line (``line``: the block's first) of the first byte that is not UTF-8."""
    try:
        return block.decode("utf-8-sig" if first else "utf-8")
    except UnicodeDecodeError as err:
        raise InputError(path, "not a UTF-8 text file", line + block[: err.start].count(b"\n")) from None


def line_chunks(path: Path) -> Iterator[tuple[int, list[str]]]:
    """The file's lines, a chunk at a time: (line number of the chunk's first line, its lines,
    each without its line end ``\\n`` or ``\\r\\n``), as :func:`read_lines` splits them. A chunk
    that is not UTF-8 raises (:func:`scan_lines` checks the whole file first)."""
    line = 1
    for k, block in enumerate(_blocks(path)):
        lines = _decoded(path, block, k == 0, line).split("\n")
        if block.endswith(b"\n"):
            lines.pop()  # what follows the chunk's last line end is the next chunk's
        yield line, [ln.removesuffix("\r") for ln in lines]
        line += len(lines)
    if line == 1 or block.endswith(b"\n"):
        yield line, [""]  # the (empty) line after the last line end


def scan_lines(path: Path) -> int:
    """The number of lines of the file as :func:`read_lines` splits it (line ends + 1), checking
    on the way that it is UTF-8 text (an error names the first line that is not)."""
    return scan_text(path)[0]


def scan_text(path: Path) -> tuple[int, bool]:
    """:func:`scan_lines`, and whether every line end is a plain ``\n`` or ``\r\n`` (no
    carriage return elsewhere, which other CSV readers take for a line end too)."""
    ends = 0
    plain = True
    for k, block in enumerate(_blocks(path)):
        if not block.isascii():  # ASCII text is UTF-8 without a byte order mark: nothing to check
            _decoded(path, block, k == 0, ends + 1)
        ends += block.count(b"\n")
        if plain and b"\r" in block:
            plain = block.count(b"\r") == block.count(b"\r\n")
    return ends + 1, plain


def read_lines(path: Path) -> list[str]:
    """All lines of a (small) text file, without their line ends (see :func:`line_chunks`)."""
    return [ln for _, lines in line_chunks(path) for ln in lines]
