"""Hand-held phone: pedestrian dead reckoning corrected by GNSS ([KFSC2015] §5).

Nominal state: position E, N, U (ENU, m), step heading ψ (azimuth of walking, rad,
clockwise from North), bias b of the levelled-gyro azimuth rate (rad/s), horizontal GNSS
error β (in units of each fix's correlated σ, first-order Gauss–Markov), step-length scale
c (1: the step model as configured) and, with the magnetometer, the holding offset o (rad, walking azimuth minus
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
GNSS (eqs. 41–44, with the correlated error): fix k of per-axis σ_k, position
z = p_gnss − (p̂ + σ_k √ρ β̂), H = [I3 0 0 0 σ_k √ρ I2], R = σ_k² (1 − ρ) horizontally
(ρ the correlated share of the variance; (2 σ_k)² vertically); δβ' = e^{−Δt/τ_β} δβ + w_β
with unit stationary variance. Phone fixes err slowly and by about what they report: on
the IPIN 2023 logs the error against the surveyed track wanders over tens of seconds
with a size that follows the reported accuracy (5–10 m at 4–8 m, 30–40 m at 50 m).
A bias in metres (σ fixed) beside white noise of σ_k lets a minute of fixes count as a
minute of independent evidence and, when the accuracy swings, is too small or too large.
Heading from the GNSS course, z = wrap(ψ_gnss − ψ̂), only from a fix taken while the PDR
detects steps with the phone held steadily, fast enough and accurate enough (a standing
phone's course is its GNSS jitter). Each update is gated by the chi-square test on its
innovation. The fixes' σ_k, the fixes skipped (in an outage, held, too fast) and the start
fix: :mod:`bodyfusion.plugins.hand_pdr.fixes`; the updates, the heading from the track's shape
and the re-anchoring of a dead reckoning that strayed from the fixes:
:mod:`bodyfusion.plugins.hand_pdr.gnss_aiding`.

Start from GNSS (``initial.position_m: gnss``): from the first usable fix that its
successor confirms (:mod:`~bodyfusion.plugins.hand_pdr.fixes`; earlier fixes are skipped).
The filter starts at the first IMU sample with a diffuse position (σ :data:`DIFFUSE_SD_M`),
so the start fix sets the position with its own σ at its own time, not a guessed σ at t0.
After ``reset_after_rejections`` consecutive gated-out fixes the position is forgotten the
same way (δp ← fresh, σ diffuse: rows of δp in the transition zeroed, diffuse Q) and taken
from the fix: a filter whose prior excludes every fix never recovers by itself.

Unknown heading (``initial.heading_deg: gnss_track``): a bank of hypotheses
(:mod:`bodyfusion.plugins.hand_pdr.hypotheses`) spread round the circle, each this filter with a
small heading σ. Only fixes and magnetometer samples taken while the phone walks, held
steadily, change their weights: standing, every hypothesis predicts the same displacement
(none), and the fixes of a standing phone are one correlated error, not independent
evidence. The bank collapses into one filter once its heading σ is small
(``heading_resolved_s``). When the phone's pose changes (:func:`~bodyfusion.plugins.hand_pdr.pdr.held_steadily`:
taken out of a pocket, raised to be read) the walking direction relative to the phone is
lost: once it is held steadily again the bank is spread round the circle anew. The filter
runs over the bank, one filter or many, and shows the fuser the mixture
(:mod:`bodyfusion.plugins.hand_pdr.bank_filter`).

Magnetometer (``magnetometer.enabled``, unset: on for a phone log with MAGN lines;
:mod:`bodyfusion.plugins.hand_pdr.magnetometer`): the device azimuth ψ_d (tilt-compensated,
declination applied) and the walking heading differ by the holding offset o, ψ = ψ_d + o;
o is a tenth error state δo (random walk), appended last. Update: z = wrap(ψ_d − (ψ̂ − ô)),
H = [0 0 0 1 0 0 0 0 0 −1], chi-square gated, after the Earth-field check (when the site's
field is given) and the quasi-static check. With a prior on o (a phone log: 0, the phone
read while walking) the magnetometer weighs the heading bank like a compass; with
``offset_deg: auto`` the first accepted sample sets ô = ψ̂ − ψ_d instead: δo ← δψ + v (the
state's row of the error transition becomes that of δψ, plus the measurement's variance),
so the fuser's cross-covariances stay exact.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.findings import Finding
from bodyfusion.base.types import InputReport
from bodyfusion.core.heading import wrap_angle
from bodyfusion.base.records import GrowingArray
from bodyfusion.core.capabilities import AbsoluteFixes, HeadingAlignment, PositionResets, TransitionTracking
from bodyfusion.core.system import LayoutContext, SensorSystem
from bodyfusion.nav.filter_health import NisRecord
from bodyfusion.plugins.hand_pdr.results import PdrResults
from bodyfusion.io.gnss import GnssFixes, read_gnss_csv, read_nmea, read_ubx
from bodyfusion.io.imu import read_imu
from bodyfusion.io.phone_log import read_getsensordata
from bodyfusion.nav.measurements import chi2_gate
from bodyfusion.plugins.hand_pdr.bank_filter import BankFilter
from bodyfusion.plugins.hand_pdr.config import HandPdrConfig
from bodyfusion.plugins.hand_pdr.fixes import PhoneFixes
from bodyfusion.plugins.hand_pdr.hypotheses import Hypothesis
from bodyfusion.plugins.hand_pdr.gnss_aiding import BIAS_LIMIT, DIFFUSE_SD_M, GnssAiding
from bodyfusion.plugins.hand_pdr.streaming import StreamingHandPdr
from bodyfusion.plugins.hand_pdr.track_heading import TrackHeading
from bodyfusion.plugins.hand_pdr.model import B, BE, BN, C, E, GNSS, MAGNETOMETER, N, O, PSI, STEADY, STEP, U, PdrModel
from bodyfusion.plugins.hand_pdr.magnetometer import (
    MagneticHeading,
    read_magnetometer_csv,
)
from bodyfusion.plugins.hand_pdr.pdr import (
    PdrInputs,
    azimuth_increments,
    detect_steps,
    held_steadily,
    step_lengths,
    up_in_body,
)

NOMINAL = [E, N, U, PSI, B, BE, BN, C]
"""Error-state indices of the nominal state's entries (E, N, U, ψ, b, βE, βN, c)."""
NO_STEP_FINDING_S = 10.0
"""A recording at least this long (s) without a detected step gets a ``no_steps`` finding."""
N_ERR = 9
"""Error states without the magnetometer; with it, the offset δo is state ``O`` (the tenth)."""


