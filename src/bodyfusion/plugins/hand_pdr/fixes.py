"""The phone's GNSS fixes as its filter takes them: σ, the fixes it skips, the start fix.

σ per axis of fix k: ``filter.accuracy_to_sigma`` × the reported accuracy, or
``filter.default_sigma_m`` where the receiver reports none. Skipped (and counted): fixes
inside a layout outage; a fix that repeats its predecessor's position exactly (the receiver
holding its solution: no new measurement); a fix reporting a ground speed no pedestrian
walks at (the receiver's solution moving on its own, as while it converges from a cold start).

Start from GNSS (``initial.position_m: gnss``). Receivers report wild first fixes (on
IPIN 2023 Trial24 the first fix is 2.6 km off, reported at 61 m; with a start σ of 5 m the
chi-square gate then refused 194 of 195 fixes and the track stayed 2.65 km away); the
start is the first usable fix that its successor confirms: |p_j+1 − p_j| minus the
distance the PDR walked between them passes the 2-D chi-square gate of σ_j² + σ_j+1².
Earlier fixes are skipped.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from bodyfusion.io.gnss import GnssFixes
from bodyfusion.nav.measurements import chi2_gate
from bodyfusion.plugins.hand_pdr.config import PdrFilterConfig


@dataclass
class PhoneFixes:
    """Per fix: time ``t`` (s), ENU position ``pos`` (m) about ``origin`` (lat, lon, h), σ per
    axis ``sd`` (m), the reported ``accuracy`` (m), ``speed`` (m/s) and ``course`` (rad);
    flags ``masked`` by an outage, ``held`` (a repeat), ``fast`` (too fast), taken ``walking``,
    taken with the phone held ``steady``. ``confirmed``: the first confirmed usable fix (-1 if
    no fix is usable)."""

    t: np.ndarray
    pos: np.ndarray
    origin: tuple[float, float, float]
    sd: np.ndarray
    accuracy: np.ndarray
    speed: np.ndarray
    course: np.ndarray
    masked: np.ndarray
    held: np.ndarray
    fast: np.ndarray
    walking: np.ndarray
    steady: np.ndarray
    confirmed: int

    @classmethod
    def of(cls, fixes: GnssFixes, outages: tuple[tuple[float, float], ...], f: PdrFilterConfig,
           origin: tuple[float, float, float] | None, step_t: np.ndarray, step_length_m: np.ndarray,
           walking: np.ndarray, steady: np.ndarray) -> "PhoneFixes":
        """``fixes`` for a phone whose PDR detected steps at ``step_t`` (s) of ``step_length_m``
        (m), ``walking`` and held ``steady`` (per fix); the geodetic origin is ``origin``, else
        the confirmed fix (the first, if none is usable)."""
        sd = f.accuracy_to_sigma * fixes.accuracy_m
        sd = np.where(np.isfinite(sd) & (sd > 0), sd, f.default_sigma_m)
        masked = np.zeros(len(fixes), dtype=bool)
        for start, duration in outages:
            masked |= (fixes.t >= start) & (fixes.t < start + duration)
        held = fixes.repeats_previous()
        fast = fixes.speed_mps > f.max_speed_mps  # NaN speed: not fast
        usable = np.flatnonzero(~masked & ~held & ~fast)
        first = (float(fixes.lat_deg[0]), float(fixes.lon_deg[0]), float(fixes.height_m[0]))
        confirmed = (first_confirmed(fixes.t, fixes.enu(first), sd, usable, chi2_gate(f.gate_probability, 2),
                                     step_t, step_length_m) if usable.size else -1)
        if origin is None:
            j = max(confirmed, 0)
            origin = (float(fixes.lat_deg[j]), float(fixes.lon_deg[j]), float(fixes.height_m[j]))
        return cls(fixes.t, fixes.enu(origin), origin, sd, fixes.accuracy_m, fixes.speed_mps,
                   np.deg2rad(fixes.course_deg), masked, held, fast, walking, steady, confirmed)

    def skipped(self, j: int, start: int) -> str | None:
        """Why fix ``j`` is skipped (``masked``, ``before_start`` the fix index ``start``,
        ``held``, ``too_fast``: its count in the diagnostics), None if it is used."""
        for reason, skip in (("masked", self.masked[j]), ("before_start", j < start), ("held", self.held[j]),
                             ("too_fast", self.fast[j])):
            if skip:
                return reason
        return None


def first_confirmed(t: np.ndarray, pos: np.ndarray, sd: np.ndarray, usable: np.ndarray, gate: float,
                    step_t: np.ndarray, step_length_m: np.ndarray) -> int:
    """Index of the first of the ``usable`` fixes (times ``t``, ENU ``pos``, σ ``sd``) whose
    successor confirms it within the 2-D chi-square ``gate`` (see the module docstring); the
    last usable one if none is confirmed (no successor contradicts it). The PDR walked steps
    of ``step_length_m`` at ``step_t``."""
    walked_m = np.concatenate([[0.0], np.cumsum(step_length_m)])
    for a, b in pairwise(usable):
        k0, k1 = np.searchsorted(step_t, [t[a], t[b]], side="right")  # steps in (t_a, t_b]
        gap = max(float(np.hypot(*(pos[b, :2] - pos[a, :2]))) - float(walked_m[k1] - walked_m[k0]), 0.0)
        if gap**2 <= gate * (sd[a] ** 2 + sd[b] ** 2):
            return int(a)
    return int(usable[-1])
