"""Findings of the evaluation against truth: what a score says went wrong, and where to look.

Three kinds: a fused system whose error is no better than its own absolute sensor's alone (a
phone's track against its GNSS fixes), a system whose error exceeds :data:`LARGE_ERROR_M`, with
the run's other findings about it as the likely cause (or, without any, the shape of its error:
a drift of heading turns the track, a wrong scale stretches it), and a distance limit the truth
itself breaks.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from bodyfusion.base.findings import Finding
from bodyfusion.base.types import TruthTrack
from bodyfusion.core.constraint_log import ConstraintLog
from bodyfusion.core.layout import LENGTH_UNITS, ConstraintConfig


def sensor_alone_findings(scores: dict, alone: dict) -> list[Finding]:
    """A warning per system whose fused horizontal p75 error exceeds its sensor alone's
    (``scores``: name → :class:`~bodyfusion.evaluation.metrics.SystemScore`; ``alone``: name →
    :func:`~bodyfusion.evaluation.metrics.sensor_alone_score`)."""
    out = []
    for name, block in alone.items():
        fused = scores[name].metrics["horizontal_error_m"]["p75"]
        own = block["horizontal_error_m"]["p75"]
        if fused > own:
            t = scores[name].t
            out.append(Finding(
                "worse_than_sensor_alone", "warning", name, float(t[0]), float(t[-1]),
                f"the fused track is worse than the system's absolute sensor alone: p75 horizontal error "
                f"{fused:.2f} m against {own:.2f} m from its fixes as they came.",
                "the dead reckoning strays (missed steps, a heading the fixes could not correct) or the fixes' "
                "error model trusts them too little.",
                "look at the system's reanchored count and step count in diagnostics; raise its "
                "filter.step_scale_sd, or lower filter.gnss_correlated_fraction."))
    return out


LARGE_ERROR_M = 1.0
"""A horizontal error (m, maximum over the truth epochs) above which a run must say why."""
SCALE_TOLERANCE = 0.05
"""A track this much larger or smaller than the truth's (relative) has a scale error."""
UNIT_TOLERANCE = 0.1
"""A truth this close (relative) to a unit's factor times the track's size is in that unit."""
HEADING_DRIFT_DEG = 5.0
"""A turn of the track between its first and second half (degrees) that is a heading drift."""
MAX_TRUTH_SPEED_MPS = 15.0
"""Faster than any body part moves (m/s): a truth that jumps faster has dropped out (a marker
lost and found again)."""
DROPOUT_MARGIN_S = 0.5
"""Time (s) on each side of a truth jump whose errors are the truth's."""
EVENT_SPAN_S = 10.0
"""Longest span (s) of a finding that reports an event (a re-anchoring), not a stretch."""
EVENT_MARGIN_S = 2.0
"""Time (s) on each side of an event over which the error is compared (:func:`_raised_error`)."""


def truth_jumps(t: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Times (s) at which the truth track jumps faster than :data:`MAX_TRUTH_SPEED_MPS`."""
    if len(t) < 2:
        return np.empty(0)
    speed = np.hypot(*np.diff(pos[:, :2], axis=0).T) / np.maximum(np.diff(t), 1e-9)
    return t[1:][speed > MAX_TRUTH_SPEED_MPS]


def _similarity(est: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(scale, rotation rad, counter-clockwise) of the 2-D similarity laying ``est`` (M, 2) onto
    ``truth`` (M, 2) about their centroids (Umeyama)."""
    a, b = est - est.mean(axis=0), truth - truth.mean(axis=0)
    cross = float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]))
    dot = float(np.sum(a * b))
    spread = float(np.sum(a * a))
    return (float(np.hypot(cross, dot) / spread) if spread > 0 else 1.0), float(np.arctan2(cross, dot))


def _truth_unit(scale: float) -> str | None:
    """The length unit whose metres per unit the truth-to-track ``scale`` is the inverse of
    (within :data:`UNIT_TOLERANCE`): a truth file in that unit read as metres; None if none."""
    for unit, metres in LENGTH_UNITS.items():
        if metres != 1.0 and abs(scale * metres - 1.0) < UNIT_TOLERANCE:
            return unit
    return None


def _raised_error(finding: Finding, t: np.ndarray, err: np.ndarray) -> bool:
    """True for a finding of an event (spanning at most :data:`EVENT_SPAN_S`) across which the
    horizontal error ``err`` (at times ``t``, s; finite) rises by more than :data:`LARGE_ERROR_M`:
    from the last error :data:`EVENT_MARGIN_S` before it to the largest within that margin after
    it (the estimate is interpolated between its records, which spreads a jump over the gap
    between two)."""
    if finding.t_start is None or finding.t_end is None or finding.t_end - finding.t_start > EVENT_SPAN_S:
        return False
    before = np.searchsorted(t, finding.t_start - EVENT_MARGIN_S, side="right") - 1
    a, b = np.searchsorted(t, [finding.t_end, finding.t_end + EVENT_MARGIN_S], side="right")
    return 0 <= before and b > a and float(err[a - 1:b].max()) - float(err[before]) > LARGE_ERROR_M


