"""Foot-mounted INS: strapdown navigation, zero-velocity detection, and the estimator the
layout's ``filter.kind`` selects: the 15-state error-state EKF (``ekf``), the EKF with the
coloured-noise zero-velocity update (``ckf``), or the ensemble filters (``enekf``, ``cenekf``)."""

from __future__ import annotations

import numpy as np

from fusion import detectors
from fusion.config import KeyedError, Layout, apply_axis_map
from fusion.errors import ConfigError, FusionError
from fusion.quaternion import levelling, quat_from_azimuth_pitch_roll
from fusion.measurements import GateCounts, chi2_gate, position_fix_update
from fusion.readers import read_imu_csv, read_truth_csv
from fusion.strapdown import NOMINAL_SIZE
from fusion.system import LayoutContext, SensorSystem
from fusion.types import ImuStream, InputReport, Trajectory
from fusion_plugins.foot_ins.config import COLOURED_KINDS, ENSEMBLE_KINDS, DetectorConfig, FootInsConfig
from fusion.error_state import PARAMS_SIZE, inv3_sym
from fusion_plugins.foot_ins.ensemble import Ensemble
from fusion_plugins.foot_ins.kernels import (C_COLOURED, C_NIS_SUM, C_ZARUS, C_ZUPTS, COUNTERS_SIZE,
                                             differenced_samples, run_foot_ins,
                                             run_foot_ins_coloured)

_DEFAULT_THRESHOLDS = {"shoe": 0.3e5, "magnitude": 0.5}


def detect_stance(stream: ImuStream, cfg: DetectorConfig, gravity: float, key: str) -> np.ndarray:
    """Stance flags (N,) from the configured detector, then debounced (durations in s)."""
    threshold = cfg.threshold if cfg.threshold is not None else _DEFAULT_THRESHOLDS.get(cfg.kind)
    if cfg.kind == "labels":  # the config model ensures the data have a stance column
        stance = stream.stance.copy()
    elif cfg.kind == "shoe":
        stance = detectors.shoe(stream.acc_b, stream.gyro_b, window=cfg.window, sigma_acc=cfg.sigma_acc,
                                sigma_gyro=cfg.sigma_gyro, threshold=threshold, gravity=gravity)
    elif cfg.kind == "magnitude":
        stance = detectors.acceleration_magnitude(stream.acc_b, threshold=threshold, gravity=gravity, window=cfg.window)
    else:
        low = cfg.low if cfg.low is not None else gravity - 1.0
        high = cfg.high if cfg.high is not None else gravity + 1.0
        if not low < high:
            raise ConfigError(f"{key}.low", f"need low < high, got {low} and {high}")
        stance = detectors.axes_sum_band(stream.acc_b, low=low, high=high, window=cfg.window)
    rate = 1.0 / np.median(np.diff(stream.t))
    if cfg.min_stance_s > 0 or cfg.min_swing_s > 0:
        stance = detectors.debounce(stance, min_stance=max(1, round(cfg.min_stance_s * rate)),
                                    min_swing=max(1, round(cfg.min_swing_s * rate)))
    return np.ascontiguousarray(stance, dtype=np.bool_)


