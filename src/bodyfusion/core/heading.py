"""One navigation frame for systems worn together.

IMUs on two feet are rarely mounted with the same yaw, a heading set by hand is rarely right,
and each system's heading then drifts on its own. Two mechanisms keep every system of a layout
in one frame, with no setting from the user:

* At the start (:func:`align_headings`), every system whose ``heading_deg`` is ``auto`` (the
  default of a foot INS) is rotated about its start point so that its first ``distance_m`` of
  travel points the way the reference's does; then every system without a given initial
  position is put where it is worn (a left foot half a stance to the left of the walking
  direction, :meth:`~bodyfusion.core.capabilities.BodyPlacement.place_on_body`). The reference
  (:func:`heading_reference`) is the layout's ``heading_alignment.reference``, else a system
  whose heading is geographic (GNSS, a magnetometer: its fixes are metres off, so a system is
  turned by the rotation that lays its whole track onto the reference's fixes,
  :func:`track_rotation`), else the first system with a numeric heading, else the first that
  travels.
* Throughout the run (:class:`HeadingTie`, applied by the fuser), the relative heading of every
  other system with a heading error state is measured against the reference's: both walk the
  same path, so over each stretch of ``window_m`` of travel their tracks have one shape. The
  rotation that lays the system's track onto the reference's (about their centroids) measures
  the difference of their heading errors (each the rotation about Up, counter-clockwise, that
  turns the estimate into the truth; :meth:`~bodyfusion.core.capabilities.HeadingAlignment.yaw_error_row`):

      z = ∠(track_S → track_R) = δθ_S − δθ_R,   σ_z² = (σ_S² + σ_R²) / r²,

  r the tracks' RMS distance from their centroids, each track moved onto the body's centreline
  first (a left foot walks half a stance to the left of it), σ a track's lateral uncertainty over the
  stretch: ``lateral_sd_m`` for a dead-reckoning system (the feet's paths differ by their
  stance width and gait phase), the horizontal position σ for one with absolute position
  fixes. It is a gated scalar update of their joint error state (Joseph form), relative for
  both; consecutive stretches share only their end points, so no stretch is counted twice.

Azimuths are clockwise from North, radians; rotations about Up counter-clockwise.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from bodyfusion.base.errors import FusionError
from bodyfusion.core.capabilities import AbsoluteFixes, BodyPlacement, HeadingAlignment, offers
from bodyfusion.core.layout import HeadingAlignmentConfig
from bodyfusion.core.system import SensorSystem

ABSOLUTE_REFERENCE_M = 30.0
"""Least travel (m) over which a geographic reference's first azimuth is taken: its positions
come from fixes a few metres apart from the truth."""


def wrap_angle(a: float) -> float:
    """Wrap to (−π, π]."""
    return float(-((-a + np.pi) % (2 * np.pi) - np.pi))


def with_heading(systems: Mapping[str, SensorSystem]) -> dict[str, SensorSystem]:
    """The systems whose heading may be aligned (:class:`~bodyfusion.core.capabilities.HeadingAlignment`)."""
    return {name: s for name, s in systems.items() if offers(s, HeadingAlignment)}


def heading_reference(systems: Mapping[str, SensorSystem], cfg: HeadingAlignmentConfig) -> str | None:
    """The system every other is aligned to (module docstring), among those with a heading; None
    without a candidate."""
    aligned = with_heading(systems)
    if cfg.reference is not None:
        if cfg.reference not in aligned:
            raise FusionError(f"heading_alignment.reference: {cfg.reference!r} ({systems[cfg.reference].plugin_name}) "
                              "has no heading to align to")
        return cfg.reference
    absolute = [n for n, s in aligned.items() if s.heading_is_absolute]
    fixed = [n for n, s in aligned.items() if not s.heading_is_auto and n not in absolute]
    ordered = absolute + fixed + [n for n in aligned if n not in absolute and n not in fixed]
    return ordered[0] if ordered else None


def lateral_offset_m(system: SensorSystem) -> float:
    """Where the system is worn, m to the right of the body's centreline (0 for a system that
    does not know: :class:`~bodyfusion.core.capabilities.BodyPlacement`)."""
    return system.lateral_offset_m if offers(system, BodyPlacement) else 0.0


def standalone_track(system: SensorSystem) -> tuple[np.ndarray, np.ndarray] | None:
    """The system's track run alone to its end (t (N,) s, horizontal positions (N, 2) m), then
    restarted; None for a system that cannot restart."""
    restart = getattr(system, "restart", None)
    if restart is None:
        return None
    system.advance(system.t_end)
    track = system.trajectory()
    restart()
    return np.asarray(track.t, dtype=float), np.asarray(track.pos_n, dtype=float)[:, :2]


def geographic_track(system: SensorSystem) -> tuple[np.ndarray, np.ndarray] | None:
    """What a geographic reference knows of where it was: its absolute sensor's own fixes
    (:meth:`~bodyfusion.core.capabilities.AbsoluteFixes.absolute_fixes`, outside any outage), else
    its track run alone."""
    fixes = system.absolute_fixes() if offers(system, AbsoluteFixes) else None
    if fixes is not None and len(fixes[0]) >= 3:
        return np.asarray(fixes[0], dtype=float), np.asarray(fixes[1], dtype=float)[:, :2]
    return standalone_track(system)


def track_rotation(moving: tuple[np.ndarray, np.ndarray], reference: tuple[np.ndarray, np.ndarray]) -> float | None:
    """The clockwise rotation (rad, as azimuth) that best lays the ``moving`` track onto the
    ``reference`` one over all the time they share (the moving track interpolated to the
    reference's times; 2-D Procrustes about their centroids: the fixes' errors, metres wandering
    over a minute, average out only over the whole track, ~1-2° on a 370 m walk with 4 m fixes);
    None when they share no stretch of travel."""
    t_m, p_m = moving
    t_r, p_r = reference
    inside = (t_r >= t_m[0]) & (t_r <= t_m[-1])
    if inside.sum() < 3:
        return None
    g = p_r[inside] - p_r[inside].mean(axis=0)
    d = np.column_stack([np.interp(t_r[inside], t_m, p_m[:, k]) for k in range(2)])
    d -= d.mean(axis=0)
    if not (np.sum(g**2) > 0 and np.sum(d**2) > 0):
        return None
    return float(np.arctan2(np.sum(g[:, 0] * d[:, 1] - g[:, 1] * d[:, 0]), np.sum(g * d)))


def align_headings(systems: Mapping[str, SensorSystem], cfg: HeadingAlignmentConfig) -> dict[str, float]:
    """Rotate every ``auto`` system onto the reference, then place the systems on the body
    (:meth:`~bodyfusion.core.capabilities.BodyPlacement.place_on_body`, about the reference's
    first walking direction); returns the rotation applied (rad) per system. A geographic
    reference's positions come from fixes metres apart from the truth: against it a system is
    turned by the rotation that lays its whole track onto the reference's (:func:`track_rotation`).
    Only systems with a heading take part (:func:`with_heading`)."""
    systems = with_heading(systems)
    auto = [name for name, s in systems.items() if s.heading_is_auto]
    placed = [name for name, s in systems.items() if offers(s, BodyPlacement) and s.wants_body_place]
    if (not auto and not placed) or len(systems) < 2:
        return {}
    ref = heading_reference(systems, cfg)
    if systems[ref].heading_is_absolute and (ref_track := geographic_track(systems[ref])) is not None:
        return _align_to_geographic(systems, auto, placed, ref, ref_track)
    candidates = [ref] if cfg.reference is not None else [ref, *[n for n in systems if n != ref]]
    ref_azimuth, distance = None, cfg.distance_m
    for name in candidates:
        distance = max(cfg.distance_m, ABSOLUTE_REFERENCE_M) if systems[name].heading_is_absolute else cfg.distance_m
        ref_azimuth = systems[name].initial_travel_azimuth(distance)
        if ref_azimuth is not None:
            ref = name
            break
        if cfg.reference is not None:
            raise FusionError(f"heading alignment: reference system {ref!r} never travels {distance:g} m")
    if ref_azimuth is None:
        raise FusionError(f"heading alignment: no system travels {cfg.distance_m:g} m to serve as reference")
    applied: dict[str, float] = {}
    for name in auto:
        if name == ref:
            continue
        azimuth = systems[name].initial_travel_azimuth(distance)
        if azimuth is None:
            raise FusionError(f"heading alignment: system {name!r} never travels {distance:g} m")
        delta = wrap_angle(ref_azimuth - azimuth)
        systems[name].rotate_initial_heading(delta)
        applied[name] = delta
    for name in placed:
        systems[name].place_on_body(ref_azimuth)
    return applied


@dataclass
class HeadingTie:
    """The relative heading of ``system`` against ``reference`` (module docstring), measured over
    stretches in which both travel ``window_m``: their positions at the fuser's epochs are
    collected (:meth:`add`) and, the stretch complete, the rotation that best lays the system's
    track onto the reference's (2-D Procrustes about their centroids) is the measurement. A walk
    that turns or goes back and forth measures it as well as a straight one.

    ``log``: every measurement as (t s, z rad, σ rad, NIS, accepted)."""

    reference: str
    system: str
    window_m: float
    lateral_sd_m: float
    offsets_m: tuple[float, float] = (0.0, 0.0)
    """Where the reference and the system are worn, m to the right of the body's centreline
    (:func:`lateral_offset_m`): taken out of each track
    before the two are compared, so that a left and a right foot walk one path."""
    points: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    travelled: np.ndarray = field(default_factory=lambda: np.zeros(2))
    log: list[tuple[float, float, float, float, bool]] = field(default_factory=list)

    def add(self, p_ref: np.ndarray, p_sys: np.ndarray) -> None:
        """The two systems' positions (ENU, m) at an epoch of the current stretch."""
        here = (np.array(p_ref[:2], dtype=float), np.array(p_sys[:2], dtype=float))
        if self.points:
            self.travelled += [np.hypot(*(here[0] - self.points[-1][0])), np.hypot(*(here[1] - self.points[-1][1]))]
        self.points.append(here)

    def measure(self, sd_ref: float, sd_sys: float) -> tuple[float, float] | None:
        """(z rad, σ_z² rad²) of the current stretch once both have travelled ``window_m`` (None
        before): z the counter-clockwise rotation from the system's centred track to the
        reference's, σ_z² = (σ_ref² + σ_sys²) / r², r the tracks' RMS distance from their
        centroids (``sd_*``: each track's lateral σ, m). The stretch then restarts from its last
        points."""
        if self.travelled.min() < self.window_m:
            return None
        ref = np.array([p[0] for p in self.points])
        sys = np.array([p[1] for p in self.points])
        if any(self.offsets_m) and len(ref) >= 2:  # on the centreline: the walking direction's right
            walk = np.gradient(ref + sys, axis=0)
            right = np.column_stack([walk[:, 1], -walk[:, 0]]) / np.maximum(np.hypot(*walk.T), 1e-12)[:, None]
            ref -= self.offsets_m[0] * right
            sys -= self.offsets_m[1] * right
        ref -= ref.mean(axis=0)
        sys -= sys.mean(axis=0)
        cross = float(np.sum(sys[:, 0] * ref[:, 1] - sys[:, 1] * ref[:, 0]))
        z = float(np.arctan2(cross, float(np.sum(sys * ref))))
        r2 = min(float(np.mean(np.sum(ref**2, axis=1))), float(np.mean(np.sum(sys**2, axis=1))))
        self.points = self.points[-1:]
        self.travelled = np.zeros(2)
        return (z, (sd_ref**2 + sd_sys**2) / r2) if r2 > 0.0 else None

    def restart_at(self, p_ref: np.ndarray, p_sys: np.ndarray) -> None:
        """After a correction: the stretch's last points are these positions."""
        self.points[-1] = (np.array(p_ref[:2], dtype=float), np.array(p_sys[:2], dtype=float))

    def forget_before(self, t: float) -> None:
        """Drop the measurements before ``t`` (s) from :attr:`log` (a live run that keeps a
        bounded history: its summary then covers the part kept)."""
        self.log = [m for m in self.log if m[0] >= t]

    def summary(self) -> dict:
        """metrics.json figures: measurements, accepted, mean NIS, the largest and RMS |z| (degrees)."""
        if not self.log:
            return {"reference": self.reference, "measurements": 0}
        z = np.array([m[1] for m in self.log])
        nis = np.array([m[3] for m in self.log])
        return {"reference": self.reference, "measurements": len(self.log),
                "accepted": int(sum(m[4] for m in self.log)), "mean_nis": float(nis.mean()),
                "max_abs_deg": float(np.degrees(np.abs(z).max())),
                "rms_deg": float(np.degrees(np.sqrt(np.mean(z**2))))}


