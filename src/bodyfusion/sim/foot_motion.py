"""One foot's motion: swing, heel-to-toe roll and impact in contact, rest, and drift in stance.

Contact, rest and the stance label. A foot is on the ground from touchdown (a swing's
end) to toe-off (the next swing's start). Without ``roll`` and ``impact`` (the walk) it is
at rest all that time. With them the contact begins with the heel roll (and the impact)
over ``max(roll.heel_s, impact.duration_s)`` and ends with the toe roll over
``roll.toe_s``; only the flat part between is at rest. The stance label (the ``stance``
column of the IMU CSV) is the truth of rest::

    stance[k]  ⇔  velocity and angular rate are zero throughout (t_{k−1}, t_k] or [t_k, t_{k+1})

For the walk that is the whole contact, both swing ends included (where velocity and
angular rate are exactly zero); for a rolling stance (running) it is the flat part with
its two ends: the rolls and the impact are labelled moving although the foot is on the
ground, and the instants of touchdown and toe-off (velocity and rate zero, but moving on
both sides) are not labelled. A stance must leave at least one still sample interval
(:func:`bodyfusion.sim.gait.plan_gait` checks it).

Swing, with ``τ`` = elapsed fraction of the swing:

* position on the straight line from where the foot leaves the ground to where it lands
  (the footprints; moved by the roll when there is one), fraction
  ``u(τ) = 35τ⁴ − 84τ⁵ + 70τ⁶ − 20τ⁷`` (7th order: velocity, acceleration and jerk
  are zero at both ends);
* height ``lift_m · 256 τ⁴(1−τ)⁴`` above that line;
* toe angle (positive toe-up) ``−pitch_amplitude · K (1−2τ) τ⁴(1−τ)⁴``, normalised to
  peak at ±amplitude: toe-down after toe-off (τ = 1/3), toe-up before heel strike
  (τ = 2/3), zero with zero rate at both ends; with a roll, plus
  ``−θ_off (1 − u(τ)) + θ_td u(τ)`` so the swing leaves the ground at the toe-off pitch
  ``−θ_off`` and lands at the touchdown pitch ``θ_td``;
* azimuth ``az0 + u(τ)(az1 − az0)`` (unwrapped path headings).

Stance roll (``roll``). After touchdown the foot, landed toe-up by ``θ_td``, rolls flat
about the heel over ``heel_s``: pitch ``θ = θ_td (1 − u(τ))``; before toe-off it rolls
about the ball of the foot over ``toe_s``: ``θ = −θ_off u(τ)`` (heel up); ``τ`` the
elapsed fraction of the roll. Rolling by ``θ`` about a pivot that is ``d`` = (forward, up)
from the IMU's flat position moves the IMU by ``R(θ) d − d`` in the heading's vertical
plane, ``R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]]``; velocity ``θ̇ R′(θ) d``, acceleration
``θ̈ R′(θ) d − θ̇² R(θ) d``. The heel is ``heel_m`` behind and ``height_m`` below the IMU,
the ball ``ball_m`` ahead and ``height_m`` below.

Impact (``impact``). At touchdown the heel pad and the sole compress and spring back: the
foot dips by ``c · 256 τ⁴(1−τ)⁴`` over ``duration_s`` (τ its elapsed fraction), with
``c = peak_g · g₀ · duration_s² / 32`` so that the upward acceleration peaks at
``peak_g`` standard gravities at mid-impact (a dip of about a millimetre: velocity and
position stay consistent with the specific force).

Foot frame: x forward (toe), y left, z up when flat. Attitude
``q_nb = q_z(π/2 − az) ⊗ q_y(−toe) ⊗ q_z(−mount_yaw)``: the optional mounting yaw turns
the IMU on the foot clockwise (seen from above) by ``mount_yaw``, so the IMU's x axis
points at azimuth ``az + mount_yaw`` while the foot is flat. In swing the IMU sits at the
foot's rotation centre, and its position is the truth.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import Polynomial

from bodyfusion.nav.earth import STANDARD_GRAVITY
from bodyfusion.sim.gait_config import Foot, StanceNoiseConfig
from bodyfusion.sim.imu import MotionState, blockwise, quat_about_axis, quat_multiply
from bodyfusion.sim.paths import direction

__all__ = ["FootMotion", "Impact", "Roll", "StanceDrift", "ground_motion_samples", "stance_drift"]


# Swing profiles in τ ∈ [0, 1].
_ALONG = Polynomial([0, 0, 0, 0, 35, -84, 70, -20])
_BUMP4 = Polynomial([0, 1]) ** 4 * Polynomial([1, -1]) ** 4  # τ⁴(1−τ)⁴
_LIFT = 256.0 * _BUMP4
_TOE = -(19683.0 / 16.0) * Polynomial([1, -2]) * _BUMP4  # peaks −1 at τ = 1/3, +1 at τ = 2/3
_PROFILES = {name: (p, p.deriv(1), p.deriv(2)) for name, p in {"along": _ALONG, "lift": _LIFT, "toe": _TOE}.items()}
_LIFT_PEAK_CURVATURE = 32.0  # −d²(256 τ⁴(1−τ)⁴)/dτ² at τ = ½, its largest value


def _along_heading(forward_up: np.ndarray, az: np.ndarray) -> np.ndarray:
    """(N, 3) ENU of (N, 2) (forward, up) components in the vertical plane of azimuth ``az``."""
    return np.column_stack([forward_up[:, :1] * direction(az), forward_up[:, 1]])


def _pivot_roll(theta: np.ndarray, dtheta: np.ndarray, ddtheta: np.ndarray,
                d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IMU displacement R(θ)d − d (N, 2) (forward, up; m), its velocity and acceleration,
    when the foot pitches by θ (rad, toe-up) about a pivot ``−d`` (N, 2) from the IMU."""
    c, s = np.cos(theta), np.sin(theta)
    rd = np.column_stack([d[:, 0] * c - d[:, 1] * s, d[:, 0] * s + d[:, 1] * c])
    jd = np.column_stack([-d[:, 0] * s - d[:, 1] * c, d[:, 0] * c - d[:, 1] * s])  # R′(θ) d
    return rd - d, dtheta[:, None] * jd, ddtheta[:, None] * jd - (dtheta**2)[:, None] * rd


