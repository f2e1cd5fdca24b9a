"""Foot-mounted INS: strapdown navigation, zero-velocity detection, and the estimator the
layout's ``filter.kind`` selects: the 15-state error-state EKF (``ekf``), the EKF with the
coloured-noise zero-velocity update (``ckf``), or the ensemble filters (``enekf``, ``cenekf``)."""

from __future__ import annotations

import logging

import numpy as np

from bodyfusion.base.errors import FusionError
from bodyfusion.base.findings import Finding
from bodyfusion.base.sections import KeyedError
from bodyfusion.core.layout import Layout, SmootherConfig
from bodyfusion.core.capabilities import BodyPlacement, HeadingAlignment, Smoothing, TransitionTracking
from bodyfusion.core.system import CovarianceHistory, LayoutContext, SensorSystem
from bodyfusion.base.types import ImuStream, InputReport, Trajectory
from bodyfusion.nav.filter_health import NisRecord, NisTally, innovation_columns, nis, quaternion_norm_deviation
from bodyfusion.io.imu import read_imu
from bodyfusion.io.truth import read_truth_csv
from bodyfusion.nav import detectors
from bodyfusion.nav.attitude import quat_to_dcm
from bodyfusion.nav.earth import earth_rate_enu
from bodyfusion.nav.error_state import DVEL, FilterParams, filter_params
from bodyfusion.nav.frames import apply_axis_map
from bodyfusion.nav.measurements import GateCounts, chi2_gate
from bodyfusion.nav.strapdown import NOMINAL_SIZE
from bodyfusion.plugins.foot_ins.config import BODY_POSITION_SD_M, STANCE_WIDTH_M, FootInsConfig
from bodyfusion.plugins.foot_ins.initial_state import InitialState
from bodyfusion.plugins.foot_ins.input_policy import (DerivedInputs, covariance_increments, navigation_clock,
                                                      repair_saturation, saturation_findings)
from bodyfusion.plugins.foot_ins.estimators import ESTIMATORS, EnsembleEkf, Estimator, RunData, compile_step_ahead
from bodyfusion.plugins.foot_ins.kernels import (C_COLOURED, C_GATED, C_NIS_SUM, C_ZARUS, C_ZUPTS, COUNTERS_SIZE,
                                                 NO_RESET, NO_STANCE, NOT_PACKED)
from bodyfusion.plugins.foot_ins.stance import LOCKOUT_STANCES, detect_stance, stance_findings
from bodyfusion.plugins.foot_ins.strides import mounting, stride_table
from bodyfusion.plugins.foot_ins.results import CovarianceLog, foot_covariance, foot_states, stance_phases, zupt_columns
from bodyfusion.plugins.foot_ins.smoothing import smooth_system
from bodyfusion.plugins.foot_ins.smoothing_joint import JointRtsMember
from bodyfusion.plugins.foot_ins.records import ATTITUDE_COVARIANCE, RECORDED_COVARIANCE, VELOCITY_VARIANCE
from bodyfusion.plugins.foot_ins.smoothing_record import ForwardRecord
from bodyfusion.plugins.foot_ins.streaming import StreamingFootIns

MIN_RATE_HZ = 40.0
"""Below this sample rate (Hz) a foot INS's run gets a ``low_rate`` finding: a swing of about
0.4 s is then under 16 samples."""
MIN_LOCKOUT_SAMPLES = 5
"""Stance updates a stance needs before all of them beyond the gate count as a lockout."""
RECOVERY_VELOCITY_SD_MPS = 0.1
"""Velocity σ (m/s) a ZUPT lockout adds beside the velocity the filter holds."""
RECOVERY_LEVEL_SD_RAD = 0.05
"""Roll and pitch σ (rad, ~3°) a ZUPT lockout adds."""

log = logging.getLogger(__name__)


