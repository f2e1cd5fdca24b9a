"""Hand-held phone: pedestrian dead reckoning corrected by GNSS (PDR/GNSS paper §5).

Nominal state: position E, N, U (ENU, m), step heading ψ (azimuth of walking, rad,
clockwise from North), bias b of the levelled-gyro azimuth rate (rad/s), horizontal GNSS
error β (m, first-order Gauss–Markov), step-length scale c (1: the step model as
configured) and, with the magnetometer, the holding offset o (rad, walking azimuth minus
the phone's device azimuth). Error state (9):
[δE, δN, δU, δψ, δS, δb, δβE, δβN, δc], δS the current step's length error (white, σ_S),
δc the scale error common to every step (a wrong Weinberg K: random walk, initial σ
``step_scale_sd``; σ 0 gives the paper's model, where step errors are white only).

At each step k (eq. 37, S_k = c s_k):  E += S_k sin ψ_k,  N += S_k cos ψ_k, and (eqs. 38–40)
    δE' = δE + S cos ψ δψ + sin ψ (δS + s δc),   δN' = δN − S sin ψ δψ + cos ψ (δS + s δc).
Between events, over Δt:  ψ += Δψ_gyro − b Δt;  δψ' = δψ − Δt δb + w_ψ;
δb' = e^{−Δt/τ} δb + w_b (first-order Gauss–Markov, τ = 1/α);  δU' = δU + w_U.
(The paper writes δψ' = δψ + Δt δb for a bias error of the opposite sign; here b is
subtracted from the azimuth rate, so its error enters with a minus.)
GNSS (eqs. 41–44, with the correlated error): position z = p_gnss − (p̂ + β̂),
H = [I3 0 0 0 I2]; δβ' = e^{−Δt/τ_β} δβ + w_β; heading from the GNSS
course when the speed is above a threshold, z = wrap(ψ_gnss − ψ̂). Each update is gated
by the chi-square test on its innovation; fixes inside a layout outage are skipped.

Magnetometer (``magnetometer.enabled``; :mod:`fusion_plugins.hand_pdr.magnetometer`): the
device azimuth ψ_d (tilt-compensated, declination applied) and the walking heading differ
by the holding offset o, ψ = ψ_d + o; o is a tenth error state δo (random walk), appended
last. Update: z = wrap(ψ_d − (ψ̂ − ô)), H = [0 0 0 1 0 0 0 0 0 −1], chi-square gated, after
the Earth-field check. With ``offset_deg: auto`` the first accepted sample sets
ô = ψ̂ − ψ_d instead: δo ← δψ + v (the state's row of the error transition becomes that
of δψ, plus the measurement's variance), so the fuser's cross-covariances stay exact.
"""

from __future__ import annotations

import numpy as np

from fusion.errors import ConfigError
from fusion.gnss import GnssFixes, read_gnss_csv, read_nmea
from fusion.heading import wrap_angle
from fusion.measurements import chi2_gate
from fusion.phone_log import read_getsensordata
from fusion.readers import read_imu_csv
from fusion.system import LayoutContext, SensorSystem
from fusion.types import InputReport, Trajectory
from fusion_plugins.hand_pdr.config import HandPdrConfig
from fusion_plugins.hand_pdr.magnetometer import MagneticHeading, read_magnetometer_csv
from fusion_plugins.hand_pdr.pdr import azimuth_increments, detect_steps, step_lengths, up_in_body

E, N, U, PSI, S, B, BE, BN, C, O = range(10)
NOMINAL = [E, N, U, PSI, B, BE, BN, C]
"""Error-state indices of the nominal state's entries (E, N, U, ψ, b, βE, βN, c)."""
N_ERR = 9
"""Error states without the magnetometer; with it, the offset δo is state ``O`` (the tenth)."""
STEP, GNSS, MAGNETOMETER = range(3)
"""Event kinds, in the order they are processed at one time."""