@dataclass(frozen=True)
class Roll:
    """A resolved :class:`~bodyfusion.sim.gait_config.StanceRollConfig`: pitches (rad), roll lengths in samples, and the
    IMU's offsets (forward, up; m) from the heel and from the ball of the foot."""

    touchdown_rad: float
    toeoff_rad: float
    heel_n: int
    toe_n: int
    from_heel: tuple[float, float]
    from_ball: tuple[float, float]


@dataclass(frozen=True)
class Impact:
    """A resolved :class:`~bodyfusion.sim.gait_config.ImpactConfig`: the dip ``depth_m`` (m)
    over ``n`` samples."""

    depth_m: float
    n: int

    @classmethod
    def of(cls, peak_g: float, n: int, rate_hz: float) -> "Impact":
        """The dip whose upward acceleration peaks at ``peak_g`` standard gravities halfway
        through ``n`` samples at ``rate_hz`` (c in the module docstring)."""
        return cls(peak_g * STANDARD_GRAVITY * (n / rate_hz) ** 2 / _LIFT_PEAK_CURVATURE, n)


def ground_motion_samples(roll: Roll | None, impact: Impact | None) -> tuple[int, int]:
    """Samples a foot moves on the ground before each toe-off (the toe roll) and after each
    touchdown (the heel roll or the impact, whichever lasts longer)."""
    return (roll.toe_n if roll is not None else 0,
            max(roll.heel_n if roll is not None else 0, impact.n if impact is not None else 0))


