"""Stance of a foot: the configured detector, and a watchdog for the stances it missed.

:func:`detect_stance` runs the layout's ``detector`` (:mod:`bodyfusion.nav.stance_detectors`) and then
the *missed-stance watchdog*: a foot that walks, runs or climbs is at rest once per stride, so
a stretch with no detected stance longer than :data:`MISSED_STRIDES` of its own stride periods
(:func:`bodyfusion.nav.gait.stride_period`; where no gait repeats, the recording's median
period, else :data:`DEFAULT_STRIDE_S`) has missed stances. Without aiding for several strides
the velocity of a foot INS runs away (metres within seconds), so the watchdog does not leave
it there: the stretch is cut into stride periods and the stillest window of each (the least
SHOE statistic) becomes a *fallback stance*. Its zero-velocity update is a loose one by
itself: the update's noise grows with the foot's angular rate there
(:func:`bodyfusion.nav.zupt.stance_velocity_sigma`), and its chi-square gate bounds the rest.
Every such stretch is counted and timed (:class:`StanceDetection`), and becomes a finding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.findings import Finding, spans
from bodyfusion.base.types import ImuStream
from bodyfusion.nav import detectors
from bodyfusion.nav.gait import stride_period
from bodyfusion.nav.stance_detectors import ADAPTIVE_WINDOW_S, SIGMA_ACC_MPS2, SIGMA_GYRO_RADPS, AdaptiveShoe
from bodyfusion.plugins.foot_ins.config import DetectorConfig

MISSED_STRIDES = 2.0
"""A stretch without stance longer than this many stride periods has missed stances."""
DEFAULT_STRIDE_S = 1.2
"""Stride period (s) assumed where the recording shows none (an ordinary walk's)."""
LOCKOUT_STRIDES = 3.0
"""Stance updates all beyond the gate for this many stride periods are a lockout (a finding)."""
LOCKOUT_STANCES = 1
"""Stances in a row whose every update is beyond the gate after which the foot INS re-inflates
its velocity and level covariance (:meth:`bodyfusion.plugins.foot_ins.system.FootIns._watch_lockout`)."""


@dataclass
class StanceDetection:
    """A foot's stance: ``stance`` (N,) the samples updated as at rest (the detector's and the
    watchdog's fallbacks), ``detected`` (N,) the detector's alone, ``period_s`` (N,) the stride
    period (s; NaN where no gait repeats), ``missed`` the stretches with missed stances as
    (first sample, end sample, stances missed) where a gait repeats, ``restless`` those where
    none does (turning on the spot, shuffling: the foot never rested, but walked no strides),
    ``fallback`` (N,) the fallback samples of both."""

    stance: np.ndarray
    detected: np.ndarray
    period_s: np.ndarray
    fallback: np.ndarray
    missed: list[tuple[int, int, int]] = field(default_factory=list)
    restless: list[tuple[int, int, int]] = field(default_factory=list)

    @property
    def missed_stances(self) -> int:
        """Stances missed in all (one fallback update each)."""
        return sum(n for _, _, n in self.missed)

    def reference_period(self) -> np.ndarray:
        """The stride period at every sample, s: the local one, else the recording's median,
        else :data:`DEFAULT_STRIDE_S`."""
        known = np.isfinite(self.period_s)
        fill = float(np.median(self.period_s[known])) if known.any() else DEFAULT_STRIDE_S
        return np.where(known, self.period_s, fill)


def detect_stance(stream: ImuStream, cfg: DetectorConfig, gravity: float, key: str) -> StanceDetection:
    """The configured detector's stance (:meth:`DetectorConfig.detector`, debounced: durations in
    s), then the missed-stance watchdog's fallbacks (module docstring), on the SHOE statistic
    over :data:`~bodyfusion.nav.stance_detectors.ADAPTIVE_WINDOW_S` (the detector's own when it
    computed that one)."""
    rate = float(1.0 / np.median(np.diff(stream.t)))
    detector = cfg.detector()
    try:
        detector.detect(stream.acc_b, stream.gyro_b, rate, gravity, labels=stream.stance)
    except ValueError as err:
        raise ConfigError(key, str(err)) from None
    stance = detector.stance
    if cfg.min_stance_s > 0 or cfg.min_swing_s > 0:
        stance = detectors.debounce(stance, min_stance=max(1, round(cfg.min_stance_s * rate)),
                                    min_swing=max(1, round(cfg.min_swing_s * rate)))
    stance = np.ascontiguousarray(stance, dtype=np.bool_)
    period = detector.period_s
    if period is None:
        period = stride_period(np.linalg.norm(stream.gyro_b, axis=1), rate)
    found = StanceDetection(stance, stance, period, np.zeros_like(stance))
    if isinstance(detector, AdaptiveShoe):
        window, statistic = detector.statistic_window, detector.statistic
    else:
        window = max(3, round(ADAPTIVE_WINDOW_S * rate))
        shoe = getattr(detector, "sigma_acc", SIGMA_ACC_MPS2), getattr(detector, "sigma_gyro", SIGMA_GYRO_RADPS)
        statistic = detectors.shoe_statistic(stream.acc_b, stream.gyro_b, window=window, sigma_acc=shoe[0],
                                             sigma_gyro=shoe[1], gravity=gravity)
    _watch(found, statistic, window, rate)
    return found


def _watch(found: StanceDetection, statistic: np.ndarray, window: int, rate: float) -> None:
    """Fill ``found.fallback`` and ``found.missed``: every stretch without stance longer than
    :data:`MISSED_STRIDES` periods, cut into periods, each one's stillest window a fallback."""
    n = found.stance.size
    if statistic.size == 0:
        return
    period = found.reference_period()
    shortest = MISSED_STRIDES * float(period.min()) * rate if period.size else 0.0
    swing = ~found.detected
    edges = np.diff(np.concatenate(([0], swing.astype(np.int8), [0])))
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        if b - a <= shortest:  # shorter than two of the shortest strides: two of its own strides at least
            continue
        p = float(np.median(period[a:b])) * rate  # samples per stride here
        if b - a <= MISSED_STRIDES * p:
            continue
        # whole strides inside the stretch, half a stride clear of the stances around it
        lo, hi = a + (0 if a == 0 else int(0.5 * p)), b - (0 if b == n else int(0.5 * p))
        cycles = max(1, int(math.floor((hi - lo) / p)))
        bounds = np.linspace(lo, hi, cycles + 1).round().astype(int)
        placed = 0
        for c0, c1 in zip(bounds[:-1], bounds[1:]):
            c1 = min(c1, statistic.size)
            if c1 <= c0:
                continue
            k = c0 + int(np.argmin(statistic[c0:c1]))
            found.fallback[k:k + window] = True
            placed += 1
        if placed:
            gait = np.mean(np.isfinite(found.period_s[a:b])) >= 0.5
            (found.missed if gait else found.restless).append((int(a), int(b), placed))
    if found.missed or found.restless:
        found.stance = found.detected | found.fallback


def stance_findings(name: str, found: StanceDetection, t: np.ndarray, hist_nis: np.ndarray,
                    gate: float, recoveries: list[float] | tuple = ()) -> list[Finding]:
    """The foot's stance findings: the stretches with missed stances (the watchdog's), and the
    ZUPT lockouts: stretches of :data:`LOCKOUT_STRIDES` periods or more whose every stance update
    was beyond the gate, and every re-inflation the filter made to end one (``hist_nis`` (N,):
    each sample's ZUPT NIS, negative where none; ``gate``: the chi-square gate, 0: off;
    ``recoveries``: the times of the re-inflations, s)."""
    out = []
    if found.missed:
        t0, t1 = t[found.missed[0][0]], t[min(found.missed[-1][1], t.size - 1)]
        seconds = sum(t[min(b, t.size - 1)] - t[a] for a, b, _ in found.missed)
        where = spans([v for a, b, _ in found.missed for v in (t[a], t[min(b, t.size - 1)])])
        period = float(np.median(found.reference_period()))
        out.append(Finding(
            "missed_stances", "warning", name, float(t0), float(t1),
            f"{found.missed_stances} stance{'s' if found.missed_stances != 1 else ''} missed over {seconds:.1f} s "
            f"({where}): the foot moved for more than "
            f"{MISSED_STRIDES:g} strides ({period:.2f} s each) without a detected stance, where every stride should "
            "have one; each missed stride got a loose zero-velocity update at its stillest instant.",
            "the foot never came to rest at the detector's threshold (a fast run, crawling, shuffling), or the "
            "sensor is not on a foot or is loose.",
            "check the sensor is strapped to the foot; keep detector.kind adaptive (it follows running); give "
            "detector.kind labels with a stance column if the recording has them."))
    if found.restless:
        seconds = sum(t[min(b, t.size - 1)] - t[a] for a, b, _ in found.restless)
        where = spans([v for a, b, _ in found.restless for v in (t[a], t[min(b, t.size - 1)])])
        out.append(Finding(
            "restless_foot", "info", name, float(t[found.restless[0][0]]),
            float(t[min(found.restless[-1][1], t.size - 1)]),
            f"the foot moved for {seconds:.1f} s ({where}) without a detected stance and without a gait (no stride "
            "repeats there); it got a loose zero-velocity update at its stillest instant of every stride period.",
            "turning on the spot, shuffling, fidgeting, or a motion that is not walking.",
            "nothing, if that is what the wearer did; check the stretch's track if it should have been a walk."))
    if gate > 0 and hist_nis.size:
        out += _lockouts(name, found, t, hist_nis, gate)
    if len(recoveries):
        out.append(Finding(
            "zupt_lockout", "warning", name, float(recoveries[0]), float(recoveries[-1]),
            f"{len(recoveries)} time(s) the zero-velocity updates of {LOCKOUT_STANCES} stances in a row were all "
            f"beyond the gate (the first at t = {recoveries[0]:.1f} s); the filter re-inflated its velocity and "
            "level covariance each time so that the next stance could pull it back.",
            "the velocity and attitude had gone wrong in between: a corrupt or clipped sample, a gap, stances "
            "missed before.",
            "look at the input there (spikes beyond the body's rates, saturation, gaps); the position error made "
            "before the recovery stays."))
    return out


def _lockouts(name: str, found: StanceDetection, t: np.ndarray, hist_nis: np.ndarray, gate: float) -> list[Finding]:
    """A finding per stretch of stance runs whose every update was beyond the gate, lasting at
    least :data:`LOCKOUT_STRIDES` stride periods."""
    stance = found.stance[:hist_nis.size]
    starts, ends = detectors.stance_events(stance)
    if starts.size == 0:
        return []
    def locked(a: int, b: int) -> bool:  # a stance run with updates, every one beyond the gate
        nis = hist_nis[a:b][hist_nis[a:b] >= 0]
        return bool(nis.size and np.all(nis > gate))

    beyond = np.array([locked(a, b) for a, b in zip(starts, ends)])
    period = found.reference_period()
    out = []
    k = 0
    while k < beyond.size:
        if not beyond[k]:
            k += 1
            continue
        j = k
        while j + 1 < beyond.size and beyond[j + 1]:
            j += 1
        a, b = starts[k], ends[j] - 1
        if t[b] - t[a] >= LOCKOUT_STRIDES * float(np.median(period[a:b + 1])):
            out.append(Finding(
                "zupt_lockout", "warning", name, float(t[a]), float(t[b]),
                f"{j - k + 1} stance phases in a row had every zero-velocity update beyond the gate (NIS > {gate:.3g}, "
                "3 degrees of freedom): the filter's velocity disagreed with rest for "
                f"{t[b] - t[a]:.1f} s and was only partly pulled back.",
                "the velocity had run away before (missed stances, a gap, saturation), or the detector flags "
                "motion as stance.",
                "look for missed stances or saturation before this span; if the detector is wrong here, lower "
                "detector.margin_decades or give stance labels."))
        k = j + 1
    return out