def large_error_findings(scores: dict, findings: list[Finding]) -> list[Finding]:
    """A warning per system whose horizontal error exceeds :data:`LARGE_ERROR_M`, naming the
    cause: the run's own findings about the system (or the run's constraints) when it has any
    (its warnings, and an event it reported that the error jumped across: a re-anchoring),
    else the shape of the error: a scale (the track larger or smaller than the truth's), a
    heading drift (its second half turned from its first) or a jump (the error grows at once)."""
    out = []
    for name, score in scores.items():
        err = score.horizontal_error_m
        finite = np.isfinite(err)
        if not finite.any() or float(np.max(err[finite])) <= LARGE_ERROR_M:
            continue
        t, worst = score.t, int(np.argmax(np.where(finite, err, -np.inf)))
        own = [f for f in findings if f.system in (name, None)
               and (f.severity == "warning" or _raised_error(f, t[finite], err[finite]))]
        est, truth = score.pos_est_aligned[finite, :2], score.pos_truth[finite, :2]
        half = max(2, len(est) // 2)
        scale, _ = _similarity(est, truth)
        turn = np.degrees(_similarity(est[half:], truth[half:])[1] - _similarity(est[:half], truth[:half])[1]) \
            if len(est) >= 4 else 0.0
        turn = (turn + 180.0) % 360.0 - 180.0
        jumps = truth_jumps(t, score.pos_truth)
        near = jumps[np.abs(jumps - t[worst]) <= DROPOUT_MARGIN_S]
        unit = _truth_unit(scale)
        if near.size and unit is None:
            out.append(Finding(
                "truth_dropout", "info", name, float(near[0]), float(near[-1]),
                f"the horizontal error reaches {err[worst]:.2f} m at t = {t[worst]:.1f} s, where the truth itself jumps "
                f"faster than {MAX_TRUTH_SPEED_MPS:g} m/s (RMSE {score.metrics['horizontal_error_m']['rmse']:.2f} m).",
                "the reference drops out there (a motion-capture marker lost and found again); the error is the "
                "truth's.", "nothing in the run; read the maximum error with that in mind."))
            continue
        if unit is not None:
            cause = (f"the truth's unit: it is {scale:.4g} times the track's size, as a truth in {unit} read as metres.")
            advice = f"set truth.unit: {unit} in the layout."
        elif own:
            cause = "; ".join(f"{f.kind.replace('_', ' ')} at t = {f.t_start:.1f}–{f.t_end:.1f} s"
                              if f.t_start is not None else f.kind.replace('_', ' ') for f in own[:3])
            cause = f"what the run reported about it: {cause} (its findings)."
            advice = "act on those findings first."
        elif abs(scale - 1.0) > SCALE_TOLERANCE:
            cause = (f"a scale error: the track is {scale:.2f} times the truth's size (step lengths, an "
                     "accelerometer scale, stances missed or found where the foot moved).")
            advice = "check the detector's stance fraction and the IMU's units; smoothing does not fix scale."
        elif abs(turn) > HEADING_DRIFT_DEG:
            cause = (f"a heading drift: the track's second half is turned {turn:.0f}° from its first "
                     "(gyro bias about Up, which stance updates cannot observe).")
            advice = ("record a still start of a few seconds (the gyro bias is taken there); add a heading "
                      "aid (a second foot, a magnetometer, position fixes).")
        else:
            cause = f"a jump: the error rises at t = {t[worst]:.1f} s without a scale or heading pattern."
            advice = "look at the input around that time (a gap, saturation, a clock jump)."
        out.append(Finding(
            "large_error", "warning", name, float(t[0]), float(t[-1]),
            f"the horizontal error reaches {err[worst]:.2f} m (at t = {t[worst]:.1f} s, RMSE "
            f"{score.metrics['horizontal_error_m']['rmse']:.2f} m), beyond {LARGE_ERROR_M:g} m.",
            cause, advice))
    return out


def truth_separation_findings(constraints: Sequence[ConstraintConfig], log: ConstraintLog | None,
                              truths: Mapping[str, TruthTrack]) -> list[Finding]:
    """A finding per ``max`` constraint the truth itself breaks: the two systems' truth tracks
    (``truths``: name → :class:`~bodyfusion.base.types.TruthTrack`, dense) interpolated to the
    epochs of the fuser's ``log`` (:class:`~bodyfusion.core.constraint_log.ConstraintLog`), their
    separation against the limit that held at each (a wrong limit pulls right estimates)."""
    out = []
    if log is None or log.n == 0:
        return out
    t = log.t[:log.n]
    for k, c in enumerate(constraints):
        a, b = c.between
        if c.kind != "max" or a not in truths or b not in truths or truths[a].sparse or truths[b].sparse:
            continue
        dims = 2 if c.horizontal or truths[a].pos_n.shape[1] < 3 else 3
        inside = (t >= max(truths[a].t[0], truths[b].t[0])) & (t <= min(truths[a].t[-1], truths[b].t[-1]))
        if not inside.any():
            continue
        pa = np.column_stack([np.interp(t[inside], truths[a].t, truths[a].pos_n[:, d]) for d in range(dims)])
        pb = np.column_stack([np.interp(t[inside], truths[b].t, truths[b].pos_n[:, d]) for d in range(dims)])
        separation = np.linalg.norm(pa - pb, axis=1)
        limit = log.limit[:log.n, k][inside]
        broken = separation > limit
        if not broken.any():
            continue
        worst = int(np.argmax(separation - limit))
        when = t[inside]
        out.append(Finding(
            "limit_broken_by_truth", "warning", None, float(when[broken][0]), float(when[broken][-1]),
            f"the truth breaks the {a}–{b} limit at {int(broken.sum())} of {int(inside.sum())} epochs: they truly "
            f"stood {separation[worst]:.2f} m apart at t = {when[worst]:.1f} s where the limit was {limit[worst]:.2f} m, "
            "so the fuser pulled right estimates towards a wrong bound.",
            "the limit is too tight for this walk (its strides, the way the systems are worn).",
            f"set constraints.{k}.distance_m to body (it follows the gait) or above {separation.max():.2f} m."))
    return out
