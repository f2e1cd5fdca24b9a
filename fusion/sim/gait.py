"""The walking pedestrian: both feet along a body path, stance and swing.

Timing. One gait cycle of a foot lasts ``T`` = 2 / cadence (cadence counts steps of
either foot) with ``stance_fraction`` of it flat and still; or, for the "pulse" profile
of the FB-RTS paper's simulation, ``swing_s`` + ``stance_s``. The other foot runs half a
cycle later. Every swing starts and ends ON an IMU sample instant (the cycle, the swing
and the half-cycle offset are rounded to whole samples, each at most half a sample off
the configured value, so stance at most one sample off), so an IMU sample's
interval never straddles a swing/stance boundary and the stance label of a sample is
unambiguous: ``stance[k]`` ⇔ the foot is still at ``t_k`` (both ends of a swing included,
where velocity and angular rate are exactly zero).

Geometry. The walk starts and ends with both feet side by side, still for
``start_still_s`` / ``end_still_s``. Footprints lie on the body path at multiples of the
step length (stride/2, adjusted so a whole number of steps fits the path), offset
``lateral_offset_m`` to the left/right, heading along the path there. The first step of
``first_foot`` and the last step of the trailing foot are half strides.

Swing, with ``τ`` = elapsed fraction of the swing:

* horizontal position on the straight line between the two footprints, fraction
  ``u(τ) = 35τ⁴ − 84τ⁵ + 70τ⁶ − 20τ⁷`` (7th order: velocity, acceleration and jerk
  are zero at both ends);
* height ``lift_m · 256 τ⁴(1−τ)⁴``;
* toe angle (positive toe-up) ``−pitch_amplitude · K (1−2τ) τ⁴(1−τ)⁴``, normalised to
  peak at ±amplitude: toe-down after toe-off (τ = 1/3), toe-up before heel strike
  (τ = 2/3), zero with zero rate at both ends;
* azimuth ``az0 + u(τ)(az1 − az0)`` (unwrapped path headings).

Foot frame: x forward (toe), y left, z up when flat. Attitude
``q_nb = q_z(π/2 − az) ⊗ q_y(−toe) ⊗ q_z(−mount_yaw)``: the optional mounting yaw turns
the IMU on the foot clockwise (seen from above) by ``mount_yaw``, so the IMU's x axis
points at azimuth ``az + mount_yaw`` while the foot is flat. The IMU sits at the
foot's rotation centre, and its position is the truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.polynomial import Polynomial
from pydantic import Field, model_validator

from fusion.config import StrictModel
from fusion.errors import ConfigError
from fusion.sim.imu import MotionState, quat_multiply
from fusion.sim.paths import BodyPath, left_normal

__all__ = ["FootMotion", "FootTrack", "GaitConfig", "GaitPlan", "StanceDrift", "StanceNoiseConfig", "plan_gait",
           "stance_drift"]

Foot = Literal["left", "right"]


class GaitConfig(StrictModel):
    """The scenario's ``gait`` section (defaults: an ordinary walk at ≈ 1.26 m/s).

    Give ``swing_s`` and ``stance_s`` together to set the cycle directly (they replace
    ``cadence_steps_per_min`` and ``stance_fraction``), e.g. the FB-RTS paper's pulse
    profile: ``{swing_s: 1, stance_s: 1, lift_m: 0, pitch_amplitude_deg: 0}``.
    """

    stride_m: float = Field(default=1.4, gt=0)
    cadence_steps_per_min: float = Field(default=108.0, gt=0)
    stance_fraction: float = Field(default=0.6, gt=0, lt=1)
    swing_s: float | None = Field(default=None, gt=0)
    stance_s: float | None = Field(default=None, gt=0)
    lift_m: float = Field(default=0.1, ge=0)
    pitch_amplitude_deg: float = Field(default=30.0, ge=0, lt=90)
    lateral_offset_m: float = Field(default=0.1, ge=0)
    start_still_s: float = Field(default=3.0, gt=0)
    end_still_s: float = Field(default=2.0, ge=0)
    first_foot: Foot = "left"

    @model_validator(mode="after")
    def _cycle(self) -> "GaitConfig":
        if (self.swing_s is None) != (self.stance_s is None):
            raise ValueError("give swing_s and stance_s together (or neither, to use cadence and stance_fraction)")
        return self

    def cycle_s(self) -> tuple[float, float]:
        """(gait cycle of one foot, swing duration) in seconds."""
        if self.swing_s is not None and self.stance_s is not None:
            return self.swing_s + self.stance_s, self.swing_s
        cycle = 2.0 * 60.0 / self.cadence_steps_per_min
        return cycle, cycle * (1.0 - self.stance_fraction)


# Swing profiles in τ ∈ [0, 1].
_ALONG = Polynomial([0, 0, 0, 0, 35, -84, 70, -20])
_BUMP4 = Polynomial([0, 1]) ** 4 * Polynomial([1, -1]) ** 4  # τ⁴(1−τ)⁴
_LIFT = 256.0 * _BUMP4
_TOE = -(19683.0 / 16.0) * Polynomial([1, -2]) * _BUMP4  # peaks −1 at τ = 1/3, +1 at τ = 2/3
_PROFILES = {name: (p, p.deriv(1), p.deriv(2)) for name, p in {"along": _ALONG, "lift": _LIFT, "toe": _TOE}.items()}


def _quat_z(angle: np.ndarray) -> np.ndarray:
    a = 0.5 * np.asarray(angle, dtype=float)
    z = np.zeros_like(a)
    return np.stack([np.cos(a), z, z, np.sin(a)], axis=-1)


def _quat_y(angle: np.ndarray) -> np.ndarray:
    a = 0.5 * np.asarray(angle, dtype=float)
    z = np.zeros_like(a)
    return np.stack([np.cos(a), z, np.sin(a), z], axis=-1)


@dataclass
class FootMotion:
    """One foot's analytic motion: footprints and the swings between them.

    footprints: (M+1, 3) ENU m, footprint_az: (M+1,) rad; swing j goes from footprint j
    to j+1 over samples ``k_start[j]`` … ``k_end[j]`` of the ``rate_hz`` grid.
    """

    foot: Foot
    rate_hz: float
    footprints: np.ndarray
    footprint_az: np.ndarray
    k_start: np.ndarray
    k_end: np.ndarray
    lift_m: float
    toe_amplitude_rad: float
    mount_yaw_rad: float = 0.0

    def mounted(self, mount_yaw_deg: float) -> "FootMotion":
        """The same foot carrying an IMU turned by ``mount_yaw_deg`` (clockwise from above)."""
        return FootMotion(self.foot, self.rate_hz, self.footprints, self.footprint_az, self.k_start,
                          self.k_end, self.lift_m, self.toe_amplitude_rad, math.radians(mount_yaw_deg))

    @property
    def t_start(self) -> np.ndarray:
        return self.k_start / self.rate_hz

    @property
    def t_end(self) -> np.ndarray:
        return self.k_end / self.rate_hz

    def stance_flags(self, n_samples: int) -> np.ndarray:
        """(n_samples,) bool: foot still at sample k (swing ends included)."""
        moving = np.zeros(n_samples + 1, dtype=np.int64)
        np.add.at(moving, np.minimum(self.k_start + 1, n_samples), 1)
        np.add.at(moving, np.minimum(self.k_end, n_samples), -1)
        return np.cumsum(moving[:n_samples]) == 0

    def evaluate(self, t: np.ndarray) -> MotionState:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        ts, te = self.t_start, self.t_end
        j = np.searchsorted(ts, t, side="left") - 1  # last swing that started strictly before t
        swing = (j >= 0) & (t < te[np.maximum(j, 0)])
        fp = j + 1  # footprint the foot stands on when not swinging
        pos = self.footprints[fp].copy()
        az = self.footprint_az[fp].copy()
        vel = np.zeros_like(pos)
        acc = np.zeros_like(pos)
        daz = np.zeros_like(az)
        toe = np.zeros_like(az)
        dtoe = np.zeros_like(az)
        if swing.any():
            js = j[swing]
            dur = te[js] - ts[js]
            tau = (t[swing] - ts[js]) / dur
            p0, p1 = self.footprints[js], self.footprints[js + 1]
            a0, a1 = self.footprint_az[js], self.footprint_az[js + 1]
            u, du, ddu = (f(tau) for f in _PROFILES["along"])
            h, dh, ddh = (self.lift_m * f(tau) for f in _PROFILES["lift"])
            step = p1 - p0
            pos[swing] = p0 + u[:, None] * step
            pos[swing, 2] += h
            vel[swing] = (du / dur)[:, None] * step
            vel[swing, 2] += dh / dur
            acc[swing] = (ddu / dur**2)[:, None] * step
            acc[swing, 2] += ddh / dur**2
            az[swing] = a0 + u * (a1 - a0)
            daz[swing] = du / dur * (a1 - a0)
            toe_p, dtoe_p, _ = _PROFILES["toe"]
            toe[swing] = self.toe_amplitude_rad * toe_p(tau)
            dtoe[swing] = self.toe_amplitude_rad * dtoe_p(tau) / dur
        yaw = 0.5 * np.pi - az  # ENU yaw, counter-clockwise from East
        q = quat_multiply(_quat_z(yaw), _quat_y(-toe))
        if self.mount_yaw_rad:
            q = quat_multiply(q, _quat_z(np.full_like(yaw, -self.mount_yaw_rad)))
        # ω_n = yaw rate about Up + (−toe rate) about the yawed y axis [−sin yaw, cos yaw, 0].
        omega = np.stack([dtoe * np.sin(yaw), -dtoe * np.cos(yaw), -daz], axis=-1)
        return MotionState(pos=pos, vel=vel, acc=acc, q_nb=q, omega_n=omega)


class StanceNoiseConfig(StrictModel):
    """A foot that is not perfectly still in stance (the coloured measurement noise of the
    MDC-cKF and DC-EnEKF papers): inside each stance run its velocity (ENU, every axis)
    follows v_k = colour_factor · v_{k−1} + ξ_k, ξ_k ~ N(0, sigma_mps²), zero at both ends
    of the run (heel strike and toe-off) and in swing (:func:`stance_drift`)."""

    colour_factor: float = Field(default=0.9, ge=0, lt=1)
    sigma_mps: float = Field(default=0.005, ge=0)


@dataclass
class StanceDrift:
    """A foot motion plus a small drift during stance, consistent in position, velocity and
    acceleration, so the IMU synthesised from it and the truth both follow the moved foot.

    The drift velocity is ``vel`` (N, 3) m/s at the sample instants and linear in between
    (acceleration constant on each sample interval, so the IMU's interval means are exact);
    its displacement ``disp`` (N, 3) m is the integral, carried into the swing that follows.
    """

    base: FootMotion
    rate_hz: float
    vel: np.ndarray
    disp: np.ndarray

    @property
    def footprint_az(self) -> np.ndarray:
        return self.base.footprint_az

    def stance_flags(self, n_samples: int) -> np.ndarray:
        """The base motion's stance flags (the drift keeps the foot on the ground)."""
        return self.base.stance_flags(n_samples)

    def evaluate(self, t: np.ndarray) -> MotionState:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        state = self.base.evaluate(t)
        n = self.vel.shape[0]
        dt = 1.0 / self.rate_hz
        k = np.clip(np.ceil(t * self.rate_hz - 1e-9).astype(np.int64), 1, n - 1)  # t in (t_{k−1}, t_k]
        u = np.clip(t - (k - 1) * dt, 0.0, dt)[:, None]
        c0, c1 = self.vel[k - 1], self.vel[k]
        a = (c1 - c0) / dt
        state.acc = state.acc + a
        state.vel = state.vel + c0 + a * u
        state.pos = state.pos + self.disp[k - 1] + c0 * u + 0.5 * a * u * u
        return state


def stance_drift(motion: FootMotion, n_samples: int, cfg: StanceNoiseConfig,
                 rng: np.random.Generator) -> StanceDrift:
    """``motion`` with the AR(1) stance velocity of ``cfg`` on its first ``n_samples`` samples
    (draws from ``rng``; see :class:`StanceNoiseConfig`)."""
    stance = motion.stance_flags(n_samples)
    inner = np.zeros(n_samples, dtype=bool)
    inner[1:-1] = stance[:-2] & stance[1:-1] & stance[2:]
    xi = cfg.sigma_mps * rng.standard_normal((n_samples, 3))
    vel = np.zeros((n_samples, 3))
    for k in np.flatnonzero(inner):
        vel[k] = cfg.colour_factor * vel[k - 1] + xi[k]
    disp = np.zeros((n_samples, 3))
    disp[1:] = np.cumsum(0.5 * (vel[1:] + vel[:-1]) / motion.rate_hz, axis=0)
    return StanceDrift(motion, motion.rate_hz, vel, disp)


@dataclass
class FootTrack:
    """One foot (or the IMU on it) sampled on the IMU grid: t (N,) s, pos (N, 3) ENU m,
    q_nb (N, 4) scalar-first, stance (N,) bool."""

    t: np.ndarray
    pos: np.ndarray
    q_nb: np.ndarray
    stance: np.ndarray


@dataclass
class GaitPlan:
    """Both feet on one time grid ``t = k / rate_hz``, k = 0 … n_samples−1."""

    rate_hz: float
    n_samples: int
    feet: dict[str, FootMotion]
    path: BodyPath
    step_m: float
    n_start_still: int

    @property
    def start_still_s(self) -> float:
        """Both feet stand still on [0, start_still_s] (rounded to the sample grid)."""
        return self.n_start_still / self.rate_hz

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.n_samples) / self.rate_hz

    def track(self, foot: Foot, mount_yaw_deg: float = 0.0) -> FootTrack:
        """``foot``'s IMU (turned by ``mount_yaw_deg``) at every sample instant."""
        motion = self.feet[foot].mounted(mount_yaw_deg)
        t = self.t
        state = motion.evaluate(t)
        return FootTrack(t, state.pos, state.q_nb, motion.stance_flags(t.size))

    @property
    def distance_m(self) -> float:
        """Distance walked along the body path."""
        return self.path.length