def _align_to_geographic(systems: Mapping[str, SensorSystem], auto: list[str], placed: list[str], ref: str,
                         ref_track: tuple[np.ndarray, np.ndarray]) -> dict[str, float]:
    """Every ``auto`` system turned onto a geographic reference's whole track, then placed on the
    body facing the reference's first walking direction (its track's first ten metres)."""
    applied: dict[str, float] = {}
    for name in auto:
        if name == ref:
            continue
        track = standalone_track(systems[name])
        delta = track_rotation(track, ref_track) if track is not None else None
        if delta is None:
            raise FusionError(f"heading alignment: system {name!r} shares no travel with the reference {ref!r}")
        systems[name].rotate_initial_heading(delta)
        applied[name] = delta
    t, p = ref_track
    far = np.flatnonzero(np.hypot(*(p - p[0]).T) >= ABSOLUTE_REFERENCE_M / 3)
    d = p[far[0]] - p[0] if far.size else np.array([0.0, 1.0])
    for name in placed:
        systems[name].place_on_body(float(np.arctan2(d[0], d[1])))
    return applied


def heading_ties(systems: Mapping[str, SensorSystem], cfg: HeadingAlignmentConfig) -> list[HeadingTie]:
    """A tie of every system with a heading error state, other than the reference and those
    whose heading is geographic, to the reference (none with ``continuous`` off or one system)."""
    systems = with_heading(systems)
    if not cfg.continuous or len(systems) < 2:
        return []
    ref = heading_reference(systems, cfg)
    if ref is None or systems[ref].yaw_error_row() is None:
        return []
    return [HeadingTie(ref, name, cfg.window_m, cfg.lateral_sd_m, (lateral_offset_m(systems[ref]), lateral_offset_m(s)))
            for name, s in systems.items() if name != ref and not s.heading_is_absolute and s.yaw_error_row() is not None]
