"""The registry of truth formats a layout may name (``truth.format``).

Each reader turns the layout's truth section into one :class:`~bodyfusion.base.types.TruthTrack`
per scored system, positions in the navigation frame (ENU, m): ``wide`` (one row per epoch,
columns per system, in the file's declared frame), ``long`` (``system,t,east_m,north_m,up_m``,
what ``fusion simulate`` writes), ``phone_log`` (the surveyed points of a GetSensorData log,
about the layout's geodetic origin). A new format is one function added to the registry.

A live run that keeps a bounded history (``fusion live --keep``) reads its truth as it goes
instead (:class:`~bodyfusion.io.truth.TruthWindow`): each system's epochs from its own chunked reader
(:data:`TRUTH_STREAMS`; a format without one, or a truth in memory, is read whole once), held
from the earliest epoch a reader of the window still needs, so that a scored run of any length
holds a bounded truth.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterator, Mapping
from pathlib import Path

import numpy as np
import pymap3d

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.types import LOG, TruthTrack
from bodyfusion.core.layout import LENGTH_UNITS, TruthConfig
from bodyfusion.io.phone_log import read_getsensordata
from bodyfusion.io.truth import long_truth_chunks, read_truth_csv, read_truth_long_csv, wide_truth_chunks
from bodyfusion.nav.frames import apply_axis_map


def _wide(truth: TruthConfig, origin: tuple[float, float, float] | None,
          systems: Collection[str]) -> dict[str, TruthTrack]:
    tracks = read_truth_csv(truth, position_columns=truth.systems, time_column=truth.time_column,
                            time_scale=truth.time_scale, rate_hz=truth.rate_hz, skip_rows=truth.skip_rows,
                            delimiter=truth.delimiter, sparse=truth.sparse)
    metres = LENGTH_UNITS[truth.unit]
    return {name: TruthTrack(tr.t, apply_axis_map(truth.axes, tr.pos_n) * metres, tr.sparse)
            for name, tr in tracks.items()}


def _long(truth: TruthConfig, origin: tuple[float, float, float] | None,
          systems: Collection[str]) -> dict[str, TruthTrack]:
    tracks = read_truth_long_csv(truth, sparse=truth.sparse)
    return {name: tr for name, tr in tracks.items() if name in systems}


def _phone_log(truth: TruthConfig, origin: tuple[float, float, float] | None,
               systems: Collection[str]) -> dict[str, TruthTrack]:
    """The log's surveyed points (POSI lines), sparse truth for ``truth.score_systems``."""
    if truth.table is not None:
        raise ConfigError("truth.format", "a phone_log truth is read from its file; an in-memory truth table is "
                                          "read as format wide or long")
    ref = read_getsensordata(truth.path).reference
    if ref is None:
        raise ConfigError("truth.path", "the log has no POSI lines")
    if origin is None:
        raise ConfigError("geodetic_origin", "surveyed truth needs a geodetic origin")
    e, n, _ = pymap3d.geodetic2enu(ref.lat_deg, ref.lon_deg, np.full(len(ref.t), origin[2]), *origin)
    pos = np.column_stack([e, n, np.zeros(len(ref.t))])
    return {name: TruthTrack(ref.t, pos, sparse=True) for name in truth.score_systems}


def _wide_chunks(truth: TruthConfig, name: str) -> Iterator[TruthTrack]:
    metres = LENGTH_UNITS[truth.unit]
    for tr in wide_truth_chunks(truth.path, name, truth.systems[name], time_column=truth.time_column,
                                time_scale=truth.time_scale, rate_hz=truth.rate_hz, skip_rows=truth.skip_rows,
                                delimiter=truth.delimiter):
        yield TruthTrack(tr.t, apply_axis_map(truth.axes, tr.pos_n) * metres, truth.sparse)


def _long_chunks(truth: TruthConfig, name: str) -> Iterator[TruthTrack]:
    for tr in long_truth_chunks(truth.path, name):
        yield TruthTrack(tr.t, tr.pos_n, truth.sparse)


TruthReader = Callable[[TruthConfig, "tuple[float, float, float] | None", Collection[str]], dict[str, TruthTrack]]
TRUTH_FORMATS: dict[str, TruthReader] = {"wide": _wide, "long": _long, "phone_log": _phone_log}
"""``truth.format`` → reader(truth section, geodetic origin or None, the layout's system names)."""
TruthChunks = Callable[[TruthConfig, str], Iterator[TruthTrack]]
TRUTH_STREAMS: dict[str, TruthChunks] = {"wide": _wide_chunks, "long": _long_chunks}
"""``truth.format`` → reader of one system's track from the section's file a chunk at a time, in
time order, with the whole reader's checks and errors (:func:`truth_stream`)."""