def plan_gait(path: BodyPath, gait: GaitConfig, rate_hz: float, key: str = "gait") -> GaitPlan:
    """Footprints and swing times of both feet for walking ``path`` (see the module docstring)."""
    cycle, swing = gait.cycle_s()
    n_cycle = int(round(cycle * rate_hz))
    n_swing = int(round(swing * rate_hz))
    n_half = n_cycle // 2
    if n_swing < 4 or n_cycle - n_swing < 1:
        raise ConfigError(key, f"a swing of {swing:.3g} s in a {cycle:.3g} s cycle is too short "
                               f"to sample at {rate_hz:g} Hz")
    n0 = int(round(gait.start_still_s * rate_hz))
    if n0 < 1:
        raise ConfigError(f"{key}.start_still_s", f"shorter than one sample at {rate_hz:g} Hz")
    n_steps = max(1, int(round(path.length / (0.5 * gait.stride_m))))
    step = path.length / n_steps

    side = {"left": 1.0, "right": -1.0}
    lead: Foot = gait.first_foot
    trail: Foot = "right" if lead == "left" else "left"
    targets: dict[str, list[float]] = {lead: [0.0], trail: [0.0]}
    starts: dict[str, list[int]] = {lead: [], trail: []}
    for i in range(1, n_steps + 2):  # event i moves foot (lead if i odd) to min(i, n)·step
        foot = lead if i % 2 else trail
        j = (i - 1) // 2
        starts[foot].append(n0 + j * n_cycle + (0 if i % 2 else n_half))
        targets[foot].append(min(i, n_steps) * step)

    feet: dict[str, FootMotion] = {}
    last = 0
    for foot in (lead, trail):
        s = np.asarray(targets[foot])
        xy, az = path.at(s)
        xy = xy + side[foot] * gait.lateral_offset_m * left_normal(az)
        footprints = np.column_stack([xy, np.zeros(len(s))])
        k_start = np.asarray(starts[foot], dtype=np.int64)
        k_end = k_start + n_swing
        last = max(last, int(k_end[-1]))
        feet[foot] = FootMotion(foot, float(rate_hz), footprints, az, k_start, k_end,
                                gait.lift_m, math.radians(gait.pitch_amplitude_deg))
    n_samples = last + int(round(gait.end_still_s * rate_hz)) + 1
    return GaitPlan(float(rate_hz), n_samples, {"left": feet["left"], "right": feet["right"]}, path, step, n0)
