"""Truth read as a run goes: one system's track a chunk of lines at a time is the whole reader's
track, with its checks and errors, and a window holds only what its readers still need."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.base.errors import InputError
from bodyfusion.base.types import TruthTrack
from bodyfusion.io import lines
from bodyfusion.io.truth import (TruthWindow, long_truth_chunks, read_truth_csv, read_truth_long_csv,
                                 wide_truth_chunks)


@pytest.fixture(autouse=True)
def small_chunks(monkeypatch):
    monkeypatch.setattr(lines, "CHUNK_BYTES", 200)  # every file below spans many chunks


def _joined(chunks) -> TruthTrack:
    parts = list(chunks)
    return TruthTrack(np.concatenate([p.t for p in parts]), np.concatenate([p.pos_n for p in parts]))


def _long_file(path: Path, blocks: bool, n: int = 300) -> Path:
    """Two systems at 100 Hz (50 Hz for the second): one block of rows each, or interleaved in time."""
    rows = [("left", k / 100.0, 0.01 * k, -0.02 * k, 0.001 * k) for k in range(n)]
    rows += [("hand", k / 50.0, 1.0 + 0.02 * k, 0.5, 1.1) for k in range(n // 2)]
    if not blocks:
        rows.sort(key=lambda r: r[1])
    path.write_text("system,t,east_m,north_m,up_m\n" + "".join(f"{s},{t!r},{e!r},{n_!r},{u!r}\n"
                                                             for s, t, e, n_, u in rows))
    return path


@pytest.mark.parametrize("blocks", [True, False])
def test_a_long_files_tracks_in_chunks_are_the_whole_readers(tmp_path, blocks):
    path = _long_file(tmp_path / "truth.csv", blocks)
    whole = read_truth_long_csv(path)
    for name in ("left", "hand"):
        chunked = _joined(long_truth_chunks(path, name))
        np.testing.assert_array_equal(chunked.t, whole[name].t)
        np.testing.assert_array_equal(chunked.pos_n, whole[name].pos_n)
    assert list(long_truth_chunks(path, "right")) == []


def test_a_wide_files_track_in_chunks_is_the_whole_readers_with_its_dropouts_skipped(tmp_path):
    t = np.arange(400) / 100.0
    text = ["time,lx,ly,lz,hx,hy"]
    for k, tk in enumerate(t.tolist()):
        lz = "" if k % 37 == 5 else f"{0.3 * tk!r}"  # marker drop-outs of one system
        text.append(f"{tk * 1e3!r},{tk!r},{-tk!r},{lz},{2 * tk!r},{tk + 1!r}")
    path = tmp_path / "wide.csv"
    path.write_text("\n".join(text) + "\n")
    columns = {"left": ("lx", "ly", "lz"), "hand": ("hx", "hy")}
    whole = read_truth_csv(path, position_columns=columns, time_column="time", time_scale=1e-3)
    for name, cols in columns.items():
        chunked = _joined(wide_truth_chunks(path, name, cols, time_column="time", time_scale=1e-3))
        np.testing.assert_array_equal(chunked.t, whole[name].t)
        np.testing.assert_array_equal(chunked.pos_n, whole[name].pos_n)  # the horizontal one's heights NaN
    by_rate = _joined(wide_truth_chunks(path, "hand", ("hx", "hy"), rate_hz=100.0))
    np.testing.assert_array_equal(by_rate.t, read_truth_csv(path, position_columns={"hand": ("hx", "hy")},
                                                            rate_hz=100.0)["hand"].t)


@pytest.mark.parametrize("blocks", [True, False])
def test_a_time_that_goes_back_in_a_later_chunk_is_refused_with_its_line(tmp_path, blocks):
    path = _long_file(tmp_path / "truth.csv", blocks)
    text = path.read_text().splitlines()
    k = next(i for i, row in enumerate(text) if row.startswith("left,2.5,"))
    text[k] = text[k].replace("left,2.5,", "left,0.5,")
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(InputError) as whole:
        read_truth_long_csv(path)
    with pytest.raises(InputError) as chunked:
        list(long_truth_chunks(path, "left"))
    assert str(chunked.value) == str(whole.value)
    assert f"truth.csv:{k + 1}:" in str(chunked.value)


def test_a_wide_system_without_any_complete_row_is_refused(tmp_path):
    path = tmp_path / "wide.csv"
    path.write_text("t,x,y,z\n" + "".join(f"{k / 10!r},{k!r},{k!r},\n" for k in range(50)))
    with pytest.raises(InputError, match="no row with all of"):
        list(wide_truth_chunks(path, "foot", ("x", "y", "z"), time_column="t"))


@settings(max_examples=40, deadline=None)
@given(chunk=st.integers(1, 50), places=st.lists(st.floats(0.0, 10.0), min_size=1, max_size=8),
       hold=st.floats(0.0, 10.0))
def test_a_window_gives_the_epochs_it_is_asked_for_and_holds_no_more_than_its_readers_need(chunk, places, hold):
    t = np.arange(1000) / 100.0
    pos = np.column_stack([t, 2 * t, -t])
    window = TruthWindow(TruthTrack(t[k:k + chunk], pos[k:k + chunk]) for k in range(0, t.size, chunk))
    window.hold_from(hold)
    reader = 0
    window.place("scores", reader)  # a reader places itself before it reads
    for tp in sorted(places):
        b = window.index(tp, side="right")
        assert b == int(np.searchsorted(t, tp, side="right"))
        ts, ps = window.epochs_between(reader, b)
        np.testing.assert_array_equal(ts, t[reader:b])
        np.testing.assert_array_equal(ps, pos[reader:b])
        reader = b
        window.place("scores", reader)
        assert window.first == min(reader, int(np.searchsorted(t, hold)))  # what the reader or the hold needs
    held = window.track()  # read to the end: what is held from the first epoch still needed on
    first = window.first
    assert first <= min(reader, int(np.searchsorted(t, hold)))
    if first < t.size:
        np.testing.assert_array_equal(held.t, t[first:])
    else:  # every epoch read was passed by the reader and the hold
        assert held is None
    assert window.span == (t[0], t[-1]) and window.epochs == t.size and window.done and window.error is None


def test_a_file_refused_hours_in_ends_the_window_there_and_says_so(tmp_path, caplog):
    """A bad cell past the first chunks: the window holds the track up to the chunk before it,
    keeps the reader's error and warns once; a run reading its truth as it goes scores to there."""
    path = _long_file(tmp_path / "truth.csv", blocks=True)
    text = path.read_text().splitlines()
    text[250] = text[250].rsplit(",", 1)[0] + ",oops"  # line 251: a height that is not a number
    path.write_text("\n".join(text) + "\n")
    window = TruthWindow(long_truth_chunks(path, "left"), "left")
    with caplog.at_level("WARNING"):
        window.read_through(math.inf)
    assert window.done and isinstance(window.error, InputError) and "truth.csv:251:" in str(window.error)
    assert 0 < window.epochs < 249 and window.span[1] < 2.49
    assert sum("the truth of left ends at" in r.getMessage() for r in caplog.records) == 1
    window.read_through(math.inf)  # no second warning, no second read
    assert sum("the truth of left ends at" in r.getMessage() for r in caplog.records) == 1