class HandPdr(StreamingHandPdr, PdrResults, GnssAiding, SensorSystem, HeadingAlignment, TransitionTracking, AbsoluteFixes, PositionResets):
    """PDR from a phone's IMU with a 9-state error Kalman filter corrected by GNSS (10 states
    with the magnetometer's holding offset), or a bank of them while the heading is unknown.

    Results: :meth:`trajectory` (one epoch per step, GNSS and magnetometer update), ``step_index``
    (IMU sample of each detected step), ``step_length_m``, ``gnss_counts`` (see
    :meth:`diagnostics`), ``mag_counts`` (accepted, rejected by the gate, by the field check,
    by the quasi-static check), ``geodetic_origin`` (lat, lon, h of the ENU frame),
    ``start_fix_s`` (time of the fix the position started from), ``heading_resolved_s`` (time
    the heading bank last collapsed; None if the heading was given, or is open at the end).
    """

    plugin_name = "hand_pdr"
    body_part = "hand"
    Config = HandPdrConfig
    data_section = "imu"

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
            if mag.enabled and log.magn is None:
                raise ConfigError(f"{key}.magnetometer.enabled", f"{config.phone_log} has no MAGN lines")
            if mag.enabled is not False and log.magn is not None:  # unset: used when the log has it
                magn = (log.magn.t, log.magn.xyz)  # GetSensorData logs µT
        else:
            d = config.imu
            stream = read_imu(d)
            report = stream.report
            self.t, acc, gyro = stream.t, stream.acc_b, stream.gyro_b
            if mag.enabled:
                magn = read_magnetometer_csv(d, mag.columns, mag.unit)
        g = config.gnss
        if g is not None and g.format in ("nmea", "ubx") and g.table is not None:
            raise ConfigError(f"{key}.gnss.format", "an in-memory GNSS table is read as format csv (its columns)")
        if g is not None and g.format != "phone_log":
            self._check_fixes_arrived()
            fixes = self._read_fixes()
        if fixes is not None and fixes.report is not report:  # a phone log's fixes share its report
            report = report.merge(fixes.report)
        self._report = report
        if fixes is not None and len(fixes) and not np.any((fixes.t >= self.t[0]) & (fixes.t <= self.t[-1])):
            report.warn(f"{name}: none of the {len(fixes)} GNSS fixes ({fixes.t[0]:.6g}–{fixes.t[-1]:.6g} s) falls "
                        f"within the IMU's time span ({self.t[0]:.6g}–{self.t[-1]:.6g} s): GNSS unused; check the "
                        "two clocks")
        self._acc_norm_median = float(np.median(np.linalg.norm(acc, axis=1)))
        derived = self._derive(self.t, acc, gyro)
        self.step_index, self.step_length_m = derived.step_index, derived.step_length_m
        self._azimuth, self._steady, up_b = derived.azimuth, derived.steady, derived.up_b
        f = config.filter
        on = magn is not None
        self.n_err = N_ERR + on
        self._nominal = NOMINAL + [O] * on
        self._angles = [3] + [8] * on  # nominal entries that are angles: ψ, o
        self._mag = MagneticHeading.of(*magn, self.t, up_b, self._azimuth, mag) if magn is not None else None
        self.geodetic_origin = context.geodetic_origin
        self._fixes: PhoneFixes | None = None
        if fixes is not None and len(fixes):
            self._fixes = self._phone_fixes(fixes)
            self.geodetic_origin = self._fixes.origin
        self._events = self._event_list()
        ini = config.initial
        self.start_fix_s: float | None = None
        self._start_fix = 0
        if ini.position_m == "gnss":
            self._check_start_fix()
            if self._fixes is None or self._fixes.confirmed < 0:
                raise ConfigError(f"{key}.initial.position_m", "no GNSS fix to start from")
            self._start_fix = self._fixes.confirmed
            self.start_fix_s = float(self._fixes.t[self._start_fix])
            self._p0 = self._fixes.pos[self._start_fix].copy()
        else:
            self._p0 = np.asarray(ini.position_m, dtype=float)
        self._psi0 = 0.0 if ini.heading_deg in ("gnss_track", "auto") else float(np.deg2rad(ini.heading_deg))
        self._gate_pos = chi2_gate(config.filter.gate_probability, 3)
        self._gate_psi = chi2_gate(config.filter.gate_probability, 1)
        self._gate_mag = chi2_gate(mag.gate_probability, 1)
        self._identity = np.eye(self.n_err)
        self._model = PdrModel(f, mag, self.n_err, ini.heading_hypotheses if ini.heading_deg == "gnss_track" else 1)
        self.restart()

    # --- set-up -----------------------------------------------------------------
    def _derive(self, t: np.ndarray, acc: np.ndarray, gyro: np.ndarray) -> PdrInputs:
        """What the filter takes from the phone's IMU samples (times ``t`` s, specific force
        ``acc`` m/s^2, rate ``gyro`` rad/s, phone frame): its steps and their lengths, the azimuth
        increments and where the phone is held steadily."""
        step, f = self.config.step, self.config.filter
        steps = detect_steps(t, acc, step, self.context.gravity_mps2)
        up_b = up_in_body(t, acc)
        return PdrInputs(steps, step_lengths(t, acc, steps, step), up_b, azimuth_increments(t, gyro, up_b),
                         held_steadily(t, up_b, f.pose_window_s, np.deg2rad(f.pose_change_deg)))

    def _read_fixes(self, first: int = 0) -> GnssFixes:
        """The fixes of the ``gnss`` section (csv: its file or in-memory table, that table's rows
        from ``first`` on; nmea; ubx)."""
        g = self.config.gnss
        if g.format == "nmea":
            return read_nmea(g.path)
        if g.format == "ubx":
            return read_ubx(g.path)
        return read_gnss_csv(g.rows_from(first) if first else g, time_column=g.time_column, lat_column=g.lat_column, lon_column=g.lon_column,
                             height_column=g.height_column, accuracy_column=g.accuracy_column,
                             speed_column=g.speed_column, course_column=g.course_column)

    def _phone_fixes(self, fixes: GnssFixes) -> PhoneFixes:
        """``fixes`` as the filter takes them (:class:`~bodyfusion.plugins.hand_pdr.fixes.PhoneFixes`),
        in the ENU frame about :attr:`geodetic_origin` (None: the start fix's)."""
        return PhoneFixes.of(fixes, self.context.outages.get(self.name, ()), self.config.filter, self.geodetic_origin,
                             self.t[self.step_index], self.step_length_m, self.walking(fixes.t),
                             self.held_steadily(fixes.t))

    def findings(self) -> list[Finding]:
        """``no_steps``: the PDR found no step in a recording of :data:`NO_STEP_FINDING_S` or more
        (it never moved: the track is the GNSS fixes', or the start point); ``gnss_reanchored``:
        each time the phone took its position afresh from a fix; a live run's departures from
        the batch run (:meth:`live_findings`)."""
        out = [Finding(
            "gnss_reanchored", "info", self.name, t, t,
            f"the phone took its position afresh from the GNSS fix at t = {t:.1f} s and moved {move:.1f} m: its "
            f"filter explained the fixes by a slow GNSS error of {bias:.1f} times the fix's correlated σ "
            f"({sd:.1f} m), more than it allows ({BIAS_LIMIT:g}).",
            "the dead reckoning strayed from the fixes (a heading or step length the fixes could not correct), or "
            "the fixes themselves carry a large slow error there (multipath, a building's shadow): the filter "
            "cannot tell the two apart and takes the fix.",
            "compare the track with the systems worn with the phone around that time; where the fixes were wrong, "
            "raise filter.gnss_correlated_fraction or the fixes' σ (filter.accuracy_to_sigma).")
            for t, move, bias, sd in self.reanchors]
        span = float(self.t[-1] - self.t[0])
        if self.step_index.size or span < NO_STEP_FINDING_S:
            return out + self.live_findings()
        g = self.context.gravity_mps2
        unit = (f" Its specific force has a median norm of {self._acc_norm_median:.3g} m/s^2 where gravity is {g:.3g}: "
                "a unit or a scale is likely wrong.") if not 0.5 * g < self._acc_norm_median < 2.0 * g else ""
        return [Finding(
            "no_steps", "warning", self.name, float(self.t[0]), float(self.t[-1]),
            f"the phone's PDR found no step in {span:.0f} s of data, so it never moved by dead reckoning: its track is "
            f"its GNSS fixes' where it has them, else its start point.{unit}",
            "the phone did not walk (on a table, in a bag), or its accelerometer is read in the wrong unit or axes, "
            "or the step detector's thresholds (step.*) miss this walker's steps.",
            "check the accelerometer's unit and axes in the phone's data section, and step.threshold_mps2."),
            *out, *self.live_findings()]

    def walking(self, t: np.ndarray) -> np.ndarray:
        """(N,) True where the PDR says the phone walks at times ``t`` (s): a step detected in
        the last ``filter.walking_window_s``."""
        step_t = self.t[self.step_index]
        if step_t.size == 0:  # no step detected: never walking
            return np.zeros(np.shape(t), dtype=bool)
        k = np.searchsorted(step_t, t, side="right") - 1
        return (k >= 0) & (np.asarray(t) - step_t[np.maximum(k, 0)] < self.config.filter.walking_window_s)

    def held_steadily(self, t: np.ndarray) -> np.ndarray:
        """(N,) True where the phone is held steadily at times ``t`` (s): its Up direction turned
        by at most ``filter.pose_change_deg`` over any ``filter.pose_window_s`` of the last
        ``filter.pose_window_s`` (:func:`~bodyfusion.plugins.hand_pdr.pdr.held_steadily`)."""
        return self._steady[np.maximum(np.searchsorted(self.t, t, side="right") - 1, 0)]

    def _event_list(self, after: float = -np.inf, until: float = np.inf) -> list[tuple[float, int, int, int]]:
        """(time, kind, index, IMU sample at or before the time) of steps, GNSS fixes,
        magnetometer updates and re-opened headings within the IMU's span, those in (``after``,
        ``until``] s only, in time order."""
        t = self.t
        lo, hi = max(after, float(t[0])), min(until, float(t[-1]))

        def within(times: np.ndarray) -> range:
            return range(*np.searchsorted(times, [lo, hi], side="right"))

        step_t = t[self.step_index]
        ev = [(float(step_t[k]), STEP, k) for k in range(*np.searchsorted(step_t, [after, until], side="right"))]
        if self._fixes is not None:
            ev += [(float(self._fixes.t[j]), GNSS, j) for j in within(self._fixes.t)]
        if self._mag is not None:
            ev += [(float(self._mag.t[k]), MAGNETOMETER, k) for k in within(self._mag.t)]
        if self.config.initial.heading_deg == "gnss_track":  # the phone held steadily again
            i0, i1 = np.searchsorted(t, [after, until], side="right")
            i0 = max(int(i0), 1)
            i1 = max(int(i1), i0)
            again = np.flatnonzero(self._steady[i0:i1] & ~self._steady[i0 - 1:i1 - 1]) + i0
            ev += [(float(t[i]), STEADY, int(i)) for i in again]
        ev.sort()
        sample = np.searchsorted(self.t, [e[0] for e in ev], side="right") - 1
        return [(te, kind, k, int(i)) for (te, kind, k), i in zip(ev, sample)]

    def _pdr_track(self, psi0: float) -> tuple[np.ndarray, np.ndarray]:
        """Step times and horizontal PDR positions (from the start, no filter) for heading psi0."""
        psi = psi0 + self._azimuth[self.step_index]
        d = np.column_stack([self.step_length_m * np.sin(psi), self.step_length_m * np.cos(psi)])
        return self.t[self.step_index], np.cumsum(d, axis=0)

    def restart(self) -> None:
        ini, f, mag = self.config.initial, self.config.filter, self.config.magnetometer
        x = np.array([*self._p0, self._psi0, 0.0, 0.0, 0.0, 1.0])  # E, N, U, ψ, b, βE, βN, c
        beta_var = float(f.gnss_correlated_fraction > 0)  # β: unit variance, or none
        sd_h, sd_u = (DIFFUSE_SD_M, DIFFUSE_SD_M) if ini.position_m == "gnss" else (ini.position_sd_m, ini.height_sd_m)
        variances = [sd_h**2, sd_h**2, sd_u**2, np.deg2rad(ini.heading_sd_deg) ** 2, f.step_length_sd_m**2,
                     f.gyro_bias_sd**2, beta_var, beta_var, f.step_scale_sd**2]
        self._offset_known = mag.offset_deg != "auto"
        if self._mag is not None:  # the holding offset o, rad (auto: a placeholder until the first sample)
            x = np.append(x, np.deg2rad(mag.offset_deg) if self._offset_known else 0.0)
            variances.append(np.deg2rad(mag.offset_sd_deg) ** 2)
        P = np.diag(variances)
        self._bank = BankFilter([Hypothesis(x, P)], self._nominal, self._angles, 3,
                                np.deg2rad(ini.heading_resolved_sd_deg))
        if ini.heading_deg == "gnss_track":
            self._bank.spread(x, P, ini.heading_hypotheses)
        self.heading_resolved_s: float | None = None
        self.heading_resolutions: list[float] = []
        self.heading_counts = {"weighted": 0, "unweighted_standing": 0, "unweighted_handling": 0, "reopened": 0}
        self.mag_counts = {"accepted": 0, "rejected_gate": 0, "rejected_field": 0, "rejected_turning": 0}
        self._tc = float(self.t[0])  # time the heading and covariance are propagated to
        self._i_tc = int(np.searchsorted(self.t, self._tc, side="right")) - 1  # its IMU sample
        self._next = 0
        self._rejected_in_row = 0
        self.gnss_counts = {"accepted": 0, "rejected": 0, "masked": 0, "held": 0, "too_fast": 0, "before_start": 0,
                            "position_resets": 0, "heading_accepted": 0, "heading_rejected": 0,
                            "heading_skipped_standing": 0, "heading_skipped_handling": 0,
                            "heading_skipped_accuracy": 0, "track_heading_accepted": 0, "track_heading_rejected": 0,
                            "reanchored": 0}
        self.reanchor_times: list[float] = []
        self.reanchors: list[tuple[float, float, float, float]] = []
        """Each re-anchoring: time (s), the horizontal move it made (m), the bias |β̂| that set it off
        (units of the fix's correlated σ) and the fix's σ (m)."""
        self._position_resets: list[tuple[float, np.ndarray]] = []
        self.nis_records = {"gnss_position": NisRecord(3), "gnss_course": NisRecord(1), "gnss_track": NisRecord(1)}
        self._track = TrackHeading(f.gnss_correlated_fraction)
        if self._mag is not None:
            self.nis_records["magnetometer"] = NisRecord(1)
        self._hist_x = GrowingArray((1 + len(self._nominal),))  # t, nominal state
        self._row = np.empty(1 + len(self._nominal))
        self._hist_P = GrowingArray((self.n_err, self.n_err))
        self._record()

    # --- the state ----------------------------------------------------------------
    @property
    def x(self) -> np.ndarray:
        """Nominal state (the mixture's mean while the heading bank is open)."""
        return self._bank.moments()[0]

    @property
    def P(self) -> np.ndarray:
        """Error-state covariance (the mixture's, moment-matched, while the bank is open)."""
        return self._bank.moments()[1]

    @property
    def heading_hypotheses(self) -> int:
        """Hypotheses of the heading bank still alive (1: one filter)."""
        return len(self._bank)

    # --- the filter -------------------------------------------------------------
    def _propagate_to(self, t: float, i: int) -> None:
        """From the current time to t (s; IMU sample i at or before it), Δt = t − t_c:
        ψ += Δψ_gyro − b Δt, β ← e^{−Δt/τ_β} β, P ← F P Fᵀ + Q (:meth:`PdrModel.time_step`)."""
        dt = t - self._tc
        if dt <= 0:
            return
        _, beta_decay = self._model.time_step(dt)
        dpsi = self._azimuth[i] - self._azimuth[self._i_tc]
        for h in self._bank:
            h.x[3] += dpsi - h.x[4] * dt
            h.x[5:7] *= beta_decay
        self._bank.transition(self._model.F_time, self._model.Q_time)
        self._tc, self._i_tc = t, i

    def _step(self, k: int) -> None:
        """Eq. 37 for step k, and the covariance by eqs. 38–40 with a fresh white δS
        (:meth:`PdrModel.step`, one F and Q per hypothesis)."""
        s_model = self.step_length_m[k]
        for i, h in enumerate(self._bank):
            psi, s = h.x[3], h.x[7] * s_model
            sin, cos = np.sin(psi), np.cos(psi)
            self._model.step(i, sin, cos, s, s_model)
            h.x[0] += s * sin
            h.x[1] += s * cos
        count = len(self._bank)
        self._bank.transition(self._model.F_step[:count], self._model.Q_step[:count])
        x = self._bank.moments(copy=False)[0]
        self._track.step(x[7] * s_model, x[3])

    def _update(self, H: np.ndarray, residual: Callable[[np.ndarray], np.ndarray], R: np.ndarray, gate: float,
                weigh: bool, kind: str | None) -> bool:
        """:meth:`BankFilter.update`; the time an open bank collapses is the heading's resolution.
        The NIS of a ``kind`` of :attr:`nis_records` is recorded while the bank is one filter."""
        was_open = len(self._bank) > 1
        ok = self._bank.update(H, residual, R, gate, weigh)
        if kind is not None and not was_open:
            self.nis_records[kind].add(self._tc, self._bank.nis[0], ok)
        if was_open and len(self._bank) == 1:
            self.heading_resolved_s = self._tc
            self.heading_resolutions.append(self._tc)
        return ok

    def _reopen_heading(self) -> None:
        """The phone is held steadily again after being handled: the walking direction relative to
        it is unknown, so the bank is spread round the circle again from the mixture's moments;
        so is the holding offset: back to its prior (δo ← fresh, σ ``offset_sd_deg``), or, if
        ``auto``, taken afresh from the next accepted sample."""
        self._track.clear()
        x, P = self._bank.moments()
        mag = self.config.magnetometer
        if self._mag is not None:
            self._offset_known = mag.offset_deg != "auto"
            x[8] = np.deg2rad(mag.offset_deg) if self._offset_known else x[8]
            P[O, :] = P[:, O] = 0.0
            P[O, O] = np.deg2rad(mag.offset_sd_deg) ** 2
        self._bank.spread(x, P, self.config.initial.heading_hypotheses)
        self.heading_resolved_s = None
        self.heading_counts["reopened"] += 1

    def _magnetometer(self, k: int) -> None:
        """Heading update from the k-th decimated magnetometer sample (see the module docstring)."""
        if not self._mag.earth_like[k]:
            self.mag_counts["rejected_field"] += 1
            return
        if not self._mag.quasi_static[k]:
            self.mag_counts["rejected_turning"] += 1
            return
        psi_d = self._mag.psi_d[k]
        if not self._offset_known:  # δo ← δψ + v
            F = np.eye(self.n_err)
            F[O] = 0.0
            F[O, PSI] = 1.0
            Q = np.zeros((self.n_err, self.n_err))
            Q[O, O] = self._model.R_mag[0, 0]
            for h in self._bank:
                h.x[8] = wrap_angle(h.x[3] - psi_d)
            self._bank.transition(F, Q)
            self._offset_known = True
            self.mag_counts["accepted"] += 1
            return
        tm = np.array([self._mag.t[k]])
        ok = self._update(self._model.H_mag, lambda x: np.array([wrap_angle(psi_d - (x[3] - x[8]))]), self._model.R_mag,
                          self._gate_mag, bool(self.walking(tm)[0] and self.held_steadily(tm)[0]), "magnetometer")
        self.mag_counts["accepted" if ok else "rejected_gate"] += 1

    def _record(self) -> None:
        """History row: time, nominal state and error-state covariance (the mixture's moments)."""
        x, P = self._bank.moments(copy=False)
        self._row[0] = self._tc
        self._row[1:] = x
        self._hist_x.append(self._row)
        self._hist_P.append(P)

    def _last_record_t(self) -> float:
        return float(self._hist_x.view()[-1, 0])

    # --- time -------------------------------------------------------------------
    @property
    def t_now(self) -> float:
        return self._tc

    def advance(self, t: float) -> None:
        while self._next < len(self._events) and self._events[self._next][0] <= t:
            te, kind, idx, i = self._events[self._next]
            self._propagate_to(te, i)
            if kind == STEP:
                self._step(idx)
            elif kind == GNSS:
                self._gnss(idx)
            elif kind == MAGNETOMETER:
                self._magnetometer(idx)
            else:
                self._reopen_heading()
            self._record()
            self._next += 1
        i = int(self.t.searchsorted(t, side="right")) - 1
        if i >= 0:
            self._propagate_to(float(self.t[i]), i)  # the state refers to the last sample at or before t
        if t >= self.t_end and self._last_record_t() < self._tc:
            self._record()  # the trajectory covers the whole data span

    # --- heading ------------------------------------------------------------------
    @property
    def heading_is_auto(self) -> bool:
        return self.config.initial.heading_deg == "auto"

    def take_position_resets(self) -> list[tuple[float, np.ndarray]]:
        """The position resets to a GNSS fix since the last call: time (s), move (3,) ENU m
        (:class:`~bodyfusion.core.capabilities.PositionResets`)."""
        out, self._position_resets = self._position_resets, []
        return out

    def absolute_fixes(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Every GNSS fix outside the layout's outages (the phone's GNSS alone)."""
        if self._fixes is None:
            return None
        use = ~self._fixes.masked
        return (self._fixes.t[use], self._fixes.pos[use]) if use.any() else None

    @property
    def heading_is_absolute(self) -> bool:
        """A phone with GNSS fixes or a magnetometer knows its heading in the geographic frame."""
        return self._fixes is not None or self._mag is not None

    def yaw_error_row(self) -> np.ndarray:
        """−δψ: ψ is an azimuth (clockwise), the row wants the rotation about Up (counter-clockwise)."""
        row = np.zeros(self.n_err)
        row[3] = -1.0
        return row

    def initial_travel_azimuth(self, distance_m: float) -> float | None:
        """As :meth:`SensorSystem.initial_travel_azimuth`. A heading unknown at the start
        (``gnss_track``) is acquired from the fixes: the azimuth is then that of the phone's own
        GNSS-aided track, the whole run filtered once (and restarted)."""
        if self.config.initial.heading_deg == "gnss_track":
            self.advance(self.t_end)
            track = self.trajectory()
            self.restart()
            path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(track.pos_n[:, :2], axis=0).T))])
            far = np.flatnonzero(path >= distance_m)
            if far.size == 0:
                return None
            d = track.pos_n[far[0], :2] - track.pos_n[0, :2]
            return float(np.arctan2(d[0], d[1]))
        ts, track = self._pdr_track(self._psi0)
        far = np.flatnonzero(np.hypot(*track.T) >= distance_m)
        return None if far.size == 0 else float(np.arctan2(*track[far[0]]))

    def rotate_initial_heading(self, delta_rad: float) -> None:
        self._psi0 += delta_rad
        self.restart()

    # --- fuser interface ------------------------------------------------------------
    def position_n(self) -> np.ndarray:
        return self._bank.moments(copy=False)[0][:3].copy()

    def covariance(self) -> np.ndarray:
        return self._bank.moments(copy=False)[1].copy()

    def apply_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        """Closed-loop reset of one filter or of every hypothesis (:meth:`BankFilter.correct`)."""
        changed = self._bank.correct(dx, P)
        if self._last_record_t() == self._tc:  # corrected at an event: that record shows it
            self._hist_x.pop()
            self._hist_P.pop()
            self._record()
        elif changed:
            self._record()

    def track_transition(self) -> None:
        self._bank.phi = self._identity.copy()

    def transition_since_sync(self) -> np.ndarray:
        phi, self._bank.phi = self._bank.phi, self._identity.copy()
        return phi

    def sync_times(self) -> np.ndarray:
        return self.t[self.step_index]

    def sample_times(self) -> np.ndarray:
        return self.t
