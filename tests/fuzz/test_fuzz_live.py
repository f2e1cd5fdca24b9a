"""Fuzzing the live engine: the Vicon walk's rows, and the fuzzing recording's feet and phone (its
IMU and GNSS streams), pushed into a :class:`~bodyfusion.live.engine.LiveRun` with hostile edits —
a cell set to a bad value, a column missing, a row for a system of no such name, a row again
(late), a block of rows reversed, a time jump — into a run keeping all its history or a bounded
part of it (``keep_s``). A run either refuses the row with one
:class:`~bodyfusion.base.errors.FusionError` naming it, or closes with finite tracks; never
another exception.

Examples: ``BODYFUSION_FUZZ_EXAMPLES`` (as the file fuzzing; by default 18 here: a live run costs
about a second; a third of them for the phone); derandomised; each case's outcome goes to the
long mode's table as the file fuzzing's do (targets ``live rows``, ``live phone rows``)."""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bodyfusion.base.errors import FusionError
from bodyfusion.core.layout import load_layout
from bodyfusion.live.engine import LiveRun
from bodyfusion.live.sources import replay_rows
from tests.fuzz.recording import write_recording
from tests.fuzz.test_fuzz_inputs import CASE_OUTCOME, recorded
from tests.paths import CONFIGS

VICON = CONFIGS / "dual_foot_vicon.yaml"
EXAMPLES = int(os.environ.get("BODYFUSION_FUZZ_EXAMPLES", "18"))
BAD_CELLS = [math.nan, math.inf, -math.inf, 1e308, -1e308, 0.0, -1.0, 1e30, "abc", "", None, True, [], {}]
"""Values a live row's cell may hold."""


@dataclass(frozen=True)
class RowEdit:
    """One edit of the row stream at ``at`` (a fraction of the rows): ``how`` is set (a cell to
    ``value``), drop (a column), system (an unknown name), again (the row once more, late),
    reverse (the next 20 rows in reverse) or jump (every later time of the row's system shifted
    by ``value`` s)."""
    at: float
    how: str
    column: int
    value: object

    def __call__(self, rows: list[tuple[float, str, dict]]) -> list[tuple[float, str, dict]]:
        k = min(int(self.at * len(rows)), len(rows) - 1)
        t, name, row = rows[k]
        column = sorted(row)[self.column % len(row)]
        if self.how == "set":
            return [*rows[:k], (t, name, {**row, column: self.value}), *rows[k + 1:]]
        if self.how == "drop":
            return [*rows[:k], (t, name, {c: v for c, v in row.items() if c != column}), *rows[k + 1:]]
        if self.how == "system":
            return [*rows[:k], (t, "head", row), *rows[k + 1:]]
        if self.how == "again":
            return [*rows[:k + 1], rows[max(k - 5, 0)], *rows[k + 1:]]
        if self.how == "reverse":
            return [*rows[:k], *rows[k:k + 20][::-1], *rows[k + 20:]]
        shift = float(self.value) if isinstance(self.value, (int, float)) and math.isfinite(self.value) else 3600.0
        time_column = next((c for c in ("time_index", "t") if c in row), column)
        return [*rows[:k], *((t2, n2, {**r2, time_column: r2[time_column] + shift} if n2 == name else r2)
                             for t2, n2, r2 in rows[k:])]


row_edits = st.lists(st.builds(RowEdit, st.floats(0.0, 1.0),
                               st.sampled_from(["set", "set", "drop", "system", "again", "reverse", "jump"]),
                               st.integers(0, 20), st.sampled_from(BAD_CELLS)), min_size=1, max_size=3)


@pytest.fixture(scope="module")
def vicon_rows() -> list[tuple[float, str, dict]]:
    run = LiveRun(load_layout(VICON))
    return [(t, name, dict(row)) for t, name, row in replay_rows(run)]


def _recording_walk(prefix: str, drop: str | None) -> Iterator[tuple[Path, list[tuple[float, str, dict]]]]:
    """The fuzzing recording (feet, phone with IMU and GNSS CSVs but no magnetometer, UWB tags on
    the feet) without system ``drop`` (None: all of them), as a live layout, and its rows."""
    folder = Path(tempfile.mkdtemp(prefix=prefix))
    layout = yaml.safe_load(write_recording(folder)["csv"].read_text())
    if drop is not None:
        del layout["systems"][drop]
    layout["systems"]["hand_phone"].pop("magnetometer", None)
    path = folder / "layout_live.yaml"
    path.write_text(yaml.safe_dump(layout, sort_keys=False))
    run = LiveRun(load_layout(path))
    yield path, [(t, name, dict(row)) for t, name, row in replay_rows(run)]
    shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="module")
def phone_walk() -> Iterator[tuple[Path, list[tuple[float, str, dict]]]]:
    """The fuzzing recording's feet and phone (no UWB) as a live layout, and its rows."""
    yield from _recording_walk("fuzz_live_phone_", "feet_tags")


@pytest.fixture(scope="module")
def tag_walk() -> Iterator[tuple[Path, list[tuple[float, str, dict]]]]:
    """The whole fuzzing recording (feet, phone, the feet's UWB tags) as a live layout, and its rows."""
    yield from _recording_walk("fuzz_live_tags_", None)


def _push_all(config: Path, rows: list[tuple[float, str, dict]], edits: list[RowEdit], target: str,
              **live: float | None) -> None:
    """Push the edited ``rows`` into a live run of ``config``: refused in one error, or finite tracks."""
    for edit in edits:
        rows = edit(rows)
    with recorded(target, edits):
        run = LiveRun(load_layout(config), lookahead_s=2.0, **live)
        try:
            for _, name, row in rows:
                run.push(name, row)
            result = run.close()
        except FusionError as err:
            assert str(err) and "\n" not in str(err).strip(), err
            CASE_OUTCOME["outcome"] = "refused"
            return
        for name, track in result.trajectories.items():
            assert np.isfinite(track.pos_n).all() and np.isfinite(track.pos_sd).all(), name


@pytest.mark.slow
@settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(edits=row_edits, keep_s=st.sampled_from([None, 15.0, 40.0]))
def test_hostile_live_rows_are_refused_in_one_error_or_run_finite(vicon_rows, edits, keep_s):
    _push_all(VICON, vicon_rows, edits, "live rows", keep_s=keep_s)


@pytest.mark.slow
@settings(max_examples=max(EXAMPLES // 3, 5), deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(edits=row_edits)
def test_hostile_live_phone_rows_are_refused_in_one_error_or_run_finite(phone_walk, edits):
    """The 12 s walk starts after 3 s of data: the phone's GNSS rows ride beside its IMU's."""
    config, rows = phone_walk
    _push_all(config, rows, edits, "live phone rows", warmup_s=3.0)


@pytest.mark.slow
@settings(max_examples=max(EXAMPLES // 3, 5), deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(edits=row_edits, keep_s=st.sampled_from([None, 10.0]))
def test_hostile_live_uwb_rows_are_refused_in_one_error_or_run_finite(tag_walk, edits, keep_s):
    """The tags' ranges (an id as text) ride beside the feet's IMU rows, taken as they come."""
    config, rows = tag_walk
    _push_all(config, rows, edits, "live uwb rows", warmup_s=3.0, keep_s=keep_s)