@dataclass
class FootMotion:
    """One foot's analytic motion: footprints and the swings between them.

    footprints: (M+1, 3) ENU m, footprint_az: (M+1,) rad; swing j goes from footprint j
    to j+1 over samples ``k_start[j]`` … ``k_end[j]`` of the ``rate_hz`` grid; ``roll`` and
    ``impact`` (optional) move the foot in contact (see the module docstring).
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
    roll: Roll | None = None
    impact: Impact | None = None

    def mounted(self, mount_yaw_deg: float) -> "FootMotion":
        """The same foot carrying an IMU turned by ``mount_yaw_deg`` (clockwise from above)."""
        return dataclasses.replace(self, mount_yaw_rad=math.radians(mount_yaw_deg))

    @property
    def t_start(self) -> np.ndarray:
        return self.k_start / self.rate_hz

    @property
    def t_end(self) -> np.ndarray:
        return self.k_end / self.rate_hz

    def stance_flags(self, n_samples: int) -> np.ndarray:
        """(n_samples,) bool: the foot at rest at sample k (see the module docstring)."""
        before, after = ground_motion_samples(self.roll, self.impact)
        moving = np.zeros(n_samples + 1, dtype=np.int64)
        np.add.at(moving, np.minimum(self.k_start - before + 1, n_samples), 1)
        np.add.at(moving, np.minimum(self.k_end + after, n_samples), -1)
        return np.cumsum(moving[:n_samples]) == 0

    def _swing_ends(self, js: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where swings ``js`` leave the ground and land (N, 3): the footprints, rolled
        heel-up about the ball and toe-up about the heel when there is a roll."""
        p0, p1 = self.footprints[js], self.footprints[js + 1]
        if self.roll is None:
            return p0, p1
        r = self.roll
        zero = np.zeros(js.size)
        off = _pivot_roll(np.full(js.size, -r.toeoff_rad), zero, zero, np.tile(r.from_ball, (js.size, 1)))[0]
        on = _pivot_roll(np.full(js.size, r.touchdown_rad), zero, zero, np.tile(r.from_heel, (js.size, 1)))[0]
        return (p0 + _along_heading(off, self.footprint_az[js]),
                p1 + _along_heading(on, self.footprint_az[js + 1]))

    def _contact(self, t: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, ...]:
        """Roll and impact at times ``t`` on the ground after swing ``j`` (−1: before the
        first): position, velocity, acceleration offsets (N, 3) ENU and pitch, pitch rate (N,)."""
        n, rate = t.size, self.rate_hz
        # the last touchdown and the next toe-off (samples); phase ends are compared as
        # k / rate_hz, the sample grid's own expression, so a sample on a boundary is exact
        landed, lifts = j >= 0, j + 1 < self.k_start.size
        k_on = self.k_end[np.maximum(j, 0)]
        k_off = self.k_start[np.minimum(j + 1, self.k_start.size - 1)]
        since = t - k_on / rate  # time since touchdown, s
        until = k_off / rate - t  # time to toe-off, s
        theta, dtheta, ddtheta = np.zeros(n), np.zeros(n), np.zeros(n)
        pivot = np.zeros((n, 2))
        if self.roll is not None:
            r = self.roll
            heel_s, toe_s = r.heel_n / rate, r.toe_n / rate
            for m, tau, dur, start, end, d in (
                    (landed & (t < (k_on + r.heel_n) / rate), since / heel_s, heel_s, r.touchdown_rad, 0.0,
                     r.from_heel),
                    (lifts & (t > (k_off - r.toe_n) / rate), 1.0 - until / toe_s, toe_s, 0.0, -r.toeoff_rad,
                     r.from_ball)):
                u, du, ddu = (f(np.clip(tau[m], 0.0, 1.0)) for f in _PROFILES["along"])
                theta[m] = start + (end - start) * u
                dtheta[m] = (end - start) * du / dur
                ddtheta[m] = (end - start) * ddu / dur**2
                pivot[m] = d
        off, v, a = _pivot_roll(theta, dtheta, ddtheta, pivot)
        az = self.footprint_az[j + 1]
        pos, vel, acc = _along_heading(off, az), _along_heading(v, az), _along_heading(a, az)
        if self.impact is not None:
            dur = self.impact.n / rate
            m = landed & (t < (k_on + self.impact.n) / rate)
            b, db, ddb = (f(np.clip(since[m] / dur, 0.0, 1.0)) for f in _PROFILES["lift"])
            pos[m, 2] -= self.impact.depth_m * b
            vel[m, 2] -= self.impact.depth_m * db / dur
            acc[m, 2] -= self.impact.depth_m * ddb / dur**2
        return pos, vel, acc, theta, dtheta

    def evaluate(self, t: np.ndarray) -> MotionState:
        """The motion at times ``t`` (s), computed a block of instants at a time (:func:`~bodyfusion.sim.imu.blockwise`)."""
        return blockwise(self._evaluate, t)

    def _evaluate(self, t: np.ndarray) -> MotionState:
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
            p0, p1 = self._swing_ends(js)
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
            if self.roll is not None:
                span = self.roll.touchdown_rad + self.roll.toeoff_rad
                toe[swing] += -self.roll.toeoff_rad + span * u
                dtoe[swing] += span * du / dur
        ground = ~swing
        if (self.roll is not None or self.impact is not None) and ground.any():
            dp, dv, da, toe[ground], dtoe[ground] = self._contact(t[ground], j[ground])
            pos[ground] += dp
            vel[ground] += dv
            acc[ground] += da
        yaw = 0.5 * np.pi - az  # ENU yaw, counter-clockwise from East
        q = quat_multiply(quat_about_axis(yaw, 3), quat_about_axis(-toe, 2))
        if self.mount_yaw_rad:
            q = quat_multiply(q, quat_about_axis(np.full_like(yaw, -self.mount_yaw_rad), 3))
        # ω_n = yaw rate about Up + (−toe rate) about the yawed y axis [−sin yaw, cos yaw, 0].
        omega = np.stack([dtoe * np.sin(yaw), -dtoe * np.cos(yaw), -daz], axis=-1)
        return MotionState(pos=pos, vel=vel, acc=acc, q_nb=q, omega_n=omega)


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
    (draws from ``rng``; see :class:`~bodyfusion.sim.gait_config.StanceNoiseConfig`)."""
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

