"""The two ways a delimited table is read — Arrow's CSV reader for the files it reads exactly
as the chunked reader does, the chunked reader for every other — give the same numbers, line
numbers, labels and errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bodyfusion.base.errors import InputError
from bodyfusion.io import tables

COLUMNS = ["t", "x", "y"]

clean_number = st.floats(-1e6, 1e6, allow_nan=False).map(repr) | st.integers(-1000, 1000).map(str)
odd_cell = st.sampled_from(["", " 1.5", "1.5 ", '"2.5"', "'3'", "nan", "NaN", "inf", "-inf", "NA", "1e3", ".5",
                            "5.", "+4", "1_000", "x", "0x10", "1e400"])
cell = st.one_of(clean_number, clean_number, clean_number, odd_cell)
label = st.sampled_from(["left", "right", ' "left" ', "hand", "right "])


@st.composite
def table_file(draw) -> bytes:
    rows = draw(st.integers(1, 12))
    labelled = draw(st.booleans())
    header = (["system"] if labelled else []) + COLUMNS + (["extra"] if draw(st.booleans()) else [])
    lines = [",".join(header)]
    for _ in range(rows):
        cells = [draw(label)] if labelled else []
        cells += [draw(cell) for _ in COLUMNS]
        if len(header) > len(cells):
            cells.append(draw(clean_number))
        if draw(st.integers(0, 20)) == 0:
            cells = cells[:-1]  # a short row
        lines.append(",".join(cells))
        if draw(st.integers(0, 15)) == 0:
            lines.append(draw(st.sampled_from(["", "   "])))  # a blank line
    end = draw(st.sampled_from(["\n", "\r\n", "\r\n", "\n", "\r"]))
    text = end.join(lines) + (end if draw(st.booleans()) else "")
    bom = "\ufeff" if draw(st.integers(0, 10)) == 0 else ""
    return (bom + text).encode()


def read(path, label):
    try:
        return tables.read_labelled_table(path, COLUMNS, label, allow_missing=("y",))
    except InputError as err:
        return str(err)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(content=table_file())
def test_arrow_and_chunked_readers_agree_on_every_file(content, tmp_path, monkeypatch):
    path = tmp_path / "table.csv"
    path.write_bytes(content)
    label = "system" if content.lstrip(b"\xef\xbb\xbf").startswith(b"system") else None
    fast = read(path, label)
    with monkeypatch.context() as m:
        m.setattr(tables, "read_clean_table", lambda *args, **kwargs: None)
        chunked = read(path, label)
    if isinstance(chunked, str):
        assert fast == chunked
        return
    assert not isinstance(fast, str), fast
    for name in COLUMNS:
        np.testing.assert_array_equal(fast[0][name], chunked[0][name])
    np.testing.assert_array_equal(fast[1], chunked[1])
    if label is not None:
        np.testing.assert_array_equal(fast[2][0], chunked[2][0])
        assert fast[2][1] == chunked[2][1]


def test_a_clean_file_is_read_by_arrow(tmp_path, monkeypatch):
    """The agreement above is not only the chunked reader agreeing with itself: a plain
    numeric file takes the Arrow path, labels and empty cells of an allowed column included."""
    path = tmp_path / "truth.csv"
    path.write_text("system,t,x,y\nleft,0.0,1.5,\n\"right\",0.01,-2e-3,4\nleft,0.02,3,5\n")
    taken = []
    arrow = tables.read_clean_table
    monkeypatch.setattr(tables, "read_clean_table", lambda *a, **k: taken.append(arrow(*a, **k)) or taken[-1])
    arrays, line_no, (codes, names) = tables.read_labelled_table(path, COLUMNS, "system", allow_missing=("y",))
    assert taken and taken[0] is not None
    np.testing.assert_array_equal(arrays["x"], [1.5, -2e-3, 3.0])
    np.testing.assert_array_equal(arrays["y"], [np.nan, 4.0, 5.0])
    np.testing.assert_array_equal(line_no, [2, 3, 4])
    assert names == ["left", "right"] and codes.tolist() == [0, 1, 0]


@pytest.mark.parametrize("body", ["0,1,2\n\n1,2,3\n", "0,1,2\r1,2,3\n", "0,1,NA\n", "0,'1',2\n"])
def test_files_arrow_would_read_differently_go_to_the_chunked_reader(body, tmp_path):
    path = tmp_path / "table.csv"
    path.write_text("t,x,y\n" + body)
    assert tables.read_clean_table(path, COLUMNS, 3, [0, 1, 2], None, 1, body.count("\n") + 2,
                                 ",", np.array([False, False, False])) is None