def truth_stream(truth: TruthConfig, origin: tuple[float, float, float] | None,
                 name: str) -> Iterator[TruthTrack]:
    """System ``name``'s truth track in chunks, in time order: from :data:`TRUTH_STREAMS` for a
    file of a format that has one; else (a truth in memory, a topic, a group, surveyed points)
    read whole (:func:`read_truth`), one chunk. Nothing for a system the truth has no track
    for."""
    chunks = TRUTH_STREAMS.get(truth.format)
    if (chunks is not None and truth.path is not None and truth.table is None and truth.topic is None
            and truth.group is None):
        if truth.format != "wide" or name in truth.systems:
            yield from chunks(truth, name)
        return
    track = read_truth(truth, origin, [name]).get(name)
    if track is not None:
        yield track


MIN_TRUTH_EPOCHS = 10
"""Fewest epochs of a dense truth track inside its system's run that a score is computed from
(an alignment fitted to two points matches any track)."""


MAX_TRUTH_SPEED_MPS = 30.0
"""Fastest a dense truth track may move between two epochs (m/s, horizontal; a human foot in a
sprint's swing stays under ~20 m/s) when the step is longer than :data:`TRUTH_JUMP_M`: faster is
a drop-out written as a number, a marker glitch, or another track's rows."""
TRUTH_JUMP_M = 0.2
"""Shortest horizontal step (m) between two truth epochs judged against :data:`MAX_TRUTH_SPEED_MPS`
(below it a motion-capture track's noise over a short interval)."""
TRUTH_COVERAGE = 0.9
"""Least share of a system's run a dense truth track spans without a warning that the score is of
a part only."""


def check_truth_overlap(truths: Mapping[str, TruthTrack], spans: Mapping[str, tuple[float, float]],
                        layout: Path | None, truth_spans: Mapping[str, tuple[float, float]] | None = None) -> None:
    """Check the truth against the systems' time spans ``spans[name]`` (s) before scoring. Refuse
    (one line, naming the truth section) a dense truth with fewer than :data:`MIN_TRUTH_EPOCHS`
    epochs inside its system's span: its score would say nothing, or say 0.000. Warn (one line
    each) of a system the truth has no track for (not scored), of a dense track spanning less
    than :data:`TRUTH_COVERAGE` of its system's run (scored on that part only: a truth file cut
    short, or another recording's), and of its jumps (:func:`_warn_of_jumps`). ``truth_spans``:
    the tracks' own spans (first, last epoch, s) where ``truths`` hold a part of them (a live
    run's truth read as it went: its jumps are checked on the part held)."""
    unscored = [name for name in spans if name not in truths]
    if truths and unscored:
        LOG.warning("truth: no track for %s in the truth section's file: not scored", ", ".join(unscored))
    for name, track in truths.items():
        if track.sparse or name not in spans:
            continue
        t0, t1 = spans[name]
        first, last = (truth_spans or {}).get(name, (track.t[0], track.t[-1]))
        inside = int(np.count_nonzero((track.t >= t0) & (track.t <= t1)))
        if inside < MIN_TRUTH_EPOCHS:
            raise ConfigError("truth", f"{name}: {inside} truth epoch(s) within its run (t = {t0:.6g}–{t1:.6g} s; the "
                                       f"truth spans {first:.6g}–{last:.6g} s): a score needs at least "
                                       f"{MIN_TRUTH_EPOCHS} (check the truth's time column and time_scale)",
                              layout)
        _warn_of_jumps(name, track)
        covered = (min(t1, last) - max(t0, first)) / (t1 - t0) if t1 > t0 else 1.0
        if covered < TRUTH_COVERAGE:
            LOG.warning("truth: %s: the truth spans t = %.6g–%.6g s, %.0f %% of its run (t = %.6g–%.6g s): scored on "
                        "that part only", name, first, last, 100 * covered, t0, t1)


def _warn_of_jumps(name: str, track: TruthTrack) -> None:
    """Warn (one line) of a dense truth track's steps between consecutive epochs faster than
    :data:`MAX_TRUTH_SPEED_MPS` over more than :data:`TRUTH_JUMP_M`: the score counts them."""
    step = np.hypot(*np.diff(track.pos_n[:, :2], axis=0).T)
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = step / np.diff(track.t)
    jumps = np.flatnonzero((step > TRUTH_JUMP_M) & ~(speed <= MAX_TRUTH_SPEED_MPS))
    if jumps.size:
        LOG.warning("truth: %s: %d jump(s) faster than %g m/s between consecutive epochs (the first at t = %.6g s, "
                    "%.3g m in %.3g s): a drop-out written as a number, a marker glitch or another track's rows; the "
                    "score counts them",
                    name, jumps.size, MAX_TRUTH_SPEED_MPS, track.t[jumps[0] + 1], step[jumps[0]],
                    track.t[jumps[0] + 1] - track.t[jumps[0]])


def read_truth(truth: TruthConfig, origin: tuple[float, float, float] | None,
               systems: Collection[str]) -> dict[str, TruthTrack]:
    """The truth tracks a layout's truth section describes: from its file, or its in-memory table
    (empty without either)."""
    if truth.path is None and truth.table is None:
        return {}
    return TRUTH_FORMATS[truth.format](truth, origin, systems)