class FootIns(StreamingFootIns, InitialState, SensorSystem, HeadingAlignment, BodyPlacement, TransitionTracking,
              Smoothing):
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
        self._prepare(read_imu(config.data))
        log.info("%s: %d samples at %.0f Hz; stance (detector %s) in %.0f %% of them", name, len(self.stance),
                 self._rate_hz, config.detector.kind, 100 * float(np.mean(self.stance)))
        self._params = self._filter_params()
        self.still = self._find_still_interval()
        t = self.stream.t
        self.still_span_s = (float(t[0]), float(t[self.still.start]), float(t[self.still.stop - 1]))
        """The recording's first sample and the levelling interval's first and last (s): what a
        live run that forgets its first samples still says of them."""
        self._check_ready()
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

    def _prepare(self, stream: ImuStream) -> None:
        """Take ``stream`` (read and checked) and what the filter derives from it whole
        (:meth:`_derive`), with the stance runs and the navigation clock."""
        derived = self._derive(stream)
        self.stream = derived.stream
        self.clipping = derived.clipping
        self._rate_hz = derived.rate_hz
        self.stance_detection = derived.detection
        self.stance = derived.detection.stance
        self._input_increments = derived.increments
        self._stance_runs = detectors.stance_events(self.stance)
        self._t_nav = navigation_clock(self.stream)

    def _derive(self, stream: ImuStream) -> DerivedInputs:
        """What the filter derives from ``stream`` whole: its saturated runs rebuilt (in place), its
        rate, the stance, the gap and saturation policies' covariance increments."""
        clipping = repair_saturation(stream, self.name)
        detection = detect_stance(stream, self.config.detector, self.context.gravity_mps2,
                                  f"systems.{self.name}.detector")
        return DerivedInputs(stream, clipping, float(1.0 / np.median(np.diff(stream.t))), detection,
                             covariance_increments(stream, self.context.gravity_mps2, clipping))

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

    def _filter_params(self) -> FilterParams:
        f = self.config.filter
        return filter_params(
            acc_noise_density=f.acc_noise_density, gyro_noise_density=f.gyro_noise_density,
            acc_bias_walk=f.acc_bias_random_walk, gyro_bias_walk=f.gyro_bias_random_walk, zupt_sigma=f.zupt_sigma_mps,
            zaru_sigma=f.zaru_sigma_radps or 0.0, gravity=self.context.gravity_mps2,
            earth_rate=earth_rate_enu(self.context.latitude_deg) if f.earth_rate else np.zeros(3),
            zupt_gate=chi2_gate(f.zupt_gate_probability, 3) if f.zupt_gate_probability is not None else 0.0,
            acc_bias_decay=0.0 if f.acc_bias_tau_s is None else 1.0 / f.acc_bias_tau_s,
            gyro_bias_decay=0.0 if f.gyro_bias_tau_s is None else 1.0 / f.gyro_bias_tau_s,
            zupt_pivot=f.zupt_pivot_m)

    def restart(self) -> None:
        """Back to the initial state at the first sample; history cleared (an ensemble redrawn from the same seed)."""
        n = len(self.stream)
        self.filter: Estimator = ESTIMATORS[self.config.filter.kind](self._x0, self._P0, self.config.filter,
                                                                     self.context.seed, self.name)
        self.run_data = RunData(self._t_nav, self.stream.acc_b, self.stream.gyro_b, self.stance, self._params,
                                np.empty((n, NOMINAL_SIZE)), np.empty((n, RECORDED_COVARIANCE)), np.full(n, NO_STANCE),
                                np.zeros(COUNTERS_SIZE))
        self.run_data.record = self._forward_record.restart(self._P0, self.run_data.counters)
        self.phi = np.eye(15) if getattr(self, "_tracking", False) else np.empty((0, 0))
        compile_step_ahead(self.filter, self.run_data, self.phi, self.context.compiling_ahead)
        self.filter.reset_and_record(*NO_RESET, self.run_data, 0, NOT_PACKED)
        self.corrections = CovarianceLog()  # the covariances corrections outside the compiled loop leave
        self._gap_index, self._gap_P = self._input_increments[0].copy(), self._input_increments[1].copy()
        self._locked_stances = 0
        self.zupt_recoveries: list[float] = []  # times (s) the ZUPT lockout re-inflated the covariance
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
    def hist_cov(self) -> np.ndarray:
        """(N, 13) covariance entries after each sample
        (:data:`~bodyfusion.plugins.foot_ins.records.RECORDED_COVARIANCE`): position variances
        and east–north covariance (m²), velocity variances (m²/s²), the attitude error's block (rad²)."""
        return self.run_data.hist_cov

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
        """Process samples up to (excluding) index i1 in compiled chunks, split where a covariance
        increment applies (the gap and saturation policies, a ZUPT recovery: recorded for the
        smoothers) and, with a ZUPT gate, at every stance's end to watch for a lockout
        (:meth:`_watch_lockout`)."""
        i = self._i + 1
        if i1 <= i:
            return
        ends = self._stance_runs[1]
        watch = self._params.zupt_gate > 0.0 and self.filter.smoothable  # the ensembles keep no NIS
        while i < i1:
            g = self._gap_index
            k = int(g.searchsorted(i))
            if k < g.size and g[k] == i:
                dP = np.zeros_like(self.P)
                dP[:15, :15] = self._gap_P[k]
                self._i = i - 1
                self.apply_correction(np.zeros(self.P.shape[0]), self.P + dP)
                k += 1
            b = min(i1, int(g[k]) if k < g.size else i1)
            r = int(ends.searchsorted(i, side="right"))
            if watch and r < ends.size and ends[r] < b:
                b = int(ends[r])
            self.filter.run(self.run_data, i, b, self.phi)
            if watch and r < ends.size and ends[r] == b:
                self._watch_lockout(r)
            i = b
        self._i = i1 - 1
        self._forward_record.capture(self._i, self.P)  # for a correction made here next

    def _watch_lockout(self, r: int) -> None:
        """After stance run r: a stance whose every zero-velocity update was beyond the gate, the
        :data:`~bodyfusion.plugins.foot_ins.stance.LOCKOUT_STANCES`-th in a row, means the filter's
        velocity and level disagree with rest by more than its covariance allows (a corrupt
        sample, a missed stance before): the velocity and level variances are re-inflated before
        the next step, by the velocity held and :data:`RECOVERY_VELOCITY_SD_MPS` beside it, and by
        the tilt the stance's specific force shows (the angle between Up and its mean turned into
        the navigation frame by the attitude held) and :data:`RECOVERY_LEVEL_SD_RAD` beside it, so
        that the next stance's updates pass the gate and pull the state back."""
        a, b = int(self._stance_runs[0][r]), int(self._stance_runs[1][r])
        nis = self.run_data.hist_nis[a:b]
        nis = nis[nis >= 0.0]
        if nis.size < MIN_LOCKOUT_SAMPLES or not np.all(nis > self._params.zupt_gate):
            self._locked_stances = 0
            return
        self._locked_stances += 1
        if self._locked_stances < LOCKOUT_STANCES or b >= len(self.stream):
            return
        dP = np.zeros((15, 15))
        v = self.hist_x[b - 1, 3:6]
        dP[DVEL, DVEL] = np.diag(v**2) + RECOVERY_VELOCITY_SD_MPS**2 * np.eye(3)
        up_n = quat_to_dcm(self.hist_x[b - 1, 6:10]) @ self.stream.acc_b[a:b].mean(axis=0)
        tilt = float(np.arccos(np.clip(up_n[2] / max(np.linalg.norm(up_n), 1e-12), -1.0, 1.0)))
        dP[6, 6] = dP[7, 7] = tilt**2 + RECOVERY_LEVEL_SD_RAD**2
        at = int(self._gap_index.searchsorted(b))
        if at < self._gap_index.size and self._gap_index[at] == b:
            self._gap_P[at] = self._gap_P[at] + dP
        else:
            self._gap_index = np.insert(self._gap_index, at, b)
            self._gap_P = np.insert(self._gap_P, at, dP, axis=0)
        self.zupt_recoveries.append(float(self.stream.t[b - 1]))
        self._locked_stances = 0

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
        return self.stream.t[self._stance_runs[0]]

    def sample_times(self) -> np.ndarray:
        return self.stream.t

    # --- smoothing (bodyfusion.plugins.foot_ins.smoothing) ---------------------------------------------
    def smoothing_record(self, first: int = 0) -> dict:
        """What the smoothers need to replay this filter's run (nothing is copied but the few covariances set outside
        the compiled loop): IMU samples, stance flags, filter parameters, the recorded nominal history, the initial
        covariance, the gaps (sample index after each gap, sorted, and the covariance the gap policy added before the
        step to it: process noise of that step), the sample indices (sorted) with the covariance left there by a fuser
        correction or a fix (and, for the ckf, after every coloured update), the kept corrections' sample indices
        (sorted, one per sample) with the nominal state before the first of them there, and what the filter recorded
        for the whole-run RTS as it ran (``forward_record``). ``first``: the run from that sample on, every index
        counted from it (a live fixed-lag window; ``P0`` is then the caller's to set). Ensemble kinds have no such
        record."""
        if not self.filter.smoothable:
            raise FusionError(f"filter.kind {self.config.filter.kind} cannot be smoothed")
        n = self._i + 1
        idx, Ps = self.corrections.covariances(first)  # in time order; the ckf's own before them, sorted stably
        if self.run_data.override_idx:
            idx = np.concatenate([*self.run_data.override_idx, idx])
            order = np.argsort(idx, kind="stable")
            idx, Ps = idx[order], np.concatenate([*self.run_data.override_P, Ps])[order]
            later = idx >= first
            idx, Ps = idx[later], Ps[later]
        # kept corrections: the state before the first at each sample
        held = self.run_data.kept_idx.view()
        k0 = int(np.searchsorted(held, first))
        kept_idx, kept_first = np.unique(held[k0:], return_index=True)
        gaps = (self._gap_index <= self._i) & (self._gap_index >= first)
        gap_idx = self._gap_index[gaps]
        # the gap policy's inflation went through apply_correction: the last override at g − 1
        keep = np.ones(idx.size, dtype=bool)
        keep[np.searchsorted(idx, gap_idx - 1, side="right") - 1] = False
        idx, Ps = (idx, Ps) if keep.all() else (idx[keep], Ps[keep])
        return {"t": self._t_nav[first:n], "acc": self.stream.acc_b[first:n], "gyro": self.stream.gyro_b[first:n],
                "stance": self.stance[first:n], "params": self._params, "hist_x": self.hist_x[first:n],
                "P0": (self._P0 if self.P_first_held is None else self.P_first_held).copy(), "P_end": self.P.copy(),
                "override_idx": idx - first, "override_P": Ps,
                "kept_idx": kept_idx - first, "kept_x": self.run_data.kept_x.view()[k0:][kept_first],
                "gap_idx": np.ascontiguousarray(gap_idx - first), "gap_dP": np.ascontiguousarray(self._gap_P[gaps]),
                "rate_hz": float(1.0 / np.median(np.diff(self.stream.t[first:]))),
                "forward_record": self._forward_record}

    def plan_smoothing(self, cfg: SmootherConfig) -> None:
        """Before the run: the filter records what the layout's ``smoother`` needs as it runs when
        :meth:`~bodyfusion.plugins.foot_ins.smoothing_record.ForwardRecord.plan` says so; restarts when that changes."""
        if self.context.growing:  # a live run's windows replay the filter: no record of a run still growing
            return
        if self._forward_record.plan(cfg, self.config.filter.kind, self._params, self.stance):
            self.restart()

    def smooth(self, cfg: SmootherConfig) -> dict | None:
        """RTS, FB or FB-RTS over this run (:mod:`bodyfusion.plugins.foot_ins.smoothing`); then :meth:`trajectory`
        is the smoothed track. The ensemble kinds are refused at validation (:meth:`check_layout`)."""
        return smooth_system(self, cfg).diagnostics

    def joint_smoothing_member(self, cfg: SmootherConfig) -> JointRtsMember:
        """This run in the joint RTS (:mod:`bodyfusion.plugins.foot_ins.smoothing_joint`)."""
        return JointRtsMember(self, cfg)

    def set_smoothed(self, x: np.ndarray | None, pos_cov: np.ndarray | None, diagnostics: dict) -> None:
        """Store the smoother's result: (n, 16) nominal states and (n, 4) position covariances (as
        :attr:`hist_cov`) replace the filter's in :meth:`trajectory` (None keeps the filter's)."""
        self.smoothed_x = x
        self.smoothed_pos_cov = pos_cov
        self.smoothing_diagnostics = diagnostics

    # --- results ----------------------------------------------------------------------
    def trajectory(self) -> Trajectory:
        """Position, velocity and attitude of every sample so far with their covariances (a
        smoothed track's velocity and attitude come without: the smoothers keep the position
        block only)."""
        x, cov = self._history()
        smoothed = cov.shape[1] < RECORDED_COVARIANCE
        return Trajectory(self.stream.t[:len(x)], x[:, 0:3], np.sqrt(np.maximum(cov[:, :3], 0.0)), cov[:, 3].copy(),
                          vel_n=x[:, 3:6], q_nb=x[:, 6:10],
                          motion_cov=None if smoothed else cov[:, VELOCITY_VARIANCE.start:ATTITUDE_COVARIANCE.stop])

    def _history(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, 16) nominal states and their covariance entries so far: the filter's (N, 13,
        :data:`~bodyfusion.plugins.foot_ins.records.RECORDED_COVARIANCE`), or where smoothed the
        smoother's states and position covariances (N, 4)."""
        n = self._i + 1
        smoothed = self.smoothed_x is not None and self.smoothed_pos_cov is not None
        return ((self.smoothed_x if smoothed else self.hist_x)[:n],
                (self.smoothed_pos_cov if smoothed else self.hist_cov)[:n])

    def states(self) -> dict[str, np.ndarray]:
        """Every sample's nominal state (:func:`~bodyfusion.plugins.foot_ins.results.foot_states`)."""
        return foot_states(self.stream.t[:self._i + 1], self._history()[0])

    def covariance_history(self) -> CovarianceHistory:
        """Every sample's recorded covariance entries (:func:`~bodyfusion.plugins.foot_ins.results.foot_covariance`:
        position, velocity variances, the attitude block; where smoothed the position block)."""
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
        parts = {"zupt": zupt_columns(self.stream.t, self.run_data.hist_nis[:self._i + 1], self._params.zupt_gate)}
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
            "zupt_recoveries": len(self.zupt_recoveries),
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
        saturation (:func:`~bodyfusion.plugins.foot_ins.input_policy.saturation_findings`), a
        rate below :data:`MIN_RATE_HZ` and a levelling without rest."""
        n = self._i + 1
        out = stance_findings(self.name, self.stance_detection, self.stream.t[:n], self.run_data.hist_nis[:n],
                              float(self._params.zupt_gate), self.zupt_recoveries)
        out += saturation_findings(self.name, self.clipping, self.stream.t)
        out += self.live_findings()
        if self._rate_hz < MIN_RATE_HZ:
            t = self.stream.t
            out.append(Finding(
                "low_rate", "warning", self.name, float(t[0]), float(t[n - 1]),
                f"the IMU samples at {self._rate_hz:.3g} Hz, below the {MIN_RATE_HZ:g} Hz a foot needs: a swing "
                f"(about 0.4 s) spans {0.4 * self._rate_hz:.0f} samples, too few for the strapdown integration and "
                "the stance detector; expect errors of metres.",
                "the recording's rate (or time_scale / rate_hz declaring it wrongly).",
                "record at 100 Hz or more; check time_scale against the file's time column."))
        if not self.still.still:
            out.append(Finding(
                "no_rest", "warning", self.name, *self.still_span_s[1:],
                f"the IMU never rested for {self.config.initial.stationary_s:g} s; it was levelled and its gyro bias "
                f"taken on its quietest window (spreads {self.still.acc_spread_mps2:.2g} m/s^2, "
                f"{self.still.gyro_spread_radps:.2g} rad/s), so its initial attitude and heading drift are uncertain.",
                "the recording starts in motion and never stands still.",
                "record a second or two standing still before walking, or lower initial.stationary_s."))
        return out
