"""The line scan a table read starts with: line count, plain line ends, UTF-8 checked."""

from __future__ import annotations

import pytest

from bodyfusion.base.errors import InputError
from bodyfusion.io import lines


@pytest.fixture(autouse=True)
def small_chunks(monkeypatch):
    monkeypatch.setattr(lines, "CHUNK_BYTES", 16)  # every file below spans several chunks


@pytest.mark.parametrize(("content", "expected"), [
    (b"t,x\n0,1\n1,2\n2,3\n3,4\n4,5\n", (7, True)),
    (b"t,x\r\n0,1\r\n1,2\r\n2,3\r\n3,4\r\n4,5", (6, True)),
    (b"t,x\n0,1\n1,2\n2,3\n3,4\n4,5\r6\n", (7, False)),  # a carriage return alone, in a later chunk
    ("\ufefft,\u00e9\n0,1\n1,2\n2,3\n3,\u00e9\n".encode(), (6, True)),  # byte order mark, non-ASCII UTF-8
    (b"", (1, True)),
])
def test_scan_counts_lines_and_finds_carriage_returns(tmp_path, content, expected):
    path = tmp_path / "table.csv"
    path.write_bytes(content)
    assert lines.scan_text(path) == expected


def test_scan_names_the_first_line_that_is_not_utf8(tmp_path):
    path = tmp_path / "table.csv"
    path.write_bytes(b"t,x\n0,1\n1,2\n2,3\n3,4\n4,\xff\n5,6\n")
    with pytest.raises(InputError, match=r"table.csv:6: not a UTF-8 text file"):
        lines.scan_text(path)