class FootIns(SensorSystem):
    """Foot-mounted IMU navigated by strapdown + ZUPT, closed loop.

    Error state (15): δp, δv, δθ (nav frame), δb_a, δb_g; see :mod:`fusion.error_state`.
    ``filter.kind`` selects the estimator:

    * ``ekf``, ``ckf``: the per-sample loop runs compiled
      (:func:`fusion_plugins.foot_ins.kernels.run_foot_ins`) in chunks between the fuser's
      sync epochs; the ckf's stance update is :mod:`fusion_plugins.foot_ins.coloured`. The
      smoothers rebuild the EKF's covariances with ordinary ZUPTs, so the ckf keeps its
      covariance after every coloured update for them (15×15 floats, 1.8 kB, per stance sample).
    * ``enekf``, ``cenekf``: M members (:class:`fusion_plugins.foot_ins.ensemble.Ensemble`);
      ``x`` is their mean, ``P`` the sample covariance of their error-state deviations (15,
      or 18 with the cenekf's coloured noise δV), and a correction moves the mean and maps
      the deviations so that their sample covariance is the one given. Position fixes are
      applied the same way: a gated Kalman update of the mean and covariance, carried to the
      members by that correction. Not smoothable, no cross-covariance tracking (refused at
      validation, :meth:`check_layout`).

    Results (after the run): :meth:`trajectory`, ``hist_x`` (N, 16) nominal (mean) states,
    ``stance`` (N,) detector output.
    """

    plugin_name = "foot_ins"
    Config = FootInsConfig
    error_model = "strapdown15"

    def __init__(self, name: str, config: FootInsConfig, context: LayoutContext) -> None:
        super().__init__(name, config, context)
        d = config.data
        self.stream = read_imu_csv(
            d.path, acc_columns=d.acc_columns, gyro_columns=d.gyro_columns, stance_column=d.stance_column,
            acc_unit=d.acc_unit, gyro_unit=d.gyro_unit, time_column=d.time_column, time_scale=d.time_scale,
            rate_hz=d.rate_hz, skip_rows=d.skip_rows, delimiter=d.delimiter, timestamp_policy=d.timestamp_policy)
        self.stance = detect_stance(self.stream, config.detector, context.gravity_mps2, f"systems.{name}.detector")
        self._params = self._filter_params()
        self._fix_index, self._fix_pos_n = self._read_position_fixes()
        fx = config.position_fixes
        self._fix_sigma = fx.sigma_m if fx is not None else 0.0
        self._fix_gate = chi2_gate(fx.gate_probability, 3) if fx is not None else 0.0
        heading = config.initial.heading_deg
        self._azimuth0 = 0.0 if heading == "auto" else np.deg2rad(heading)
        self._x0, self._P0 = self._initial_state()
        self.restart()

    @classmethod
    def check_layout(cls, name: str, config: FootInsConfig, layout: Layout) -> None:
        """Refuse layout settings this system's estimator cannot serve (KeyedError naming the
        layout key): the ensemble kinds with a smoother (the smoothers rebuild the 15-state
        EKF's covariances) or with tracked cross-covariances (no error-state transition Φ)."""
        kind = config.filter.kind
        if kind not in ENSEMBLE_KINDS:
            return
        if layout.smoother.kind != "none":
            raise KeyedError("smoother.kind", f"systems.{name}.filter.kind {kind} cannot be smoothed "
                                              "(the smoothers rebuild the 15-state EKF); use none")
        constrained = {n for c in layout.constraints for n in c.between}
        if layout.fuser.cross_covariance and name in constrained and layout.fuser.method != "none":
            raise KeyedError("fuser.cross_covariance", f"systems.{name}.filter.kind {kind} has no error-state "
                                                       "transition to carry cross-covariances; use false")

    @property
    def is_ensemble(self) -> bool:
        """True for the ensemble estimators (enekf, cenekf)."""
        return self.config.filter.kind in ENSEMBLE_KINDS

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
            from fusion.earth import earth_rate_enu

            p[7:10] = earth_rate_enu(self.context.latitude_deg)
        return p

    def _initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Levelling and gyro bias from the stationary window at the start (roll/pitch from
        the mean specific force, b_g = mean angular rate); heading from the layout."""
        ini = self.config.initial
        t = self.stream.t
        window = t - t[0] <= ini.stationary_s
        if window.sum() < 2:
            raise ConfigError(f"systems.{self.name}.initial.stationary_s", "window holds fewer than 2 samples")
        pitch, roll = levelling(self.stream.acc_b[window].mean(axis=0))
        x = np.zeros(NOMINAL_SIZE)
        x[0:3] = ini.position_m
        x[6:10] = quat_from_azimuth_pitch_roll(self._azimuth0, pitch, roll)
        x[13:16] = self.stream.gyro_b[window].mean(axis=0)
        sd = np.concatenate([
            np.full(3, ini.position_sd_m), np.full(3, ini.velocity_sd_mps),
            np.deg2rad([ini.level_sd_deg, ini.level_sd_deg, ini.heading_sd_deg]),
            np.full(3, ini.acc_bias_sd_mps2), np.full(3, ini.gyro_bias_sd_radps)])
        return x, np.diag(sd**2)

    def restart(self) -> None:
        """Back to the initial state at the first sample; history cleared (the ensemble
        redrawn from the same seed)."""
        n = len(self.stream)
        f = self.config.filter
        self.ensemble: Ensemble | None = None
        if self.is_ensemble:
            self.ensemble = Ensemble(f.members, self._x0, self._P0,
                                     f.colour_factor if f.kind in COLOURED_KINDS else None, f.zupt_sigma_mps,
                                     self.context.seed, self.name)
            self.x = self.ensemble.mean[:NOMINAL_SIZE].copy()
            self.P = self.ensemble.covariance()
        else:
            self.x = self._x0.copy()
            self.P = self._P0.copy()
        self.hist_x = np.empty((n, NOMINAL_SIZE))
        self.hist_pos_var = np.empty((n, 3))
        self.hist_x[0] = self.x
        self.hist_pos_var[0] = np.diag(self.P)[:3]
        self.counters = np.zeros(COUNTERS_SIZE)
        self.phi = np.eye(15) if getattr(self, "_tracking", False) else np.empty((0, 0))
        self.mech_memory = np.zeros(6)
        self.fix_counts = GateCounts()
        self._next_fix = 0
        self._i = 0  # index of the sample the state refers to
        # for the smoother (fusion.smoothing): covariances left by corrections outside the
        # compiled loop (fuser constraints, position fixes), and the smoothed result
        self._override_idx: list[np.ndarray] = []
        self._override_P: list[np.ndarray] = []
        self.smoothed_x: np.ndarray | None = None
        self.smoothed_pos_var: np.ndarray | None = None
        self.smoothing_diagnostics: dict | None = None

    # --- time ---------------------------------------------------------------------
    @property
    def t_now(self) -> float:
        return float(self.stream.t[self._i])

    def advance(self, t: float) -> None:
        i1 = int(np.searchsorted(self.stream.t, t, side="right"))
        while self._next_fix < len(self._fix_index) and self._fix_index[self._next_fix] < i1:
            k = self._fix_index[self._next_fix]
            self._run_to(k + 1)
            if self.ensemble is not None:
                self._ensemble_position_fix(self._fix_pos_n[self._next_fix])
            else:
                position_fix_update(self.x, self.P, self._fix_pos_n[self._next_fix], self._fix_sigma,
                                    self._fix_gate, self.fix_counts, self.phi)
                self.hist_x[k] = self.x
                self.hist_pos_var[k] = np.diag(self.P)[:3]
                self._record_override(k)
            self._next_fix += 1
        self._run_to(i1)

    def _run_to(self, i1: int) -> None:
        """Process samples up to (excluding) index i1 in one compiled chunk."""
        if i1 <= self._i + 1:
            return
        i0 = self._i + 1
        st = self.stream
        if self.ensemble is not None:
            self.ensemble.run(st.t, st.acc_b, st.gyro_b, self.stance, i0, i1, self._params, self.hist_x,
                              self.hist_pos_var, self.counters)
            self.x = self.ensemble.mean[:NOMINAL_SIZE].copy()
            self.P = self.ensemble.covariance()
        else:
            f = self.config.filter
            if f.kind == "ckf":
                idx = differenced_samples(self.stance, i0, i1)
                post_P = np.empty((idx.size, 15, 15))
                run_foot_ins_coloured(self.x, self.P, st.t, st.acc_b, st.gyro_b, self.stance, i0, i1, self._params,
                                      f.colour_factor, self.mech_memory, self.phi, self.hist_x, self.hist_pos_var,
                                      self.counters, post_P)
                if idx.size:  # the smoother rebuilds ordinary ZUPTs: it takes the ckf's covariances here
                    self._override_idx.append(idx.astype(np.int64))
                    self._override_P.append(post_P)
            else:
                run_foot_ins(self.x, self.P, st.t, st.acc_b, st.gyro_b, self.stance, i0, i1, self._params,
                             self.mech_memory, self.phi, self.hist_x, self.hist_pos_var, self.counters)
        self._i = i1 - 1

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
        from fusion.error_state import inject

        P = 0.5 * (P + P.T)
        if self.ensemble is not None:
            self.ensemble.correct(np.asarray(dx, dtype=np.float64), P)
            self.x = self.ensemble.mean[:NOMINAL_SIZE].copy()
            self.P = P
            self.hist_x[self._i] = self.x
            self.hist_pos_var[self._i] = np.diag(self.P)[:3]
            return
        inject(self.x, np.ascontiguousarray(dx, dtype=np.float64))
        self.P = P
        self.hist_x[self._i] = self.x
        self.hist_pos_var[self._i] = np.diag(self.P)[:3]
        self._record_override(self._i)

    def _ensemble_position_fix(self, z_n: np.ndarray) -> None:
        """Gated position fix on the ensemble: the Kalman update of the mean and the sample
        covariance (H selects δp, σ per axis, chi-square gate), applied to the members by
        :meth:`apply_correction`."""
        y = z_n - self.x[0:3]
        r_var = self._fix_sigma**2
        P = self.P
        S = P[0:3, 0:3] + r_var * np.eye(3)
        if float(y @ inv3_sym(np.ascontiguousarray(S)) @ y) > self._fix_gate:
            self.fix_counts.rejected += 1
            return
        K = np.linalg.solve(S, P[0:3, :]).T
        IKH = np.eye(P.shape[0])
        IKH[:, 0:3] -= K
        self.apply_correction(K @ y, IKH @ P @ IKH.T + r_var * K @ K.T)
        self.fix_counts.accepted += 1

    def track_transition(self) -> None:
        if self.ensemble is not None:
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

    # --- smoothing (fusion.smoothing) --------------------------------------------------
    def _record_override(self, i: int) -> None:
        self._override_idx.append(np.array([i], dtype=np.int64))
        self._override_P.append(self.P[None].copy())

    def smoothing_record(self) -> dict:
        """What the smoother needs to rebuild this filter's run (nothing is copied but the
        few covariances set outside the compiled loop): IMU samples, stance flags, filter
        parameters, the recorded nominal history, the initial covariance, and the sample
        indices (sorted) with the covariance left there by a fuser correction or a fix (and,
        for the ckf, after every coloured update). Ensemble kinds have no such record."""
        if self.ensemble is not None:
            raise FusionError(f"filter.kind {self.config.filter.kind} cannot be smoothed")
        n = self._i + 1
        idx = np.concatenate([np.empty(0, dtype=np.int64), *self._override_idx])
        Ps = np.concatenate([np.empty((0, 15, 15)), *self._override_P])
        order = np.argsort(idx, kind="stable")
        return {"t": self.stream.t[:n], "acc": self.stream.acc_b[:n], "gyro": self.stream.gyro_b[:n],
                "stance": self.stance[:n], "params": self._params, "hist_x": self.hist_x[:n],
                "P0": self._P0.copy(), "P_end": self.P.copy(), "override_idx": np.ascontiguousarray(idx[order]),
                "override_P": np.ascontiguousarray(Ps[order]), "rate_hz": float(1.0 / np.median(np.diff(self.stream.t)))}

    def set_smoothed(self, x: np.ndarray | None, pos_var: np.ndarray | None, diagnostics: dict) -> None:
        """Store the smoother's result: (n, 16) nominal states and (n, 3) position
        variances replace the filter's in :meth:`trajectory` (None keeps the filter's)."""
        self.smoothed_x = x
        self.smoothed_pos_var = pos_var
        self.smoothing_diagnostics = diagnostics

    # --- results ----------------------------------------------------------------------
    def trajectory(self) -> Trajectory:
        n = self._i + 1
        if self.smoothed_x is not None and self.smoothed_pos_var is not None:
            return Trajectory(self.stream.t[:n], self.smoothed_x[:n, 0:3],
                              np.sqrt(np.maximum(self.smoothed_pos_var[:n], 0.0)))
        return Trajectory(self.stream.t[:n], self.hist_x[:n, 0:3], np.sqrt(np.maximum(self.hist_pos_var[:n], 0.0)))

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
            "filter_kind": self.config.filter.kind,
            **({"coloured_updates": int(self.counters[C_COLOURED])} if self.config.filter.kind == "ckf" else {}),
            **({"members": self.config.filter.members} if self.ensemble is not None else {}),
            **({"position_fixes_accepted": self.fix_counts.accepted,
                "position_fixes_rejected": self.fix_counts.rejected} if self.config.position_fixes else {}),
            **({"smoothing": self.smoothing_diagnostics} if self.smoothing_diagnostics is not None else {}),
        }
