"""The foot INS's state at its first sample: levelled and its gyro bias taken where the IMU rests,
navigated back from there when the recording starts in motion.

A mixin of :class:`~bodyfusion.plugins.foot_ins.system.FootIns` (its stream, stance, filter
parameters, initial heading and position are the system's):

* :meth:`InitialState._find_still_interval`: the first still interval
  (:func:`bodyfusion.nav.initial_alignment.find_still_interval`: spreads at the recording's own
  noise floor, no drift of the angular rate), else the quietest window and a warning;
* :meth:`InitialState._initial_state`: TRIAD levelling on the interval's mean specific force, the
  gyro bias its mean angular rate, the heading the layout's (or the alignment's), the priors
  widened to the window's standard errors where it was not still;
* :meth:`InitialState._navigate_back`: the state at the first sample, from the interval's start
  back (the forward kernel on the reversed record).
"""

from __future__ import annotations

import numpy as np

from bodyfusion.base.errors import ConfigError
from bodyfusion.nav.attitude import quat_to_dcm
from bodyfusion.nav.error_state import DPOS, rotate_about_up
from bodyfusion.nav.initial_alignment import (AXIS_VECTORS, StillInterval, attitude_from_specific_force,
                                              find_still_interval, heading_axis, mean_standard_error)
from bodyfusion.nav.strapdown import NOMINAL_SIZE
from bodyfusion.plugins.foot_ins.kernels import C_GATED, C_ZUPTS, COUNTERS_SIZE, run_foot_ins
from bodyfusion.plugins.foot_ins.records import RECORDED_COVARIANCE, FilterHistory, FilterState, ImuSamples, no_record

MIN_STILL_SAMPLES = 10
"""Fewest samples in a still window: its spreads must measure the sensor's noise."""


