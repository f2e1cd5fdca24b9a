"""Foot-mounted INS: strapdown navigation, zero-velocity detection, and the estimator the
layout's ``filter.kind`` selects: the 15-state error-state EKF (``ekf``), the EKF with the
coloured-noise zero-velocity update (``ckf``), or the ensemble filters (``enekf``, ``cenekf``)."""

from __future__ import annotations

import logging

import numpy as np

from bodyfusion.base.errors import ConfigError, FusionError
from bodyfusion.base.findings import Finding
from bodyfusion.base.sections import KeyedError
from bodyfusion.core.layout import Layout, SmootherConfig
from bodyfusion.core.system import CovarianceHistory, LayoutContext, SensorSystem
from bodyfusion.base.types import InputReport, Trajectory
from bodyfusion.evaluation.consistency import NisRecord, NisTally, innovation_columns, nis, quaternion_norm_deviation
from bodyfusion.io.imu import read_imu
from bodyfusion.io.truth import read_truth_csv
from bodyfusion.nav import detectors
from bodyfusion.nav.attitude import quat_to_dcm
from bodyfusion.nav.earth import earth_rate_enu
from bodyfusion.nav.error_state import (DPOS, P_ACC_BIAS_DECAY, P_EARTH_RATE, P_GYRO_BIAS_DECAY,
                                       P_ZUPT_GATE, P_ZUPT_PIVOT, PARAMS_SIZE, rotate_about_up)
from bodyfusion.nav.frames import apply_axis_map
from bodyfusion.nav.initial_alignment import (AXIS_VECTORS, StillInterval, attitude_from_specific_force,
                                              find_still_interval, heading_axis, mean_standard_error)
from bodyfusion.nav.measurements import GateCounts, chi2_gate
from bodyfusion.nav.strapdown import NOMINAL_SIZE
from bodyfusion.plugins.foot_ins.config import BODY_POSITION_SD_M, STANCE_WIDTH_M, FootInsConfig
from bodyfusion.plugins.foot_ins.input_policy import (covariance_increments, navigation_clock, repair_saturation,
                                                      saturation_findings)
from bodyfusion.plugins.foot_ins.estimators import ESTIMATORS, EnsembleEkf, Estimator, RunData, compile_step_ahead
from bodyfusion.plugins.foot_ins.kernels import (C_COLOURED, C_GATED, C_NIS_SUM, C_ZARUS, C_ZUPTS, COUNTERS_SIZE,
                                                 NO_RESET, NO_STANCE, NOT_PACKED, no_record, run_foot_ins)
from bodyfusion.plugins.foot_ins.stance import detect_stance, stance_findings
from bodyfusion.plugins.foot_ins.strides import mounting, stride_table
from bodyfusion.plugins.foot_ins.results import CovarianceLog, foot_covariance, foot_states, stance_phases, zupt_columns
from bodyfusion.plugins.foot_ins.smoothing import ForwardRecord, smooth_system

MIN_STILL_SAMPLES = 10
"""Fewest samples in a still window: its spreads must measure the sensor's noise."""

log = logging.getLogger(__name__)


