"""The phone filter's model matrices, filled in place in buffers made once per system.

Error state (see :mod:`bodyfusion.plugins.hand_pdr.system`, whose docstring gives the
equations): [δE, δN, δU, δψ, δS, δb, δβE, δβN, δc] and, with the magnetometer, δo. The
constant terms (noise densities squared, decay rates, the fixed entries of F and H) are
computed once from the configuration; per call only the entries that change are written,
so a time step, a step or a fix allocates no matrix.
"""

from __future__ import annotations

import numpy as np

from bodyfusion.plugins.hand_pdr.config import MagnetometerConfig, PdrFilterConfig

E, N, U, PSI, S, B, BE, BN, C, O = range(10)
STEP, GNSS, MAGNETOMETER, STEADY = range(4)
"""The filter's event kinds, in the order they are processed at one time: a step, a GNSS fix, a
magnetometer sample, the phone held steadily again (the heading re-opened)."""
"""Error-state indices (O, the holding offset δo, only with the magnetometer)."""


class PdrModel:
    """F and Q of a time step (``F_time``, ``Q_time``) and of a step (``F_step``, ``Q_step``,
    (count, n, n): one per hypothesis of the heading bank); H and R of a GNSS position fix
    (``H_pos``, ``R_pos``), of a GNSS course (``H_psi``, ``R_psi``) and of a magnetometer
    sample (``H_mag``, ``R_mag``), for ``n_err`` error states and banks of up to ``count``."""

    def __init__(self, f: PdrFilterConfig, mag: MagnetometerConfig, n_err: int, count: int) -> None:
        self.magnetometer = n_err > O
        self._neg_rates = -1.0 / np.array([f.correlation_time_s, f.gnss_bias_time_s])  # bias, β decay rates
        self._q_psi = f.heading_noise_density**2  # rad²/s
        self._q_bias = f.gyro_bias_sd**2  # (rad/s)²
        self._q_up = f.height_noise_density**2  # m²/s
        self._q_beta = float(f.gnss_correlated_fraction > 0)  # β of unit variance, or none
        self._q_scale = f.step_scale_random_walk**2  # 1/s
        self._q_offset = np.deg2rad(mag.offset_random_walk) ** 2  # rad²/s
        self._q_step = f.step_length_sd_m**2  # m²
        self._rho = f.gnss_correlated_fraction
        self._sqrt_rho = np.sqrt(f.gnss_correlated_fraction)
        self.F_time, self.Q_time = np.eye(n_err), np.zeros((n_err, n_err))
        self.F_step = np.repeat(np.eye(n_err)[None], count, axis=0)
        self.F_step[:, S, S] = 0.0  # the previous step's δS does not carry over
        self.Q_step = np.zeros((count, n_err, n_err))
        self._step_block = np.ix_([E, N, S], [E, N, S])
        self.H_pos, self.R_pos = np.zeros((3, n_err)), np.zeros((3, 3))
        self.H_pos[0, E] = self.H_pos[1, N] = self.H_pos[2, U] = 1.0
        self.H_psi = np.zeros((1, n_err))
        self.H_psi[0, PSI] = 1.0
        self.R_psi = np.array([[np.deg2rad(f.gnss_heading_sd_deg) ** 2]])
        self.H_mag = np.zeros((1, n_err))
        if self.magnetometer:
            self.H_mag[0, PSI], self.H_mag[0, O] = 1.0, -1.0
        self.R_mag = np.array([[np.deg2rad(mag.sigma_deg) ** 2]])

    def time_step(self, dt: float) -> tuple[float, float]:
        """F_time, Q_time of a time step of ``dt`` (s): F = I but F[ψ, b] = −Δt, F[b, b] = e^{−Δt/τ},
        F[β, β] = e^{−Δt/τ_β}; Q diagonal: q_ψ Δt, σ_b² (1 − e^{−2Δt/τ}), q_U Δt, (1 − e^{−2Δt/τ_β})
        for β, q_c Δt, q_o Δt. Returns the decays (e^{−Δt/τ}, e^{−Δt/τ_β})."""
        decay, beta_decay = np.exp(dt * self._neg_rates)
        F, Q = self.F_time, self.Q_time
        F[PSI, B] = -dt
        F[B, B] = decay
        F[BE, BE] = F[BN, BN] = beta_decay
        Q[PSI, PSI] = self._q_psi * dt
        Q[B, B] = self._q_bias * (1.0 - decay**2)
        Q[U, U] = self._q_up * dt
        Q[BE, BE] = Q[BN, BN] = self._q_beta * (1.0 - beta_decay**2)
        Q[C, C] = self._q_scale * dt
        if self.magnetometer:
            Q[O, O] = self._q_offset * dt
        return decay, beta_decay

    def step(self, i: int, sin: float, cos: float, s: float, s_model: float) -> None:
        """F_step[i], Q_step[i] of a step of modelled length ``s_model`` (m), scaled length ``s``
        (m) at heading ψ (its ``sin``, ``cos``), eqs. 38–40: F = I with F[S, S] = 0 and
        F[E, ψ] = S cos ψ, F[E, c] = s sin ψ, F[N, ψ] = −S sin ψ, F[N, c] = s cos ψ;
        Q = σ_S² f fᵀ, f = (sin ψ, cos ψ, 1) at (E, N, S)."""
        F = self.F_step[i]
        F[E, PSI], F[E, C] = s * cos, s_model * sin
        F[N, PSI], F[N, C] = -s * sin, s_model * cos
        f = np.array([sin, cos, 1.0])
        self.Q_step[i][self._step_block] = np.multiply.outer(f * self._q_step, f)

    def gnss_position(self, sd: float) -> None:
        """H_pos, R_pos of a fix of per-axis σ ``sd`` (m): H[0, βE] = H[1, βN] = σ √ρ,
        R = diag(σ² (1 − ρ), σ² (1 − ρ), (2σ)²)."""
        self.H_pos[0, BE] = self.H_pos[1, BN] = sd * self._sqrt_rho
        self.R_pos[0, 0] = self.R_pos[1, 1] = sd**2 * (1.0 - self._rho)
        self.R_pos[2, 2] = (2.0 * sd) ** 2