class HandPdr(SensorSystem):
    """PDR from a phone's IMU with a 9-state error Kalman filter corrected by GNSS (10 states
    with the magnetometer's holding offset).

    Results: :meth:`trajectory` (one epoch per step, GNSS and magnetometer update), ``step_index``
    (IMU sample of each detected step), ``step_length_m``, ``gnss_counts`` (accepted,
    rejected, masked), ``mag_counts`` (accepted, rejected by the gate, rejected by the field
    check), ``geodetic_origin`` (lat, lon, h of the ENU frame), ``heading_alignment_end_s``
    (time of the last fix used by ``gnss_track``).
    """

    plugin_name = "hand_pdr"
    Config = HandPdrConfig

    def __init__(self, name: str, config: HandPdrConfig, context: LayoutContext) -> None:
        super().__init__(name, config, context)
        key = f"systems.{name}"
        report = InputReport()
        fixes: GnssFixes | None = None
        mag = config.magnetometer
        magn: tuple[np.ndarray, np.ndarray] | None = None
        if config.phone_log is not None:
            log = read_getsensordata(config.phone_log)
            report = log.report
            self.t = log.acc.t
            acc = log.acc.xyz
            gyro = np.column_stack([np.interp(self.t, log.gyro.t, log.gyro.xyz[:, k]) for k in range(3)])
            if config.gnss is not None and config.gnss.format == "phone_log":
                fixes = log.gnss
            if mag.enabled:
                if log.magn is None:
                    raise ConfigError(f"{key}.magnetometer.enabled", f"{config.phone_log} has no MAGN lines")
                magn = (log.magn.t, log.magn.xyz)  # GetSensorData logs µT
        else:
            d = config.imu
            stream = read_imu_csv(d.path, acc_columns=d.acc_columns, gyro_columns=d.gyro_columns,
                                  acc_unit=d.acc_unit, gyro_unit=d.gyro_unit, time_column=d.time_column,
                                  time_scale=d.time_scale, rate_hz=d.rate_hz, skip_rows=d.skip_rows,
                                  delimiter=d.delimiter, timestamp_policy=d.timestamp_policy)
            report = stream.report
            self.t, acc, gyro = stream.t, stream.acc_b, stream.gyro_b
            if mag.enabled:
                magn = read_magnetometer_csv(d, mag.columns, mag.unit)
        g = config.gnss
        if g is not None and g.format == "csv":
            fixes = read_gnss_csv(g.path, time_column=g.time_column, lat_column=g.lat_column, lon_column=g.lon_column,
                                  height_column=g.height_column, accuracy_column=g.accuracy_column,
                                  speed_column=g.speed_column, course_column=g.course_column)
        elif g is not None and g.format == "nmea":
            fixes = read_nmea(g.path)
        if fixes is not None:
            report = report.merge(fixes.report)
        self._report = report
        self.step_index = detect_steps(self.t, acc, config.step, context.gravity_mps2)
        self.step_length_m = step_lengths(self.t, acc, self.step_index, config.step)
        up_b = up_in_body(self.t, acc)
        self._azimuth = azimuth_increments(self.t, gyro, up_b)
        self.n_err = N_ERR + mag.enabled
        self._nominal = NOMINAL + [O] * mag.enabled
        self._mag = MagneticHeading.of(*magn, self.t, up_b, mag) if magn is not None else None
        self.geodetic_origin = context.geodetic_origin
        if fixes is not None and len(fixes):
            if self.geodetic_origin is None:
                self.geodetic_origin = (float(fixes.lat_deg[0]), float(fixes.lon_deg[0]), float(fixes.height_m[0]))
            self._fix_t = fixes.t
            self._fix_pos = fixes.enu(self.geodetic_origin)
            sd = config.filter.accuracy_to_sigma * fixes.accuracy_m
            self._fix_sd = np.where(np.isfinite(sd) & (sd > 0), sd, config.filter.default_sigma_m)
            self._fix_speed = fixes.speed_mps
            self._fix_course = np.deg2rad(fixes.course_deg)
            masked = np.zeros(len(fixes), dtype=bool)
            for start, duration in context.outages.get(name, ()):
                masked |= (fixes.t >= start) & (fixes.t < start + duration)
            self._fix_masked = masked
        else:
            self._fix_t = np.empty(0)
            self._fix_masked = np.empty(0, dtype=bool)
        self._events = self._event_list()
        self.heading_alignment_end_s: float | None = None
        ini = config.initial
        if ini.position_m == "gnss":
            usable = np.flatnonzero(~self._fix_masked)
            if usable.size == 0:
                raise ConfigError(f"{key}.initial.position_m", "no GNSS fix to start from")
            self._p0 = self._fix_pos[usable[0]].copy()
        else:
            self._p0 = np.asarray(ini.position_m, dtype=float)
        if ini.heading_deg == "gnss_track":
            self._psi0 = self._heading_from_gnss_track(key)
        elif ini.heading_deg == "auto":
            self._psi0 = 0.0
        else:
            self._psi0 = float(np.deg2rad(ini.heading_deg))
        self._gate_pos = chi2_gate(config.filter.gate_probability, 3)
        self._gate_psi = chi2_gate(config.filter.gate_probability, 1)
        self._gate_mag = chi2_gate(mag.gate_probability, 1)
        self.restart()

    # --- set-up -----------------------------------------------------------------
    def _event_list(self) -> list[tuple[float, int, int]]:
        """(time, kind, index) of steps, GNSS fixes and magnetometer updates, in time order."""
        ev = [(float(self.t[i]), STEP, k) for k, i in enumerate(self.step_index)]
        ev += [(float(tf), GNSS, j) for j, tf in enumerate(self._fix_t) if self.t[0] < tf <= self.t[-1]]
        if self._mag is not None:
            ev += [(float(tm), MAGNETOMETER, k) for k, tm in enumerate(self._mag.t) if self.t[0] < tm <= self.t[-1]]
        return sorted(ev)

    def _pdr_track(self, psi0: float) -> tuple[np.ndarray, np.ndarray]:
        """Step times and horizontal PDR positions (from the start, no filter) for heading psi0."""
        psi = psi0 + self._azimuth[self.step_index]
        d = np.column_stack([self.step_length_m * np.sin(psi), self.step_length_m * np.cos(psi)])
        return self.t[self.step_index], np.cumsum(d, axis=0)

    def _heading_from_gnss_track(self, key: str) -> float:
        """Initial heading rotating the PDR track's first ``align_distance_m`` onto the GNSS
        track's (the angle between the two displacement vectors over the same interval)."""
        usable = np.flatnonzero(~self._fix_masked)
        if usable.size < 2:
            raise ConfigError(f"{key}.initial.heading_deg", "gnss_track needs GNSS fixes")
        pos = self._fix_pos[usable, :2]
        far = np.flatnonzero(np.hypot(*(pos - pos[0]).T) >= self.config.initial.align_distance_m)
        if far.size == 0:
            raise ConfigError(f"{key}.initial.heading_deg",
                              f"GNSS never moves {self.config.initial.align_distance_m} m from its first fix")
        t0, t1 = self._fix_t[usable[0]], self._fix_t[usable[far[0]]]
        self.heading_alignment_end_s = float(t1)
        ts, track = self._pdr_track(0.0)
        if len(ts) < 2:
            raise ConfigError(f"{key}.initial.heading_deg", "no steps detected to align")
        p0, p1 = (np.array([np.interp(t, ts, track[:, c]) for c in range(2)]) for t in (t0, t1))
        d_pdr, d_gnss = p1 - p0, pos[far[0]] - pos[0]
        return float(np.arctan2(d_gnss[0], d_gnss[1]) - np.arctan2(d_pdr[0], d_pdr[1]))

    def restart(self) -> None:
        ini, f, mag = self.config.initial, self.config.filter, self.config.magnetometer
        self.x = np.array([*self._p0, self._psi0, 0.0, 0.0, 0.0, 1.0])  # E, N, U, ψ, b, βE, βN, c
        variances = [ini.position_sd_m**2, ini.position_sd_m**2, ini.height_sd_m**2,
                     np.deg2rad(ini.heading_sd_deg) ** 2, f.step_length_sd_m**2, f.gyro_bias_sd**2,
                     f.gnss_bias_sd_m**2, f.gnss_bias_sd_m**2, f.step_scale_sd**2]
        self._offset_known = mag.offset_deg != "auto"
        if mag.enabled:  # the holding offset o, rad (auto: a placeholder until the first sample)
            self.x = np.append(self.x, np.deg2rad(mag.offset_deg) if self._offset_known else 0.0)
            variances.append(np.deg2rad(mag.offset_sd_deg) ** 2)
        self.P = np.diag(variances)
        self.mag_counts = {"accepted": 0, "rejected_gate": 0, "rejected_field": 0}
        self._tc = float(self.t[0])  # time the heading and covariance are propagated to
        self._next = 0
        self.gnss_counts = {"accepted": 0, "rejected": 0, "masked": 0, "heading_accepted": 0, "heading_rejected": 0}
        self._hist: list[tuple[float, float, float, float, float, float, float]] = []
        self._record()
        self.phi = None

    # --- the filter -------------------------------------------------------------
    def _propagate_to(self, t: float) -> None:
        dt = t - self._tc
        if dt <= 0:
            return
        f = self.config.filter
        i0, i1 = (np.searchsorted(self.t, v, side="right") - 1 for v in (self._tc, t))
        self.x[3] += self._azimuth[i1] - self._azimuth[i0] - self.x[4] * dt
        F = np.eye(self.n_err)
        F[PSI, B] = -dt
        decay = np.exp(-dt / f.correlation_time_s)
        F[B, B] = decay
        beta_decay = np.exp(-dt / f.gnss_bias_time_s)
        F[BE, BE] = F[BN, BN] = beta_decay
        self.x[5:7] *= beta_decay
        Q = np.zeros(self.n_err)
        Q[PSI] = f.heading_noise_density**2 * dt
        Q[B] = f.gyro_bias_sd**2 * (1.0 - decay**2)
        Q[U] = f.height_noise_density**2 * dt
        Q[BE] = Q[BN] = f.gnss_bias_sd_m**2 * (1.0 - beta_decay**2)
        Q[C] = f.step_scale_random_walk**2 * dt
        if self._mag is not None:
            Q[O] = np.deg2rad(self.config.magnetometer.offset_random_walk) ** 2 * dt
        self._transition(F, Q)
        self._tc = t

    def _transition(self, F: np.ndarray, Q: np.ndarray) -> None:
        """P ← F P Fᵀ + Q (Q a full matrix or its diagonal); the fuser's Φ ← F Φ."""
        self.P = F @ self.P @ F.T + (np.diag(Q) if Q.ndim == 1 else Q)
        self.P = 0.5 * (self.P + self.P.T)
        if self.phi is not None:
            self.phi = F @ self.phi

    def _step(self, k: int) -> None:
        """Eq. 37 for step k, and the covariance by eqs. 38–40 with a fresh white δS."""
        s_model, psi = self.step_length_m[k], self.x[3]
        s = self.x[7] * s_model
        F = np.eye(self.n_err)
        F[E, PSI], F[E, S], F[E, C] = s * np.cos(psi), np.sin(psi), s_model * np.sin(psi)
        F[N, PSI], F[N, S], F[N, C] = -s * np.sin(psi), np.cos(psi), s_model * np.cos(psi)
        fresh = np.eye(self.n_err)
        fresh[S, S] = 0.0  # the previous step's δS does not carry over
        Q = np.zeros(self.n_err)
        Q[S] = self.config.filter.step_length_sd_m**2
        self.x[0] += s * np.sin(psi)
        self.x[1] += s * np.cos(psi)
        self._transition(F @ fresh, F @ np.diag(Q) @ F.T)

    def _update(self, H: np.ndarray, y: np.ndarray, R: np.ndarray, gate: float) -> bool:
        """Gated Kalman update (Joseph form), closed-loop reset; False if rejected."""
        S_ = H @ self.P @ H.T + R
        if float(y @ np.linalg.solve(S_, y)) > gate:
            return False
        K = self.P @ H.T @ np.linalg.inv(S_)
        dx = K @ y
        self.x += dx[self._nominal]  # δS is white: nothing to feed back
        IKH = np.eye(self.n_err) - K @ H
        self.P = IKH @ self.P @ IKH.T + K @ R @ K.T
        self.P = 0.5 * (self.P + self.P.T)
        if self.phi is not None:
            self.phi = IKH @ self.phi
        return True

    def _gnss(self, j: int) -> None:
        if self._fix_masked[j]:
            self.gnss_counts["masked"] += 1
            return
        f = self.config.filter
        H = np.zeros((3, self.n_err))
        H[0, E] = H[1, N] = H[2, U] = 1.0
        H[0, BE] = H[1, BN] = 1.0
        sd = self._fix_sd[j]
        R = np.diag([sd**2, sd**2, (2.0 * sd) ** 2])
        predicted = self.x[:3] + np.array([self.x[5], self.x[6], 0.0])
        ok = self._update(H, self._fix_pos[j] - predicted, R, self._gate_pos)
        self.gnss_counts["accepted" if ok else "rejected"] += 1
        if ok and np.isfinite(self._fix_course[j]) and self._fix_speed[j] >= f.min_speed_for_heading_mps:
            Hp = np.zeros((1, self.n_err))
            Hp[0, PSI] = 1.0
            y = np.array([wrap_angle(self._fix_course[j] - self.x[3])])
            okh = self._update(Hp, y, np.array([[np.deg2rad(f.gnss_heading_sd_deg) ** 2]]), self._gate_psi)
            self.gnss_counts["heading_accepted" if okh else "heading_rejected"] += 1

    def _magnetometer(self, k: int) -> None:
        """Heading update from the k-th decimated magnetometer sample (see the module docstring)."""
        if not self._mag.earth_like[k]:
            self.mag_counts["rejected_field"] += 1
            return
        r = np.deg2rad(self.config.magnetometer.sigma_deg) ** 2
        psi_d = self._mag.psi_d[k]
        if not self._offset_known:  # δo ← δψ + v
            F = np.eye(self.n_err)
            F[O] = 0.0
            F[O, PSI] = 1.0
            Q = np.zeros(self.n_err)
            Q[O] = r
            self.x[8] = wrap_angle(self.x[3] - psi_d)
            self._transition(F, Q)
            self._offset_known = True
            self.mag_counts["accepted"] += 1
            return
        H = np.zeros((1, self.n_err))
        H[0, PSI], H[0, O] = 1.0, -1.0
        y = np.array([wrap_angle(psi_d - (self.x[3] - self.x[8]))])
        ok = self._update(H, y, np.array([[r]]), self._gate_mag)
        self.mag_counts["accepted" if ok else "rejected_gate"] += 1

    def _record(self) -> None:
        """History row: time, position (m), position one-sigma (m)."""
        self._hist.append((self._tc, *self.x[:3], *np.sqrt(np.maximum(np.diag(self.P)[:3], 0.0))))

    # --- time -------------------------------------------------------------------
    @property
    def t_now(self) -> float:
        return self._tc

    def advance(self, t: float) -> None:
        while self._next < len(self._events) and self._events[self._next][0] <= t:
            te, kind, idx = self._events[self._next]
            self._propagate_to(te)
            if kind == STEP:
                self._step(idx)
            elif kind == GNSS:
                self._gnss(idx)
            else:
                self._magnetometer(idx)
            self._record()
            self._next += 1
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        if i >= 0:
            self._propagate_to(float(self.t[i]))  # the state refers to the last sample at or before t
        if t >= self.t_end and self._hist[-1][0] < self._tc:
            self._record()  # the trajectory covers the whole data span

    # --- heading ------------------------------------------------------------------
    @property
    def heading_is_auto(self) -> bool:
        return self.config.initial.heading_deg == "auto"

    def initial_travel_azimuth(self, distance_m: float) -> float | None:
        ts, track = self._pdr_track(self._psi0)
        far = np.flatnonzero(np.hypot(*track.T) >= distance_m)
        return None if far.size == 0 else float(np.arctan2(*track[far[0]]))

    def rotate_initial_heading(self, delta_rad: float) -> None:
        self._psi0 += delta_rad
        self.restart()

    # --- fuser interface ------------------------------------------------------------
    def position_n(self) -> np.ndarray:
        return self.x[:3].copy()

    def covariance(self) -> np.ndarray:
        return self.P.copy()

    def apply_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        changed = bool(np.any(dx)) or not np.array_equal(P, self.P)
        self.x += dx[self._nominal]
        self.P = 0.5 * (P + P.T)
        if self._hist[-1][0] == self._tc:  # corrected at an event: that record shows it
            self._hist.pop()
            self._record()
        elif changed:
            self._record()

    def track_transition(self) -> None:
        self.phi = np.eye(self.n_err)

    def transition_since_sync(self) -> np.ndarray:
        phi, self.phi = self.phi, np.eye(self.n_err)
        return phi

    def sync_times(self) -> np.ndarray:
        return self.t[self.step_index]

    def sample_times(self) -> np.ndarray:
        return self.t

    # --- results ----------------------------------------------------------------------
    def trajectory(self) -> Trajectory:
        h = np.array(self._hist)
        # several records at one time (an update right after a step): keep the last
        last = np.concatenate([h[1:, 0] > h[:-1, 0], [True]])
        h = h[last]
        return Trajectory(h[:, 0], h[:, 1:4], h[:, 4:7])

    @property
    def samples(self) -> int:
        return len(self.t)

    @property
    def input_report(self) -> InputReport:
        return self._report

    def diagnostics(self) -> dict:
        return {"steps": int(len(self.step_index)),
                "mean_step_length_m": float(self.x[7] * self.step_length_m.mean()) if len(self.step_length_m) else None,
                "step_scale": float(self.x[7]),
                "gnss": dict(self.gnss_counts),
                **({"magnetometer": {**self.mag_counts, "offset_deg": float(np.rad2deg(wrap_angle(self.x[8])))}}
                   if self._mag is not None else {})}