class InitialState:
    """The foot INS's initial state (module docstring)."""

    def _find_still_interval(self) -> StillInterval:
        """The first still interval (:func:`bodyfusion.nav.initial_alignment.find_still_interval`);
        without one, the quietest window, and a warning."""
        ini = self.config.initial
        key = f"systems.{self.name}.initial.stationary_s"
        t = self.stream.t
        length = round(ini.stationary_s * self._rate_hz)
        if length < MIN_STILL_SAMPLES:
            raise ConfigError(key, f"{ini.stationary_s:g} s holds {length} samples at {self._rate_hz:.4g} Hz; "
                                   f"the noise of a still window needs at least {MIN_STILL_SAMPLES}")
        if length > len(t):
            raise ConfigError(key, f"{ini.stationary_s} s is longer than the recording ({t[-1] - t[0]:.3g} s)")
        still = find_still_interval(self.stream.acc_b, self.stream.gyro_b, length, ini.still_acc_sd_mps2,
                                    ini.still_gyro_sd_radps)
        span = f"t = {t[still.start]:.2f}–{t[still.stop - 1]:.2f} s"
        if not still.still:
            self.stream.report.warn(
                f"{self.name}: no still interval of {ini.stationary_s:g} s (spreads ≤ {ini.still_acc_sd_mps2:g} m/s^2, "
                f"{ini.still_gyro_sd_radps:g} rad/s); levelled on the quietest window {span} (spreads "
                f"{still.acc_spread_mps2:.2g} m/s^2, {still.gyro_spread_radps:.2g} rad/s), level and gyro-bias "
                "uncertainty at least the standard errors of its means")
        elif still.start > 0:
            self.stream.report.notes.append(f"{self.name}: levelled on the still interval {span}; the "
                                            f"{t[still.start] - t[0]:.2f} s before it navigated backward from there")
        return still

    def _initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """The state at the first sample: levelled (TRIAD on the mean specific force) and the
        gyro bias (mean angular rate) on the still interval, the heading from the layout; if
        the interval starts later, navigated backward to the first sample (:meth:`_navigate_back`)."""
        ini = self.config.initial
        st = self.still
        window = slice(st.start, st.stop)
        f_b = self.stream.acc_b[window].mean(axis=0)
        self.heading_axis = heading_axis(f_b, ini.heading_axis)
        if self.heading_axis != ini.heading_axis and ini.heading_deg != "auto" and not hasattr(self, "_x0"):
            self.stream.report.warn(f"{self.name}: body axis {ini.heading_axis} is near vertical at rest; "
                                    f"initial.heading_deg is taken as the heading of axis {self.heading_axis}")
        level_sd = np.deg2rad(ini.level_sd_deg)
        gyro_bias_sd = ini.gyro_bias_sd_radps
        if not st.still:  # the mean over a moving window: the standard errors of its means
            level_sd = max(level_sd, mean_standard_error(self.stream.acc_b[window]) / self.context.gravity_mps2)
            gyro_bias_sd = max(gyro_bias_sd, mean_standard_error(self.stream.gyro_b[window]))
        x = np.zeros(NOMINAL_SIZE)
        x[6:10] = attitude_from_specific_force(f_b, self._azimuth0, self.heading_axis)
        x[13:16] = self.stream.gyro_b[window].mean(axis=0)
        sd = np.concatenate([
            np.full(3, self._position_sd0), np.full(3, ini.velocity_sd_mps),
            [level_sd, level_sd, np.deg2rad(ini.heading_sd_deg)],
            np.full(3, ini.acc_bias_sd_mps2), np.full(3, gyro_bias_sd)])
        P = np.diag(sd**2)
        self._still_priors = {"level_sd_deg": float(np.degrees(level_sd)), "gyro_bias_sd_radps": float(gyro_bias_sd)}
        if st.start > 0:
            x, P = self._navigate_back(x, P, st.start)
        x[0:3] = self._position0
        return x, P

    def _navigate_back(self, x_s: np.ndarray, P_s: np.ndarray, s: int) -> tuple[np.ndarray, np.ndarray]:
        """From the state at sample s back to sample 0: the forward kernel run on the reversed
        record (t → −t, ω → −ω, the same specific force; velocity, gyro bias and the Earth
        rate change sign), with the same gated ZUPTs. The result is turned about Up so that
        the heading at sample 0 is the layout's, and its covariance doubled: the forward run
        uses the same zero-velocity updates again (the bound for information counted twice);
        position restarts from the layout's with its prior σ."""
        st = self.stream
        r = np.arange(s + 1)
        src = np.minimum(s - r + 1, s)  # the sample whose interval is stepped back over (r ≥ 1)
        params = self._params.backward()
        sign = np.ones(15)
        sign[3:6] = sign[12:15] = -1.0
        flip = np.outer(sign, sign)
        xb = x_s.copy()
        xb[3:6] *= -1.0
        xb[13:16] *= -1.0
        Pb = P_s * flip
        t_r, acc_r, gyro_r = -self._t_nav[s - r], st.acc_b[src], -st.gyro_b[src]
        stance_r = np.ascontiguousarray(self.stance[s - r])
        hist_x, hist_cov = np.empty((s + 1, NOMINAL_SIZE)), np.empty((s + 1, RECORDED_COVARIANCE))
        self.backward_counters = np.zeros(COUNTERS_SIZE)
        run_foot_ins(FilterState(xb, Pb, np.zeros(6), np.empty((0, 0))), ImuSamples(t_r, acc_r, gyro_r, stance_r), 1,
                     s + 1, params, FilterHistory(hist_x, hist_cov, np.empty(s + 1), self.backward_counters),
                     no_record())
        xb[3:6] *= -1.0
        xb[13:16] *= -1.0
        Pb = 2.0 * (Pb * flip)
        a_n = quat_to_dcm(xb[6:10]) @ AXIS_VECTORS[self.heading_axis]
        x0, P0 = rotate_about_up(xb, Pb, self._azimuth0 - float(np.arctan2(a_n[0], a_n[1])))
        P0[DPOS, :] = 0.0
        P0[:, DPOS] = 0.0
        P0[DPOS, DPOS] = np.eye(3) * self._position_sd0**2
        return x0, P0

    def _initialisation_report(self) -> dict:
        st, (t_first, t_still, t_still_end) = self.still, self.still_span_s
        P0 = self._P0
        report = {"still_interval_s": [t_still, t_still_end], "still": st.still,
                  "acc_spread_mps2": st.acc_spread_mps2, "gyro_spread_radps": st.gyro_spread_radps,
                  "heading_axis": self.heading_axis, **self._still_priors,
                  "first_sample_sd": {"level_deg": float(np.degrees(np.sqrt(max(P0[6, 6], P0[7, 7])))),
                                      "heading_deg": float(np.degrees(np.sqrt(P0[8, 8]))),
                                      "gyro_bias_radps": float(np.sqrt(np.max(np.diag(P0)[12:15])))}}
        if st.start > 0:
            report["backward_s"] = t_still - t_first
            report["backward_zupts"] = int(self.backward_counters[C_ZUPTS])
            report["backward_zupt_gated"] = int(self.backward_counters[C_GATED])
        return report
