"""Barometric altimeter: height from pressure in a 4-state closed-loop error filter.

Nominal state (4,): East, North, Up (m, ENU) and the pressure bias b (Pa). Error
state δx = [δE, δN, δU, δb], true minus estimated; ``position_indices`` = 0:3.

* Measurement at each sample: z = p̃ = p_ISA(U) + b + v, v ~ N(0, σ_p²), linearised as
  H = [0, 0, ∂p/∂h(U), 1] (:mod:`bodyfusion_barometer.atmosphere`).
* Propagation: every state is a random walk, F = I, Q = diag(q_EN, q_EN, q_U, q_b)·dt.
* East/North: the barometer cannot observe them. They stay at ``initial.position_m``
  with a large variance (``horizontal_sd_m``, growing with ``horizontal_random_walk``)
  and no correlation with Up, so the fuser's constraints may move them freely while the
  other systems keep theirs; only Up carries information.
* After every update the estimate is added to the nominal state (closed loop), so
  ``apply_correction`` simply adds dx.

The per-sample loop is plain NumPy: a pressure log is small. A plugin with a fast IMU
should compile its loop (see the built-in ``foot_ins`` and its numba kernel).
"""

from __future__ import annotations

import numpy as np

from bodyfusion.base.errors import ConfigError, InputError
from bodyfusion.core.capabilities import TransitionTracking
from bodyfusion.core.system import JacobianCase, LayoutContext, SensorSystem
from bodyfusion.base.types import InputReport, Trajectory
from bodyfusion_barometer import atmosphere
from bodyfusion_barometer.config import BarometerConfig

N_STATES = 4
UP, BIAS = 2, 3


def read_pressure_csv(cfg, key: str) -> tuple[np.ndarray, np.ndarray, InputReport]:
    """Times (s) and pressures (Pa) from the CSV; rows whose time does not increase are
    dropped (policy ``drop``, counted in the report)."""
    path = cfg.path
    try:
        header = path.read_text().splitlines()[0].split(cfg.delimiter)
    except FileNotFoundError:
        raise ConfigError(f"{key}.path", f"file not found: {path}") from None
    except IndexError:
        raise InputError(path, "empty file") from None
    header = [h.strip() for h in header]
    for col in ("time_column", "pressure_column"):
        if getattr(cfg, col) not in header:
            raise ConfigError(f"{key}.{col}", f"no column {getattr(cfg, col)!r} in {path.name} (have {header})")
    try:
        table = np.loadtxt(path, delimiter=cfg.delimiter, skiprows=1, ndmin=2)
    except ValueError as err:
        raise InputError(path, f"not a numeric CSV: {err}") from None
    t = table[:, header.index(cfg.time_column)] * cfg.time_scale
    p = table[:, header.index(cfg.pressure_column)] * (100.0 if cfg.pressure_unit == "hPa" else 1.0)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p)) and np.all(p > 0)):
        raise InputError(path, "non-finite time or non-positive pressure")
    keep = np.ones(t.size, dtype=bool)
    last = -np.inf
    for i, ti in enumerate(t):  # drop every row not after the last kept one
        keep[i] = ti > last
        last = max(last, ti)
    report = InputReport(dropped_samples=int((~keep).sum()))
    if report.dropped_samples:
        report.notes.append(f"{path.name}: dropped {report.dropped_samples} rows with non-increasing time")
    if keep.sum() < 2:
        raise InputError(path, "fewer than 2 samples")
    return t[keep], p[keep], report