class FootIns(SensorSystem):
    """Foot-mounted IMU navigated by strapdown + ZUPT, closed loop.

    Error state (15): δp, δv, δθ (nav frame), δb_a, δb_g; see :mod:`bodyfusion.nav.error_state`.
    ``filter.kind`` selects the estimator:

    * ``ekf``, ``ckf``: the per-sample loop runs compiled (:func:`bodyfusion.plugins.foot_ins.kernels.run_foot_ins`)
      in chunks between the fuser's sync epochs; the ckf's stance update is :mod:`bodyfusion.plugins.foot_ins.coloured`.
      The smoothers rebuild the EKF's covariances with ordinary ZUPTs, so the ckf keeps its covariance after
      every coloured update for them (15×15 floats, 1.8 kB, per stance sample).
    * ``enekf``, ``cenekf``: M members (:class:`bodyfusion.plugins.foot_ins.ensemble.Ensemble`); ``x`` is their
      mean, ``P`` the sample covariance of their error-state deviations (15, or 18 with the cenekf's coloured
      noise δV), and a correction moves the mean and maps the deviations so that their sample covariance is
      the one given. Position fixes are applied the same way: a gated Kalman update of the mean and
      covariance, carried to the members by that correction. Not smoothable, no cross-covariance tracking
      (refused at validation, :meth:`check_layout`).

    Results (after the run): :meth:`trajectory`, ``hist_x`` (N, 16) nominal (mean) states, ``stance`` (N,)
    detector output."""

    plugin_name = "foot_ins"
    body_part = "foot"
    Config = FootInsConfig
    data_section = "data"
    error_model = "strapdown15"
    smooths_in_a_thread = True  # its smoother is one compiled call (nogil) on its own record

    def __init__(self, name: str, config: FootInsConfig, context: LayoutContext) -> None:
        super().__init__(name, config, context)
        self.stream = read_imu(config.data)
        self.clipping = repair_saturation(self.stream, name)
        self._rate_hz = float(1.0 / np.median(np.diff(self.stream.t)))
        self.stance_detection = detect_stance(self.stream, config.detector, context.gravity_mps2,
                                              f"systems.{name}.detector")
        self.stance = self.stance_detection.stance
        log.info("%s: %d samples at %.0f Hz; stance (detector %s) in %.0f %% of them", name, len(self.stance),
                 self._rate_hz, config.detector.kind, 100 * float(np.mean(self.stance)))
        self._params = self._filter_params()
        self.still = self._find_still_interval()
        self._gap_index, self._gap_P = covariance_increments(self.stream, context.gravity_mps2, self.clipping)
        self._t_nav = navigation_clock(self.stream)
        self._fix_index, self._fix_pos_n = self._read_position_fixes()
        fx = config.position_fixes
        self._fix_sigma = fx.sigma_m if fx is not None else 0.0
        self._fix_gate = chi2_gate(fx.gate_probability, 3) if fx is not None else 0.0
        heading = config.initial.heading_deg
        self._azimuth0 = 0.0 if heading == "auto" else np.deg2rad(heading)
        self._position0 = np.zeros(3) if config.initial.position_m is None else np.asarray(config.initial.position_m)
        self._position_sd0 = config.initial.position_sd_m
        self._x0, self._P0 = self._initial_state()
        self._forward_record = ForwardRecord()  # what the filter records for the whole-run RTS
        self.restart()

    @classmethod
    def check_layout(cls, name: str, config: FootInsConfig, layout: Layout) -> None:
        """Refuse layout settings this system's estimator cannot serve (KeyedError naming the
        layout key): a smoother for an estimator the smoothers cannot rebuild, tracked
        cross-covariances for one without an error-state transition (the ensemble kinds)."""
        kind = config.filter.kind
        estimator = ESTIMATORS[kind]
        if layout.smoother.kind != "none" and not estimator.smoothable:
            raise KeyedError("smoother.kind", f"systems.{name}.filter.kind {kind} cannot be smoothed "
                                              "(the smoothers rebuild the 15-state EKF); use none")
        constrained = {n for c in layout.constraints for n in c.between}
        if (layout.fuser.cross_covariance and name in constrained and layout.fuser.method != "none"
                and not estimator.tracks_transition):
            raise KeyedError("fuser.cross_covariance", f"systems.{name}.filter.kind {kind} has no error-state "
                                                       "transition to carry cross-covariances; use false")

    # --- set-up -------------------------------------------------------------------
    def _read_position_fixes(self) -> tuple[np.ndarray, np.ndarray]:
        """Fix positions (K, 3) and the index of the last IMU sample at or before each fix."""
        fx = self.config.position_fixes
        if fx is None:
            return np.empty(0, dtype=np.int64), np.empty((0, 3))
        track = read_truth_csv(fx.path, position_columns={"fix": fx.columns}, time_column=fx.time_column,
                               time_scale=fx.time_scale, rate_hz=fx.rate_hz, delimiter=fx.delimiter)["fix"]
        index = np.searchsorted(self.stream.t, track.t, side="right") - 1
        usable = index >= 1
        return index[usable].astype(np.int64), apply_axis_map(fx.axes, track.pos_n[usable])

    def _filter_params(self) -> np.ndarray:
        f = self.config.filter
        p = np.zeros(PARAMS_SIZE)
        p[:7] = (f.acc_noise_density, f.gyro_noise_density, f.acc_bias_random_walk, f.gyro_bias_random_walk,
                 f.zupt_sigma_mps, f.zaru_sigma_radps or 0.0, self.context.gravity_mps2)
        if f.earth_rate:
            p[P_EARTH_RATE] = earth_rate_enu(self.context.latitude_deg)
        if f.zupt_gate_probability is not None:
            p[P_ZUPT_GATE] = chi2_gate(f.zupt_gate_probability, 3)
        p[P_ZUPT_PIVOT] = f.zupt_pivot_m
        for index, tau in ((P_ACC_BIAS_DECAY, f.acc_bias_tau_s), (P_GYRO_BIAS_DECAY, f.gyro_bias_tau_s)):
            p[index] = 0.0 if tau is None else 1.0 / tau
        return p

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
        params = self._params.copy()
        params[P_EARTH_RATE] *= -1.0
        sign = np.ones(15)
        sign[3:6] = sign[12:15] = -1.0
        flip = np.outer(sign, sign)
        xb = x_s.copy()
        xb[3:6] *= -1.0
        xb[13:16] *= -1.0
        Pb = P_s * flip
        t_r, acc_r, gyro_r = -self._t_nav[s - r], st.acc_b[src], -st.gyro_b[src]
        stance_r = np.ascontiguousarray(self.stance[s - r])
        hist_x, hist_cov = np.empty((s + 1, NOMINAL_SIZE)), np.empty((s + 1, 4))
        self.backward_counters = np.zeros(COUNTERS_SIZE)
        run_foot_ins(xb, Pb, t_r, acc_r, gyro_r, stance_r, 1, s + 1, params, np.zeros(6), np.empty((0, 0)),
                     hist_x, hist_cov, np.empty(s + 1), self.backward_counters, *no_record())
        xb[3:6] *= -1.0
        xb[13:16] *= -1.0
        Pb = 2.0 * (Pb * flip)
        a_n = quat_to_dcm(xb[6:10]) @ AXIS_VECTORS[self.heading_axis]
        x0, P0 = rotate_about_up(xb, Pb, self._azimuth0 - float(np.arctan2(a_n[0], a_n[1])))
        P0[DPOS, :] = 0.0
        P0[:, DPOS] = 0.0
        P0[DPOS, DPOS] = np.eye(3) * self._position_sd0**2
        return x0, P0

    def restart(self) -> None:
        """Back to the initial state at the first sample; history cleared (an ensemble redrawn from the same seed)."""
        n = len(self.stream)
        self.filter: Estimator = ESTIMATORS[self.config.filter.kind](self._x0, self._P0, self.config.filter,
                                                                     self.context.seed, self.name)
        self.run_data = RunData(self._t_nav, self.stream.acc_b, self.stream.gyro_b, self.stance, self._params,
                                np.empty((n, NOMINAL_SIZE)), np.empty((n, 4)), np.full(n, NO_STANCE),
                                np.zeros(COUNTERS_SIZE))
        self.run_data.record = self._forward_record.restart(self._P0, self.run_data.counters)
        self.phi = np.eye(15) if getattr(self, "_tracking", False) else np.empty((0, 0))
        compile_step_ahead(self.filter, self.run_data, self.phi, self.context.compiling_ahead)
        self.filter.reset_and_record(*NO_RESET, self.run_data, 0, NOT_PACKED)
        self.corrections = CovarianceLog()  # the covariances corrections outside the compiled loop leave
        self.fix_counts = GateCounts()
        self.fix_nis = NisRecord(3)
        self._next_fix = 0
        self._i = 0  # index of the sample the state refers to
        self.smoothed_x: np.ndarray | None = None
        self.smoothed_pos_cov: np.ndarray | None = None
        self.smoothing_diagnostics: dict | None = None

    @property
    def x(self) -> np.ndarray:
        """Nominal state (16,): position ENU m, velocity m/s, q_nb, accelerometer and gyro biases."""
        return self.filter.x

    @property
    def P(self) -> np.ndarray:
        """Error-state covariance (15, 15; 18, 18 for the cenekf)."""
        return self.filter.P

    @property
    def hist_x(self) -> np.ndarray:
        """(N, 16) nominal state after each sample."""
        return self.run_data.hist_x

    @property
    def hist_pos_cov(self) -> np.ndarray:
        """(N, 4) position covariance after each sample: variances east, north, up and the
        east–north covariance, m²."""
        return self.run_data.hist_pos_cov

    @property
    def counters(self) -> np.ndarray:
        """The kernels' counters (layout ``C_*`` of :mod:`bodyfusion.plugins.foot_ins.kernels`)."""
        return self.run_data.counters

    # --- time ---------------------------------------------------------------------
    @property
    def t_now(self) -> float:
        return float(self.stream.t[self._i])

    def advance(self, t: float) -> None:
        i1 = int(self.stream.t.searchsorted(t, side="right"))
        while self._next_fix < len(self._fix_index) and self._fix_index[self._next_fix] < i1:
            k = self._fix_index[self._next_fix]
            self._run_to(k + 1)
            self._count_fix_nis(self._fix_pos_n[self._next_fix])
            self.filter.position_fix(self._fix_pos_n[self._next_fix], self._fix_sigma, self._fix_gate,
                                     self.fix_counts, self.phi)
            self._record_state(k)
            self._next_fix += 1
        self._run_to(i1)

    def _run_to(self, i1: int) -> None:
        """Process samples up to (excluding) index i1 in compiled chunks, split where the gap
        policy inflates the covariance (recorded for the smoothers)."""
        i = self._i + 1
        if i1 <= i:
            return
        g = self._gap_index  # sorted; the usual case, none ahead, costs no search
        gaps = g[g.searchsorted(i):g.searchsorted(i1)].tolist() if g.size and g[-1] >= i else []
        for a, b in zip([i, *gaps], [*gaps, i1]):
            if a in gaps:
                dP = np.zeros_like(self.P)
                dP[:15, :15] = self._gap_P[g.searchsorted(a)]
                self._i = a - 1
                self.apply_correction(np.zeros(self.P.shape[0]), self.P + dP)
            self.filter.run(self.run_data, a, b, self.phi)
        self._i = i1 - 1
        self._forward_record.capture(self._i, self.P)  # for a correction made here next

    # --- heading ------------------------------------------------------------------
    @property
    def heading_is_auto(self) -> bool:
        return self.config.initial.heading_deg == "auto"

    def initial_travel_azimuth(self, distance_m: float) -> float | None:
        self.restart()
        chunk_s = 5.0
        t = self.t_start
        azimuth = None
        while self._i < len(self.stream) - 1:
            t += chunk_s
            self.advance(t)
            pos = self.hist_x[: self._i + 1, 0:2]
            path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pos, axis=0).T))])
            reached = np.flatnonzero(path >= distance_m)
            if reached.size:
                d = pos[reached[0]] - pos[0]
                azimuth = float(np.arctan2(d[0], d[1]))
                break
        self.restart()
        return azimuth

    def yaw_error_row(self) -> np.ndarray:
        """δθ_U, the attitude error about Up (:mod:`bodyfusion.nav.error_state`)."""
        row = np.zeros(self.P.shape[0])
        row[8] = 1.0
        return row

    @property
    def side(self) -> str | None:
        """The foot wearing it: ``foot`` of the layout, else ``left``/``right`` in the system's name."""
        if self.config.foot is not None:
            return self.config.foot
        sides = [side for side in ("left", "right") if side in self.name.lower()]
        return sides[0] if len(sides) == 1 else None

    @property
    def wants_body_place(self) -> bool:
        return self.config.initial.position_m is None

    @property
    def lateral_offset_m(self) -> float:
        """Half of :data:`~bodyfusion.plugins.foot_ins.config.STANCE_WIDTH_M` left (−) or right (+)."""
        return {"left": -0.5, "right": 0.5, None: 0.0}[self.side] * STANCE_WIDTH_M

    def place_on_body(self, walking_azimuth_rad: float) -> None:
        """Half of :data:`~bodyfusion.plugins.foot_ins.config.STANCE_WIDTH_M` to the left or right
        of the walking direction, σ at least :data:`~bodyfusion.plugins.foot_ins.config.BODY_POSITION_SD_M`
        horizontally (twice that, at the origin, when the side is unknown)."""
        right = np.array([np.cos(walking_azimuth_rad), -np.sin(walking_azimuth_rad), 0.0])  # azimuth + 90°
        self._position0 = self.lateral_offset_m * right
        self._position_sd0 = max(self.config.initial.position_sd_m,
                                 BODY_POSITION_SD_M * (1.0 if self.side is not None else 2.0))
        self._x0, self._P0 = self._initial_state()
        self.restart()

    def rotate_initial_heading(self, delta_rad: float) -> None:
        self._azimuth0 += delta_rad
        self._x0, self._P0 = self._initial_state()
        self.restart()

    # --- fuser interface ------------------------------------------------------------
    def position_n(self) -> np.ndarray:
        return self.x[0:3].copy()

    def covariance(self) -> np.ndarray:
        return self.P.copy()

    def apply_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        self._record_state(self._i, dx, P)

    def apply_relative_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        """As :meth:`apply_correction`; the smoothers keep it as made (the state before it kept)."""
        if self.filter.smoothable:
            self.run_data.kept_idx.append(self._i)
            self.run_data.kept_x.append(self.x)  # copied into the record's storage
        self.apply_correction(dx, P)

    def _record_state(self, i: int, dx: np.ndarray = NO_RESET[0], P: np.ndarray = NO_RESET[1]) -> None:
        """History row i after a state set outside the compiled loop: the closed-loop reset by dx
        (n,) and P (n, n) (a fuser correction, the gap policy's inflation) or, without them, a
        position fix the estimator made; the covariance left there is recorded for the smoothers."""
        f, log = self.filter, self.corrections
        packed = log.row(i) if f.smoothable else NOT_PACKED
        if not f.reset_and_record(dx, P, self.run_data, i, packed):
            log.keep_lower(f.P)

    def track_transition(self) -> None:
        if not self.filter.tracks_transition:
            raise FusionError(f"system {self.name!r} (foot_ins, filter.kind {self.config.filter.kind}) cannot "
                              "track cross-covariances: set fuser.cross_covariance false")
        self._tracking = True
        self.phi = np.eye(15)

    def transition_since_sync(self) -> np.ndarray:
        phi = self.phi.copy()
        self.phi = np.eye(15)
        return phi

    def sync_times(self) -> np.ndarray:
        starts, _ = detectors.stance_events(self.stance)
        return self.stream.t[starts]

    def sample_times(self) -> np.ndarray:
        return self.stream.t

    # --- smoothing (bodyfusion.plugins.foot_ins.smoothing) ---------------------------------------------
    def smoothing_record(self) -> dict:
        """What the smoothers need to replay this filter's run (nothing is copied but the few covariances set outside
        the compiled loop): IMU samples, stance flags, filter parameters, the recorded nominal history, the initial
        covariance, the gaps (sample index after each gap, sorted, and the covariance the gap policy added before the
        step to it: process noise of that step), the sample indices (sorted) with the covariance left there by a fuser
        correction or a fix (and, for the ckf, after every coloured update), the kept corrections' sample indices
        (sorted, one per sample) with the nominal state before the first of them there, and what the filter recorded
        for the whole-run RTS as it ran (``forward_record``). Ensemble kinds have no such record."""
        if not self.filter.smoothable:
            raise FusionError(f"filter.kind {self.config.filter.kind} cannot be smoothed")
        n = self._i + 1
        idx, Ps = self.corrections.covariances()  # in time order; the ckf's own before them, sorted stably
        if self.run_data.override_idx:
            order = np.argsort(idx := np.concatenate([*self.run_data.override_idx, idx]), kind="stable")
            idx, Ps = idx[order], np.concatenate([*self.run_data.override_P, Ps])[order]
        # kept corrections: the state before the first at each sample
        kept_idx, first = np.unique(self.run_data.kept_idx.view(), return_index=True)
        gaps = self._gap_index <= self._i
        gap_idx = self._gap_index[gaps]
        # the gap policy's inflation went through apply_correction: the last override at g − 1
        keep = np.ones(idx.size, dtype=bool)
        keep[np.searchsorted(idx, gap_idx - 1, side="right") - 1] = False
        return {"t": self._t_nav[:n], "acc": self.stream.acc_b[:n], "gyro": self.stream.gyro_b[:n],
                "stance": self.stance[:n], "params": self._params, "hist_x": self.hist_x[:n],
                "P0": self._P0.copy(), "P_end": self.P.copy(), "override_idx": idx if keep.all() else idx[keep],
                "override_P": Ps if keep.all() else Ps[keep], "kept_idx": kept_idx,
                "kept_x": self.run_data.kept_x.view()[first],
                "gap_idx": np.ascontiguousarray(gap_idx), "gap_dP": np.ascontiguousarray(self._gap_P[gaps]),
                "rate_hz": float(1.0 / np.median(np.diff(self.stream.t))), "forward_record": self._forward_record}

    def plan_smoothing(self, cfg: SmootherConfig) -> None:
        """Before the run: the filter records what the layout's ``smoother`` needs as it runs when
        :meth:`~bodyfusion.plugins.foot_ins.smoothing.ForwardRecord.plan` says so; restarts when that changes."""
        if self._forward_record.plan(cfg, self.config.filter.kind, self._params, self.stance):
            self.restart()

    def smooth(self, cfg: SmootherConfig) -> dict | None:
        """RTS, FB or FB-RTS over this run (:mod:`bodyfusion.plugins.foot_ins.smoothing`); then :meth:`trajectory`
        is the smoothed track. The ensemble kinds are refused at validation (:meth:`check_layout`)."""
        return smooth_system(self, cfg).diagnostics

    def set_smoothed(self, x: np.ndarray | None, pos_cov: np.ndarray | None, diagnostics: dict) -> None:
        """Store the smoother's result: (n, 16) nominal states and (n, 4) position covariances (as
        :attr:`hist_pos_cov`) replace the filter's in :meth:`trajectory` (None keeps the filter's)."""
        self.smoothed_x = x
        self.smoothed_pos_cov = pos_cov
        self.smoothing_diagnostics = diagnostics

    def _initialisation_report(self) -> dict:
        st, t = self.still, self.stream.t
        P0 = self._P0
        report = {"still_interval_s": [float(t[st.start]), float(t[st.stop - 1])], "still": st.still,
                  "acc_spread_mps2": st.acc_spread_mps2, "gyro_spread_radps": st.gyro_spread_radps,
                  "heading_axis": self.heading_axis, **self._still_priors,
                  "first_sample_sd": {"level_deg": float(np.degrees(np.sqrt(max(P0[6, 6], P0[7, 7])))),
                                      "heading_deg": float(np.degrees(np.sqrt(P0[8, 8]))),
                                      "gyro_bias_radps": float(np.sqrt(np.max(np.diag(P0)[12:15])))}}
        if st.start > 0:
            report["backward_s"] = float(t[st.start] - t[0])
            report["backward_zupts"] = int(self.backward_counters[C_ZUPTS])
            report["backward_zupt_gated"] = int(self.backward_counters[C_GATED])
        return report

    # --- results ----------------------------------------------------------------------
    def trajectory(self) -> Trajectory:
        x, cov = self._history()
        return Trajectory(self.stream.t[:len(x)], x[:, 0:3], np.sqrt(np.maximum(cov[:, :3], 0.0)), cov[:, 3].copy())

    def _history(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, 16) nominal states and (N, 4) position covariances so far, smoothed where smoothed."""
        n = self._i + 1
        smoothed = self.smoothed_x is not None and self.smoothed_pos_cov is not None
        return ((self.smoothed_x if smoothed else self.hist_x)[:n],
                (self.smoothed_pos_cov if smoothed else self.hist_pos_cov)[:n])

    def states(self) -> dict[str, np.ndarray]:
        """Every sample's nominal state (:func:`~bodyfusion.plugins.foot_ins.results.foot_states`)."""
        return foot_states(self.stream.t[:self._i + 1], self._history()[0])

    def covariance_history(self) -> CovarianceHistory:
        """The position covariance of every sample; the foot INS stores no other block."""
        return foot_covariance(self.stream.t[:self._i + 1], self._history()[1])

    def events(self) -> dict[str, np.ndarray]:
        """The stance phases the detector found."""
        return stance_phases(self.stream.t, self.stance[:self._i + 1])

    def strides(self) -> dict[str, np.ndarray]:
        """Stride by stride, on the navigated (smoothed where smoothed) track
        (:func:`~bodyfusion.plugins.foot_ins.strides.stride_table`)."""
        n = self._i + 1
        return stride_table(self.stream.t[:n], self._history()[0][:, 0:3], self.stance[:n])

    def innovations(self) -> dict[str, np.ndarray]:
        """Every stance update's NIS (``zupt``, 3 dof, before the gate; beyond it: de-weighted; the
        ensemble kinds keep none) and every position fix's (``position_fix``, 3 dof)."""
        parts = {"zupt": zupt_columns(self.stream.t, self.run_data.hist_nis[:self._i + 1], self._params[P_ZUPT_GATE])}
        if self.config.position_fixes is not None:
            parts["position_fix"] = self.fix_nis.columns()
        return innovation_columns(parts)

    @property
    def samples(self) -> int:
        return len(self.stream)

    @property
    def input_report(self) -> InputReport:
        return self.stream.report

    def diagnostics(self) -> dict:
        zupts = int(self.counters[C_ZUPTS])
        return {
            "stance_fraction": float(self.stance.mean()),
            "zupt_updates": zupts,
            "zaru_updates": int(self.counters[C_ZARUS]),
            "zupt_mean_nis": float(self.counters[C_NIS_SUM] / zupts) if zupts else None,
            "zupt_gated": int(self.counters[C_GATED]),
            "missed_stances": self.stance_detection.missed_stances,
            "fallback_updates": int(self.stance_detection.fallback[:self._i + 1].sum()),
            "initialisation": self._initialisation_report(),
            "mounting": mounting(self.stream.t[:self._i + 1], self._history()[0], self.stance[:self._i + 1],
                                 self.stream.acc_b),
            **({"input_checks": self.stream.checks.to_dict()} if self.stream.checks is not None else {}),
            "filter_kind": self.config.filter.kind,
            **({"coloured_updates": int(self.counters[C_COLOURED])} if self.config.filter.kind == "ckf" else {}),
            **({"members": self.config.filter.members} if isinstance(self.filter, EnsembleEkf) else {}),
            **({"position_fixes_accepted": self.fix_counts.accepted,
                "position_fixes_rejected": self.fix_counts.rejected} if self.config.position_fixes else {}),
            **({"smoothing": self.smoothing_diagnostics} if self.smoothing_diagnostics is not None else {}),
        }

    def _count_fix_nis(self, z_n: np.ndarray) -> None:
        """The NIS of position fix z_n (ENU, m) against the state before it, S = P_pp + σ² I."""
        value = nis(z_n - self.x[0:3], self.P[0:3, 0:3] + self._fix_sigma**2 * np.eye(3))
        self.fix_nis.add(self.t_now, value, value <= self._fix_gate)

    def health(self) -> dict:
        """As :meth:`SensorSystem.health`, plus ``quaternion_norm_max_deviation`` of the filter's
        history (``smoothed_quaternion_norm_max_deviation``: the smoother's) and ``nis``:
        ``zupt`` (3 dof, every stance sample before gating; beyond the gate: de-weighted;
        with the ckf the coloured updates' NIS too), ``zaru`` (3 dof; the compiled kernels keep
        no ZARU NIS sum, so only its count), ``position_fix`` (3 dof, with position fixes)."""
        n = self._i + 1
        c = self.counters
        tallies = {"zupt": NisTally(3, int(c[C_ZUPTS]), float(c[C_NIS_SUM]), int(c[C_GATED])),
                   "zaru": NisTally(3, int(c[C_ZARUS]), None)}
        if self.config.position_fixes is not None:
            tallies["position_fix"] = self.fix_nis.tally()
        out = {**super().health(), "quaternion_norm_max_deviation": quaternion_norm_deviation(self.hist_x[:n, 6:10]),
               "nis": {kind: tally.to_dict() for kind, tally in tallies.items()}}
        out["nis"]["zupt"]["missed_stances"] = self.stance_detection.missed_stances  # beside the gated ones
        if self.smoothed_x is not None:
            out["smoothed_quaternion_norm_max_deviation"] = quaternion_norm_deviation(self.smoothed_x[:n, 6:10])
        return out

    def findings(self) -> list[Finding]:
        """Missed stances and ZUPT lockouts (:func:`~bodyfusion.plugins.foot_ins.stance.stance_findings`),
        saturation (:func:`~bodyfusion.plugins.foot_ins.input_policy.saturation_findings`), and a
        levelling without rest."""
        n = self._i + 1
        out = stance_findings(self.name, self.stance_detection, self.stream.t[:n], self.run_data.hist_nis[:n],
                              float(self._params[P_ZUPT_GATE]))
        out += saturation_findings(self.name, self.clipping, self.stream.t)
        if not self.still.still:
            t = self.stream.t
            out.append(Finding(
                "no_rest", "warning", self.name, float(t[self.still.start]), float(t[self.still.stop - 1]),
                f"the IMU never rested for {self.config.initial.stationary_s:g} s; it was levelled and its gyro bias "
                f"taken on its quietest window (spreads {self.still.acc_spread_mps2:.2g} m/s^2, "
                f"{self.still.gyro_spread_radps:.2g} rad/s), so its initial attitude and heading drift are uncertain.",
                "the recording starts in motion and never stands still.",
                "record a second or two standing still before walking, or lower initial.stationary_s."))
        return out
