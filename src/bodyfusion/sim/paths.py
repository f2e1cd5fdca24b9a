"""Body paths for the simulator: horizontal curves parametrised by arc length.

A path is a chain of straight lines and circular arcs in the horizontal ENU plane
(East, North in metres). Headings are azimuths (rad, clockwise from North, the
project's convention, see :mod:`bodyfusion.nav.attitude`) and are kept *unwrapped* along
the path: two clockwise laps of a square end at azimuth ``start + 4π``, so a foot's
yaw never jumps by 2π.

Polyline corners are rounded with a turn radius (a circular arc tangent to both legs)
so the heading changes continuously. Path kinds (the ``kind`` key of the scenario's
``path`` section): ``polyline``, ``square``, ``rectangle``, ``loops`` (circles) and
``out_and_back``; each config model's :meth:`build` returns a :class:`BodyPath`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Union

import numpy as np
from pydantic import Field

from bodyfusion.base.sections import StrictModel
from bodyfusion.base.errors import ConfigError

__all__ = [
    "Arc",
    "BodyPath",
    "Line",
    "LoopsPath",
    "OutAndBackPath",
    "PATH_KINDS",
    "PathConfig",
    "PolylinePath",
    "RectanglePath",
    "SquarePath",
    "direction",
    "left_normal",
    "polyline_path",
]


def direction(azimuth: np.ndarray | float) -> np.ndarray:
    """Unit vector(s) (East, North) of an azimuth (clockwise from North); shape (..., 2)."""
    a = np.asarray(azimuth, dtype=float)
    return np.stack([np.sin(a), np.cos(a)], axis=-1)


def left_normal(azimuth: np.ndarray | float) -> np.ndarray:
    """Unit vector(s) (East, North) pointing to the left of a walker heading ``azimuth``."""
    a = np.asarray(azimuth, dtype=float)
    return np.stack([-np.cos(a), np.sin(a)], axis=-1)


@dataclass(frozen=True)
class Line:
    """Straight segment from ``start`` (E, N) along ``azimuth`` (rad) for ``length`` (m)."""

    start: tuple[float, float]
    azimuth: float
    length: float

    def at(self, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xy = np.asarray(self.start) + sigma[:, None] * direction(self.azimuth)
        return xy, np.full(sigma.shape, self.azimuth)

    @property
    def end(self) -> tuple[np.ndarray, float]:
        xy, az = self.at(np.array([self.length]))
        return xy[0], float(az[0])


@dataclass(frozen=True)
class Arc:
    """Circular arc of ``radius`` (m) entered at ``start`` (E, N) with heading ``azimuth0``;
    ``turn`` (rad) is the signed heading change, positive clockwise (a right turn)."""

    start: tuple[float, float]
    azimuth0: float
    radius: float
    turn: float

    @property
    def length(self) -> float:
        return self.radius * abs(self.turn)

    def at(self, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sign = 1.0 if self.turn >= 0 else -1.0
        az = self.azimuth0 + sign * sigma / self.radius
        # The centre lies on the side the walker turns to; right normal = -left normal.
        centre = np.asarray(self.start) - sign * self.radius * left_normal(self.azimuth0)
        xy = centre + sign * self.radius * left_normal(az)
        return xy, az

    @property
    def end(self) -> tuple[np.ndarray, float]:
        xy, az = self.at(np.array([self.length]))
        return xy[0], float(az[0])


Segment = Union[Line, Arc]


class BodyPath:
    """A chain of :class:`Line` and :class:`Arc` segments, evaluated by arc length.

    ``closed`` says the walk ends where it began (used for the truth's loop flag).
    """

    def __init__(self, segments: list[Segment], closed: bool = False) -> None:
        segments = [s for s in segments if s.length > 0]
        if not segments:
            raise ConfigError("path", "the path has zero length")
        self.segments = segments
        lengths = np.array([s.length for s in segments], dtype=float)
        self.s_start = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
        self.length = float(lengths.sum())
        self.closed = closed

    def at(self, s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Position (N, 2) (E, N in m) and unwrapped azimuth (N,) at arc lengths ``s`` (clipped to the path)."""
        s = np.clip(np.atleast_1d(np.asarray(s, dtype=float)), 0.0, self.length)
        idx = np.clip(np.searchsorted(self.s_start, s, side="right") - 1, 0, len(self.segments) - 1)
        xy = np.empty((s.size, 2))
        az = np.empty(s.size)
        order = np.argsort(idx, kind="stable")  # the points of each segment together, in their order
        first = np.flatnonzero(np.diff(idx[order], prepend=-1))
        for m in np.split(order, first[1:]):
            k = int(idx[m[0]])
            seg = self.segments[k]
            sigma = np.clip(s[m] - self.s_start[k], 0.0, seg.length)
            xy[m], az[m] = seg.at(sigma)
        return xy, az

    @property
    def start(self) -> tuple[np.ndarray, float]:
        xy, az = self.at(0.0)
        return xy[0], float(az[0])

    @property
    def end(self) -> tuple[np.ndarray, float]:
        xy, az = self.at(self.length)
        return xy[0], float(az[0])


def _wrap_pi(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def polyline_path(points: np.ndarray, turn_radius: float, *, closed: bool = False,
                  azimuths: list[float] | None = None, key: str = "path") -> BodyPath:
    """Lines through ``points`` (M, 2) with every interior corner rounded by ``turn_radius``.

    ``azimuths`` (optional, unwrapped, one per leg) gives the legs' headings exactly
    (avoids round-off when the caller knows them); otherwise they come from the points.
    """
    pts = np.asarray(points, dtype=float)
    legs = np.diff(pts, axis=0)
    lengths = np.hypot(legs[:, 0], legs[:, 1])
    if np.any(lengths <= 1e-9):
        k = int(np.flatnonzero(lengths <= 1e-9)[0])
        raise ConfigError(f"{key}.waypoints_m.{k + 1}", "repeats the previous waypoint")
    if azimuths is None:
        az = [math.atan2(legs[0, 0], legs[0, 1])]
        for k in range(1, len(legs)):
            turn = _wrap_pi(math.atan2(legs[k, 0], legs[k, 1]) - az[-1])
            if abs(abs(turn) - math.pi) < 1e-9:
                raise ConfigError(f"{key}.waypoints_m.{k}",
                                  "the path reverses here; use kind out_and_back for a U-turn")
            az.append(az[-1] + turn)
    else:
        az = list(azimuths)
    turns = [az[k + 1] - az[k] for k in range(len(az) - 1)]
    tangent = [turn_radius * math.tan(abs(t) / 2) for t in turns]
    segments: list[Segment] = []
    cursor = pts[0]
    for k in range(len(legs)):
        cut_in = tangent[k - 1] if k > 0 else 0.0
        cut_out = tangent[k] if k < len(turns) else 0.0
        straight = lengths[k] - cut_in - cut_out
        if straight < -1e-9:
            raise ConfigError(f"{key}.turn_radius_m",
                              f"{turn_radius:g} m is too large: the rounded corners do not fit "
                              f"on leg {k} ({lengths[k]:.3g} m)")
        line = Line((float(cursor[0]), float(cursor[1])), az[k], max(straight, 0.0))
        segments.append(line)
        cursor, _ = line.end
        if k < len(turns) and turns[k] != 0.0 and turn_radius > 0:
            arc = Arc((float(cursor[0]), float(cursor[1])), az[k], turn_radius, turns[k])
            segments.append(arc)
            cursor, _ = arc.end
    return BodyPath(segments, closed=closed)


# --------------------------------------------------------------------------- scenario models


class _PathBase(StrictModel):
    start_m: tuple[float, float] = (0.0, 0.0)
    """Where the walk starts (E, N in m)."""


class PolylinePath(StrictModel):
    """Straight legs through ``waypoints_m`` (E, N), corners rounded by ``turn_radius_m``."""

    kind: Literal["polyline"]
    waypoints_m: list[tuple[float, float]] = Field(min_length=2)
    turn_radius_m: float = Field(default=0.5, ge=0)

    def build(self) -> BodyPath:
        pts = np.asarray(self.waypoints_m, dtype=float)
        closed = bool(np.allclose(pts[0], pts[-1]))
        return polyline_path(pts, self.turn_radius_m, closed=closed)


class _QuadPath(_PathBase):
    """A four-sided loop walked ``laps`` times from a corner; turning right when ``clockwise``."""

    laps: int = Field(default=1, ge=1, le=10_000)
    clockwise: bool = True
    start_heading_deg: float = 0.0
    turn_radius_m: float = Field(default=0.5, ge=0)

    def _sides(self) -> tuple[float, float]:
        raise NotImplementedError

    def build(self) -> BodyPath:
        a, b = self._sides()
        turn = (math.pi / 2) * (1 if self.clockwise else -1)
        az0 = math.radians(self.start_heading_deg)
        sides = [a, b] * (2 * self.laps)
        azimuths = [az0 + k * turn for k in range(len(sides))]
        pts = [np.asarray(self.start_m, dtype=float)]
        for length, az in zip(sides, azimuths):
            pts.append(pts[-1] + length * direction(az))
        pts[-1] = pts[0].copy()
        return polyline_path(np.asarray(pts), self.turn_radius_m, closed=True, azimuths=azimuths)


class RectanglePath(_QuadPath):
    """A rectangle: first leg ``length_m`` along ``start_heading_deg``, then ``width_m``."""

    kind: Literal["rectangle"]
    length_m: float = Field(gt=0)
    width_m: float = Field(gt=0)

    def _sides(self) -> tuple[float, float]:
        return self.length_m, self.width_m


class SquarePath(_QuadPath):
    """A square of ``side_m``, first leg along ``start_heading_deg``."""

    kind: Literal["square"]
    side_m: float = Field(gt=0)

    def _sides(self) -> tuple[float, float]:
        return self.side_m, self.side_m


class LoopsPath(_PathBase):
    """A circle of ``radius_m`` walked ``laps`` times, entered along ``start_heading_deg``."""

    kind: Literal["loops"]
    radius_m: float = Field(gt=0)
    laps: float = Field(default=1, gt=0, le=10_000)
    clockwise: bool = True
    start_heading_deg: float = 0.0

    def build(self) -> BodyPath:
        turn = 2 * math.pi * self.laps * (1 if self.clockwise else -1)
        arc = Arc((float(self.start_m[0]), float(self.start_m[1])), math.radians(self.start_heading_deg),
                  self.radius_m, turn)
        return BodyPath([arc], closed=float(self.laps).is_integer())


class OutAndBackPath(_PathBase):
    """Out ``length_m`` along ``start_heading_deg`` and back, ``repeats`` times; each
    U-turn is a half circle of ``turn_radius_m`` to the ``turn`` side (a pedestrian's
    U-turn takes some room), so the way back runs 2·turn_radius_m beside the way out."""

    kind: Literal["out_and_back"]
    length_m: float = Field(gt=0)
    repeats: int = Field(default=1, ge=1, le=10_000)
    turn: Literal["left", "right"] = "right"
    start_heading_deg: float = 0.0
    turn_radius_m: float = Field(default=0.5, gt=0)

    def build(self) -> BodyPath:
        sign = 1.0 if self.turn == "right" else -1.0
        az = math.radians(self.start_heading_deg)
        cursor = np.asarray(self.start_m, dtype=float)
        segments: list[Segment] = []
        for k in range(2 * self.repeats):
            line = Line((float(cursor[0]), float(cursor[1])), az, self.length_m)
            segments.append(line)
            cursor, _ = line.end
            if k < 2 * self.repeats - 1:
                arc = Arc((float(cursor[0]), float(cursor[1])), az, self.turn_radius_m, sign * math.pi)
                segments.append(arc)
                cursor, az = arc.end
        return BodyPath(segments, closed=False)


PATH_KINDS: dict[str, type[StrictModel]] = {
    "polyline": PolylinePath,
    "square": SquarePath,
    "rectangle": RectanglePath,
    "loops": LoopsPath,
    "out_and_back": OutAndBackPath,
}
"""The scenario's ``path.kind`` → its section model (each has ``build() -> BodyPath``)."""

PathConfig = Union[PolylinePath, SquarePath, RectanglePath, LoopsPath, OutAndBackPath]