class Barometer(SensorSystem, TransitionTracking):
    """Barometric altimeter (see the module docstring). Deterministic: no random numbers."""

    plugin_name = "barometer"
    Config = BarometerConfig

    def __init__(self, name: str, config: BarometerConfig, context: LayoutContext) -> None:
        super().__init__(name, config, context)
        key = f"systems.{name}"
        self.t, self.pressure_pa, self._report = read_pressure_csv(config.data, f"{key}.data")
        ini = config.initial
        if ini.reference_pressure_pa is not None:
            self.p_ref = float(ini.reference_pressure_pa)
        else:
            window = self.t - self.t[0] <= ini.reference_window_s
            if window.sum() < 1:
                raise ConfigError(f"{key}.initial.reference_window_s", "window holds no sample")
            self.p_ref = float(self.pressure_pa[window].mean())
        self.t_ref = ini.reference_temperature_k
        self.h_ref = ini.position_m[2]
        f = config.filter
        self._q = np.array([f.horizontal_random_walk**2] * 2 + [f.height_random_walk**2, f.bias_random_walk**2])
        self._r = f.pressure_sigma_pa**2
        self._tracking = False
        self.restart()

    # --- state --------------------------------------------------------------------
    def restart(self) -> None:
        """Back to the initial state at the first sample; history cleared."""
        ini = self.config.initial
        n = self.t.size
        self.x = np.array([*ini.position_m, 0.0])
        self.P = np.diag([ini.horizontal_sd_m**2] * 2 + [ini.height_sd_m**2, ini.bias_sd_pa**2])
        self.hist_x = np.empty((n, N_STATES))
        self.hist_var = np.empty((n, N_STATES))
        self.hist_x[0] = self.x
        self.hist_var[0] = np.diag(self.P)
        self.phi = np.eye(N_STATES)
        self.nis_sum = 0.0
        self._i = 0

    def predicted_pressure(self, x: np.ndarray) -> float:
        """Measurement model h(x) = p_ISA(U) + b (Pa)."""
        return float(atmosphere.pressure_at(x[UP], self.p_ref, self.t_ref, self.h_ref) + x[BIAS])

    def measurement_jacobian(self, x: np.ndarray) -> np.ndarray:
        """H (4,) = ∂h/∂x: ∂p/∂U and 1 for the bias."""
        return np.array([0.0, 0.0, float(atmosphere.dpressure_dheight(x[UP], self.p_ref, self.t_ref, self.h_ref)), 1.0])

    def _run_to(self, i1: int) -> None:
        """Process samples self._i+1 … i1−1: propagate, update with the pressure, reset."""
        eye = np.eye(N_STATES)
        for i in range(self._i + 1, i1):
            dt = self.t[i] - self.t[i - 1]
            self.P[np.diag_indices(N_STATES)] += self._q * dt  # F = I
            H = self.measurement_jacobian(self.x)
            y = self.pressure_pa[i] - self.predicted_pressure(self.x)
            PH = self.P @ H
            S = H @ PH + self._r
            K = PH / S
            A = eye - np.outer(K, H)
            self.P = A @ self.P @ A.T + self._r * np.outer(K, K)
            self.P = 0.5 * (self.P + self.P.T)
            self.x = self.x + K * y  # closed loop: the error estimate goes into the nominal state
            if self._tracking:
                self.phi = A @ self.phi
            self.nis_sum += y * y / S
            self.hist_x[i] = self.x
            self.hist_var[i] = np.diag(self.P)
        self._i = max(self._i, i1 - 1)

    # --- time ---------------------------------------------------------------------
    @property
    def t_start(self) -> float:
        return float(self.t[0])

    @property
    def t_end(self) -> float:
        return float(self.t[-1])

    @property
    def t_now(self) -> float:
        return float(self.t[self._i])

    def advance(self, t: float) -> None:
        self._run_to(int(np.searchsorted(self.t, t, side="right")))

    # --- fuser interface --------------------------------------------------------------
    def position_n(self) -> np.ndarray:
        return self.x[0:3].copy()

    def covariance(self) -> np.ndarray:
        return self.P.copy()

    def apply_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        self.x = self.x + np.asarray(dx, dtype=float)
        self.P = 0.5 * (P + P.T)
        self.hist_x[self._i] = self.x
        self.hist_var[self._i] = np.diag(self.P)

    def track_transition(self) -> None:
        self._tracking = True
        self.phi = np.eye(N_STATES)

    def transition_since_sync(self) -> np.ndarray:
        phi, self.phi = self.phi, np.eye(N_STATES)
        return phi

    def sync_times(self) -> np.ndarray:
        return np.empty(0)  # no events of its own: it is corrected at the others' epochs

    def sample_times(self) -> np.ndarray:
        return self.t

    # --- analytic Jacobians, checked by bodyfusion.testing ------------------------------------
    def jacobian_cases(self) -> list[JacobianCase]:
        """The measurement Jacobian H at a few heights, and ∂h/∂p of the inverse model."""
        cases = []
        for up in (self.h_ref, self.h_ref + 3.0, self.h_ref - 20.0, self.h_ref + 400.0):
            x = np.array([10.0, -5.0, up, 1.5])
            cases.append(JacobianCase(f"measurement H at U={up:g} m", func=lambda v: np.array([self.predicted_pressure(v)]),
                                      x=x, jacobian=self.measurement_jacobian(x)[None, :], step=1e-3))
        p = np.array([self.p_ref * 0.97])
        cases.append(JacobianCase(
            "height_at ∂h/∂p", func=lambda v: np.atleast_1d(atmosphere.height_at(v[0], self.p_ref, self.t_ref)),
            x=p, jacobian=np.atleast_2d(atmosphere.dheight_dpressure(p[0], self.p_ref, self.t_ref)), step=1e-2))
        return cases

    # --- results ----------------------------------------------------------------------------
    def trajectory(self) -> Trajectory:
        n = self._i + 1
        return Trajectory(self.t[:n], self.hist_x[:n, 0:3], np.sqrt(np.maximum(self.hist_var[:n, 0:3], 0.0)))

    def bias_pa(self) -> np.ndarray:
        """History of the estimated pressure bias (Pa)."""
        return self.hist_x[: self._i + 1, BIAS]

    @property
    def samples(self) -> int:
        return int(self.t.size)

    @property
    def input_report(self) -> InputReport:
        return self._report

    def diagnostics(self) -> dict:
        updates = self._i
        return {"reference_pressure_pa": self.p_ref, "pressure_bias_pa": float(self.x[BIAS]),
                "mean_nis": float(self.nis_sum / updates) if updates else None}
