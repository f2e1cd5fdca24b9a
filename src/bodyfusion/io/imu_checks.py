"""Sanity checks of an IMU stream: units, sample rate, gaps and clipping.

A recording whose units or time base are declared wrong still "runs" and gives nonsense, so
every stream read for a navigation system is looked at once before it is used. Each finding
is one line (:attr:`ImuChecks.warnings`) for the console and metrics.json, and a count
(:meth:`ImuChecks.to_dict`). Nothing is changed in the data: gaps are handled by the
navigation system's explicit gap policy (e.g. the foot INS inflates its covariance across
them), the rest are the user's to fix in the layout.

Thresholds are physical and hold for any body-worn MEMS IMU:

* specific force: at rest (the quietest quarter-second of the recording,
  :func:`bodyfusion.nav.initial_alignment.window_spreads`) its magnitude is g to within 10 %;
  1 ± 0.5 means g was declared as m/s^2, 9.8 × g the reverse;
* angular rate: no human segment turns faster than ~35 rad/s (2000 °/s, the largest
  full-scale range of such sensors); a moving recording (specific-force spread above
  1 m/s^2) whose rate never exceeds 0.2 rad/s was most likely declared deg/s while in rad/s;
* rate: 1 / median Δt against the declared nominal rate (2 % tolerance), and a rate outside
  1 Hz–10 kHz (a time scale off by 1000);
* gaps: a step longer than ``max_step_samples`` nominal periods;
* clipping: readings flat at an axis's extreme while their flanks still climb, again and again
  (:func:`bodyfusion.nav.saturation.find_clipping`): the sensor's range was exceeded there.
"""

from __future__ import annotations

import math

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.base.types import ImuChecks
from bodyfusion.nav.earth import STANDARD_GRAVITY
from bodyfusion.nav.initial_alignment import window_spreads
from bodyfusion.nav.saturation import find_clipping

MAX_BODY_RATE_RADPS = 35.0
"""Above any human segment's angular rate and the widest MEMS gyro range (2000 °/s), rad/s."""
MOTION_ACC_SPREAD_MPS2 = 1.0
"""Standard deviation of ‖f‖ above which a recording certainly holds motion, m/s^2."""
MIN_REST_SPECIFIC_FORCE_MPS2 = 0.5
"""Least specific force (m/s^2) an accelerometer may read where it is stillest: gravity is 9.8
m/s^2 (1 g if mis-declared as m/s^2); below this the accelerometer reads nothing at all."""
MIN_MOVING_RATE_RADPS = 0.2
"""A moving body-worn sensor exceeds this angular rate somewhere (99.9th percentile), rad/s."""
RATE_TOLERANCE = 0.02
"""Relative difference between declared and measured sample rate that is reported."""


