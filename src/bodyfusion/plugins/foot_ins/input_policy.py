"""What the foot INS does with the imperfect parts of its IMU stream: gaps and saturation.

Both are explicit, counted policies (the stream's report says what was done), and both end in
the same mechanism: a covariance increment at a sample (the index of the step it precedes),
applied by the filter before that step and kept by the smoothers as that step's extra process
noise (:meth:`bodyfusion.plugins.foot_ins.system.FootIns._run_to`).

* Gaps: the step across a gap is mechanised over at most a nominal period plus
  :data:`GAP_HOLD_S` (:func:`navigation_clock`: no sample is held for longer), and before it
  the covariance grows by what the foot may have done in the Δ missing seconds: an unknown
  acceleration and rotation of the recording's own RMS sizes σ_f = rms(‖f‖ − g),
  σ_ω = rms(‖ω‖), bounded by a walker's reach: σ_p = min(σ_f Δ²/2, v_max Δ),
  σ_v = min(σ_f Δ, v_max), σ_θ = min(σ_ω Δ, θ_max) per axis (:data:`GAP_SPEED_SD_MPS`,
  :data:`GAP_ATTITUDE_SD_RAD`).
* Saturation: every clipped run the stream's checks found
  (:func:`bodyfusion.nav.saturation.find_clipping`) is rebuilt from its flanks
  (:func:`repair_saturation`), and after the run the covariance grows by the repair's
  uncertainty: σ_θ = :data:`~bodyfusion.nav.saturation.REPAIR_UNCERTAINTY` × the rebuilt
  angle beyond the gyroscope's rail on the level axes (east, north: rad; a foot clips its
  pitch rate, and the stance updates observe level, while an uncertain heading they cannot
  observe would only take up their corrections); σ_v the same of the rebuilt velocity beyond
  the accelerometer's rail (m/s, every axis).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bodyfusion.base.findings import Finding
from bodyfusion.base.types import ImuStream
from bodyfusion.nav.error_state import DATT, DPOS, DVEL
from bodyfusion.nav.saturation import REPAIR_UNCERTAINTY, Clipping, find_clipping
from bodyfusion.plugins.foot_ins.stance import StanceDetection


@dataclass
class DerivedInputs:
    """What a foot INS derives from an IMU stream whole
    (:meth:`~bodyfusion.plugins.foot_ins.system.FootIns._derive`): the stream
    (saturated runs rebuilt), each clipped sensor's :class:`~bodyfusion.nav.saturation.Clipping`,
    the rate (Hz), the :class:`~bodyfusion.plugins.foot_ins.stance.StanceDetection`, and the
    covariance increments (sample indices, (K, 15, 15))."""

    stream: ImuStream
    clipping: dict
    rate_hz: float
    detection: StanceDetection
    increments: tuple[np.ndarray, np.ndarray]


GAP_HOLD_S = 0.1
"""Longest stretch of a gap (s) integrated with the sample after it held: a tenth of a stride,
over which the foot's specific force and rate stay near one sample's."""
GAP_SPEED_SD_MPS = 3.0
"""One-sigma speed (m/s) of a foot over a gap in its IMU stream: a brisk run; bounds the
position and velocity uncertainty a gap adds."""
SATURATION_WARNING_RAD = 0.05
"""A repair whose uncertainty reaches this attitude error (rad, ~3°) makes saturation a warning."""
GAP_ATTITUDE_SD_RAD = 0.5
"""Largest one-sigma attitude error (rad) a gap adds: the error-state model is small-angle, and
the stance updates that follow re-level roll and pitch."""


def repair_saturation(stream: ImuStream, name: str) -> dict[str, Clipping]:
    """Rebuild the clipped runs of ``stream`` (its acc_b and gyro_b are replaced by repaired
    copies where any run was clipped; :func:`bodyfusion.nav.saturation.find_clipping`, as the
    reader's checks found it) and note it in its report; returns the
    :class:`~bodyfusion.nav.saturation.Clipping` of each clipped sensor (``"acc"``, ``"gyro"``)."""
    if stream.checks is not None:
        found = stream.checks.clipping
    else:  # a stream the reader did not check
        dt = float(np.median(np.diff(stream.t))) if len(stream) > 1 else 0.0
        found = {key: c for key, x in (("acc", stream.acc_b), ("gyro", stream.gyro_b))
                 if (c := find_clipping(x, dt)).runs}
    for key, attribute, what, unit in (("acc", "acc_b", "accelerometer", "m/s"), ("gyro", "gyro_b", "gyroscope", "rad")):
        if key in found:
            setattr(stream, attribute, found[key].repaired(getattr(stream, attribute)))
            worst = max(r.excess_integral for r in found[key].runs)
            stream.report.notes.append(f"{name}: {len(found[key].runs)} clipped {what} runs rebuilt from their "
                                       f"flanks; up to {REPAIR_UNCERTAINTY * worst:.2g} {unit} of uncertainty added "
                                       "after each")
    return found


def clock_lag(stream: ImuStream) -> np.ndarray:
    """(N,) what the navigation clock drops at each sample (s): of a gap before it, what is
    missing beyond the nominal period plus :data:`GAP_HOLD_S`; 0 elsewhere."""
    lag = np.zeros(len(stream))
    checks = stream.checks
    if checks is not None and checks.gap_index.size:
        lag[checks.gap_index] = np.maximum(checks.gap_missing_s - GAP_HOLD_S, 0.0)
    return lag


def navigation_clock(stream: ImuStream) -> np.ndarray:
    """The sample times the filter integrates over (s): the recording's, with every gap step
    cut to the nominal period plus :data:`GAP_HOLD_S` (the time after a gap moves back by what
    is missing beyond that, :func:`clock_lag`): a short gap is integrated with its sample held,
    as any step; of a long one only what a held sample can describe, the rest is the covariance of
    :func:`covariance_increments`. Output times stay the recording's."""
    checks = stream.checks
    if checks is None or checks.gap_index.size == 0:
        return stream.t
    return stream.t - np.cumsum(clock_lag(stream))


def covariance_increments(stream: ImuStream, gravity_mps2: float,
                          clipping: dict[str, Clipping]) -> tuple[np.ndarray, np.ndarray]:
    """The gap and saturation policies' covariance increments (module docstring): sorted
    sample indices (the step each precedes) and their (K, 15, 15) increments, summed where a
    gap and a repaired run share one."""
    increments: dict[int, np.ndarray] = {}

    def add(index: int, block: slice, variance: float, axes: int = 3) -> None:
        dP = increments.setdefault(int(index), np.zeros((15, 15)))
        dP[block, block] += variance * np.diag(np.arange(3) < axes)

    checks = stream.checks
    if checks is not None and checks.gap_index.size:
        f_dev = np.linalg.norm(stream.acc_b, axis=1) - gravity_mps2
        sigma_f = float(np.sqrt(np.mean(f_dev**2)))
        sigma_w = float(np.sqrt(np.mean(np.sum(stream.gyro_b**2, axis=1))))
        for index, missing in zip(checks.gap_index, checks.gap_missing_s):
            add(index, DPOS, min(sigma_f * missing**2 / 2, GAP_SPEED_SD_MPS * missing) ** 2)
            add(index, DVEL, min(sigma_f * missing, GAP_SPEED_SD_MPS) ** 2)
            add(index, DATT, min(sigma_w * missing, GAP_ATTITUDE_SD_RAD) ** 2)
    for key, block, axes in (("gyro", DATT, 2), ("acc", DVEL, 3)):
        for run in clipping[key].runs if key in clipping else ():
            if run.stop < len(stream):
                add(run.stop, block, (REPAIR_UNCERTAINTY * run.excess_integral) ** 2, axes)
    if not increments:
        return np.empty(0, dtype=np.int64), np.empty((0, 15, 15))
    index = np.array(sorted(increments), dtype=np.int64)
    return index, np.stack([increments[int(k)] for k in index])


def saturation_findings(name: str, clipping: dict[str, Clipping], t: np.ndarray) -> list[Finding]:
    """A finding per clipped sensor: a warning when a repair's uncertainty reaches
    :data:`SATURATION_WARNING_RAD` (or its m/s for the accelerometer), else for information."""
    out = []
    for key, what, unit, field in (("gyro", "gyroscope", "rad", "rotation"), ("acc", "accelerometer", "m/s", "velocity")):
        if key not in clipping:
            continue
        c = clipping[key]
        worst = REPAIR_UNCERTAINTY * max(r.excess_integral for r in c.runs)
        rails = ", ".join(f"{'xyz'[a]} {'−+'[s]}{c.rail[a, s]:.4g}" for a in range(3) for s in range(2)
                          if np.isfinite(c.rail[a, s]))
        out.append(Finding(
            "saturation", "warning" if worst >= SATURATION_WARNING_RAD else "info", name,
            float(t[c.runs[0].start]), float(t[min(c.runs[-1].stop, t.size - 1)]),
            f"the {what} hit its range ({rails}) in {len(c.runs)} runs, {c.samples} samples; each was rebuilt from "
            f"its flanks, the {field} lost there uncertain by up to {worst:.2g} {unit} a run.",
            f"the motion is faster than the {what}'s full-scale range (a running swing turns at 10-20 rad/s).",
            f"set the {what} to a wider range when recording (±2000 °/s, ±16 g)."))
    return out