def check_imu(t: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray, *, source: str, acc_unit: str,
              gyro_unit: str, declared_rate_hz: float | None = None, max_step_samples: float = 5.0,
              plausibility: bool = True) -> ImuChecks:
    """Check a stream already converted to SI (t s, acc_b m/s^2, gyro_b rad/s) against what
    physics and the declaration (units, nominal rate) allow; see the module docstring. Without
    ``plausibility`` only what shapes a navigation system's inputs is looked for (gaps,
    clipping): the units, rate and rest checks, which only report, are left out (the rest's
    specific force and the largest rate are then NaN): a live run's pass over the last seconds of
    a recording whose whole is checked at its close."""
    dt = np.diff(t)
    nominal_dt = float(np.median(dt)) if dt.size else float("nan")
    rate = 1.0 / nominal_dt if nominal_dt > 0 else float("nan")
    if not plausibility:
        out = ImuChecks(source, rate, float("nan"), float("nan"))
        _inputs_checks(out, t, dt, nominal_dt, acc_b, gyro_b, max_step_samples)
        return out
    f = np.linalg.norm(acc_b, axis=1)
    w = np.linalg.norm(gyro_b, axis=1)
    length = int(min(len(t), max(10, round(0.25 * rate)) if np.isfinite(rate) else 10))
    s_f, s_w = window_spreads(acc_b, gyro_b, length)
    rest = int(np.argmin(s_f / max(s_f.min(), 1e-12) + s_w / max(s_w.min(), 1e-12)))
    rest_f = float(np.linalg.norm(acc_b[rest:rest + length].mean(axis=0)))
    w_top = float(np.percentile(w, 99.9))
    out = ImuChecks(source, rate, rest_f, float(w.max()))
    warn = out.warnings.append
    g = STANDARD_GRAVITY
    if not rest_f >= MIN_REST_SPECIFIC_FORCE_MPS2:
        raise InputError(source, f"the accelerometer reads {rest_f:.3g} m/s^2 where the IMU is stillest (t = "
                                 f"{t[rest]:.3g} s): no gravity, so it cannot be levelled; check acc_columns and "
                                 "acc_unit (an accelerometer at rest reads about 9.8 m/s^2, or 1 g)")
    if not 0.9 * g <= rest_f <= 1.1 * g:
        hint = ""
        if 0.5 <= rest_f <= 2.0 and acc_unit != "g":
            hint = " (≈ 1: the data look like g; set acc_unit: g)"
        elif 0.5 * g * g <= rest_f <= 2.0 * g * g and acc_unit == "g":
            hint = " (≈ 9.8 g: the data look like m/s^2; set acc_unit: m/s^2)"
        warn(f"{source}: specific force at rest {rest_f:.3g} m/s^2 (t = {t[rest]:.3g} s) is not near gravity "
             f"({g:.2f}); check acc_unit ({acc_unit}){hint}")
    if w_top > MAX_BODY_RATE_RADPS:
        hint = " (the data look like deg/s; set gyro_unit: deg/s)" if gyro_unit != "deg/s" else ""
        warn(f"{source}: angular rate reaches {w_top:.3g} rad/s (99.9th percentile), faster than any body "
             f"segment ({MAX_BODY_RATE_RADPS:g} rad/s); check gyro_unit ({gyro_unit}){hint}")
    elif np.std(f) > MOTION_ACC_SPREAD_MPS2 and w_top < MIN_MOVING_RATE_RADPS:
        hint = " (the data look like rad/s; set gyro_unit: rad/s)" if gyro_unit == "deg/s" else ""
        warn(f"{source}: the sensor moves (‖f‖ spread {np.std(f):.2g} m/s^2) but its angular rate never exceeds "
             f"{w_top:.2g} rad/s; check gyro_unit ({gyro_unit}){hint}")
    if declared_rate_hz is not None and math.isfinite(rate) and abs(rate / declared_rate_hz - 1.0) > RATE_TOLERANCE:
        warn(f"{source}: timestamps give {rate:.4g} Hz, the layout declares {declared_rate_hz:.4g} Hz; "
             "check time_scale or rate_hz")
    elif not 1.0 <= rate <= 1e4:
        warn(f"{source}: timestamps give a sample rate of {rate:.4g} Hz; check time_scale (seconds per unit)")
    _inputs_checks(out, t, dt, nominal_dt, acc_b, gyro_b, max_step_samples)
    return out


def _inputs_checks(out: ImuChecks, t: np.ndarray, dt: np.ndarray, nominal_dt: float, acc_b: np.ndarray,
                   gyro_b: np.ndarray, max_step_samples: float) -> None:
    """The checks whose findings shape a navigation system's inputs, into ``out``: the gaps
    (steps longer than ``max_step_samples`` nominal periods ``nominal_dt`` s) and the clipped
    runs of each sensor."""
    source, warn = out.source, out.warnings.append
    gaps = np.flatnonzero(dt > max_step_samples * nominal_dt) + 1
    if gaps.size:
        out.gap_index = gaps.astype(np.int64)
        out.gap_missing_s = dt[gaps - 1] - nominal_dt
        worst = int(np.argmax(out.gap_missing_s))
        warn(f"{source}: {gaps.size} gap(s) longer than {max_step_samples:g} samples, "
             f"{out.gap_missing_s.sum():.3g} s missing in all, the longest {out.gap_missing_s[worst]:.3g} s "
             f"at t = {t[gaps[worst]]:.6g} s")
    for key, what, x, unit in (("acc", "accelerometer", acc_b, "m/s^2"), ("gyro", "gyroscope", gyro_b, "rad/s")):
        clipping = find_clipping(x, nominal_dt if np.isfinite(nominal_dt) else 0.0)
        if clipping.runs:
            out.clipping[key] = clipping
            warn(f"{source}: {clipping.describe(what, unit)}")
    out.clipped_acc_samples = out.clipping["acc"].samples if "acc" in out.clipping else 0
    out.clipped_gyro_samples = out.clipping["gyro"].samples if "gyro" in out.clipping else 0
