"""The pedestrian's feet along a body path: walking, running or on stairs; stance and swing.

Gait kinds. ``gait.kind`` picks defaults (:data:`GAIT_KINDS`) for one foot model; every key
can be overridden, and every feature (roll, impact, stairs, pauses) can be used with any kind:

======  ========  ==========  ======  ======  =====  ========  ==============================
kind    stride    cadence     stance  lift    toe    lateral   also
======  ========  ==========  ======  ======  =====  ========  ==============================
walk    1.4 m     108 /min    0.6     0.10 m  30°    0.10 m    — (≈ 1.26 m/s)
run     2.12 m    170 /min    0.2125  0.25 m  35°    0.06 m    ``roll``, ``impact`` (3.0 m/s;
                                                               stance 0.15 s, flight 0.20 s)
stairs  0.56 m    90 /min     0.62    0.20 m  15°    0.10 m    ``stairs`` (0.28 m tread,
                                                               0.17 m rise, every step up)
======  ========  ==========  ======  ======  =====  ========  ==============================

Timing. One gait cycle of a foot lasts ``T`` = 2 / cadence (cadence counts steps of
either foot) with ``stance_fraction`` of it on the ground; or, for the "pulse" profile
of the FB-RTS paper's simulation, ``swing_s`` + ``stance_s``. The other foot runs half a
cycle later; with a stance fraction below ½ (running) both feet are in the air for
``T (½ − stance_fraction)`` after each toe-off (the flight phase). Every swing, roll and
impact starts and ends ON an IMU sample instant (the cycle, the swing, the half-cycle
offset and the roll and impact durations are rounded to whole samples, each at most half a
sample off the configured value), so a sample interval never straddles two phases.

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
both sides) are not labelled. A stance must leave at least one still sample interval.
The first toe roll starts at ``start_still_s`` and ``end_still_s`` starts after the last
heel roll, so both feet are at rest for those two times whatever the gait.

Geometry. The walk starts and ends with both feet side by side, still for
``start_still_s`` / ``end_still_s``. Footprints lie on the body path at multiples of the
step length (stride/2, adjusted so a whole number of steps fits the path), offset
``lateral_offset_m`` to the left/right, heading along the path there. The first step of
``first_foot`` and the last step of the trailing foot are half strides.

Stairs (``stairs``). The m-th step (m = 1 … n, the footprint m step lengths along the
path) is a tread: footprint m stands ``rise_m`` higher than footprint m − 1 in an ``up``
flight, lower in a ``down`` one, level in a ``level`` one (a landing). ``flights`` runs
from the first step in order; a flight without ``steps`` runs to the end of the walk, and
steps after the last flight are level. Each swing of a foot therefore climbs two risers
(one for the first and the last step), and the truth's ``up`` is the footprint height.

Pauses (``pauses``). At the first swing that would start at or after ``at_s`` the walker
stands: that swing and all later ones start later, by as much as it takes for both feet
to be at rest together for ``duration_s`` (rounded to samples; longer when the gait's own
double support already is). ``at_s`` is on the simulation clock, after the first step and
after the previous pause has ended.

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
from typing import Any, Literal

import numpy as np
from numpy.polynomial import Polynomial
from pydantic import Field, model_validator

from bodyfusion.core.layout import StrictModel
from bodyfusion.core.errors import ConfigError
from bodyfusion.nav.earth import STANDARD_GRAVITY
from bodyfusion.sim.imu import MotionState, quat_multiply
from bodyfusion.sim.paths import BodyPath, direction, left_normal

__all__ = ["FlightConfig", "FootMotion", "FootTrack", "GAIT_KINDS", "GaitConfig", "GaitPlan", "Impact", "ImpactConfig",
           "PauseConfig", "Roll", "StairsConfig", "StanceDrift", "StanceNoiseConfig", "StanceRollConfig", "plan_gait",
           "stance_drift"]

Foot = Literal["left", "right"]
GaitKind = Literal["walk", "run", "stairs"]


class StanceRollConfig(StrictModel):
    """Heel-to-toe roll in stance (see the module docstring): the foot lands toe-up by
    ``touchdown_pitch_deg`` and rolls flat about the heel over ``heel_s``; it rolls heel-up
    about the ball to ``toeoff_pitch_deg`` over ``toe_s`` before toe-off. ``heel_m``: the heel
    contact behind the IMU, ``ball_m``: the ball of the foot ahead of it, ``height_m``: the
    IMU above the sole (m)."""

    touchdown_pitch_deg: float = Field(default=8.0, ge=0, lt=45)
    toeoff_pitch_deg: float = Field(default=12.0, ge=0, lt=45)
    heel_s: float = Field(default=0.05, gt=0)
    toe_s: float = Field(default=0.05, gt=0)
    heel_m: float = Field(default=0.12, ge=0)
    ball_m: float = Field(default=0.08, ge=0)
    height_m: float = Field(default=0.06, ge=0)


class ImpactConfig(StrictModel):
    """Heel-strike transient: the upward acceleration peaks at ``peak_g`` (standard
    gravities) halfway through ``duration_s`` after touchdown (see the module docstring)."""

    peak_g: float = Field(default=4.0, gt=0, le=20)
    duration_s: float = Field(default=0.03, gt=0)


class FlightConfig(StrictModel):
    """``steps`` treads ``up``, ``down`` or ``level`` (a landing); no ``steps``: to the end of the walk."""

    direction: Literal["up", "down", "level"]
    steps: int | None = Field(default=None, ge=1)


class StairsConfig(StrictModel):
    """Stairs: each footprint ``rise_m`` (m) above or below the previous one, by ``flights``
    from the first step on (the tread is the step length, stride_m / 2)."""

    rise_m: float = Field(default=0.17, gt=0, le=0.3)
    flights: list[FlightConfig] = Field(default_factory=lambda: [FlightConfig(direction="up")], min_length=1)


class PauseConfig(StrictModel):
    """Both feet at rest for ``duration_s`` from the first step boundary after ``at_s`` (s)."""

    at_s: float = Field(gt=0)
    duration_s: float = Field(gt=0)


GAIT_KINDS: dict[str, dict[str, Any]] = {
    "walk": {},
    # 3.0 m/s (2.12 m × 170/120 Hz); stance 0.15 s of a 0.706 s cycle
    "run": {"stride_m": 2.12, "cadence_steps_per_min": 170.0, "stance_fraction": 0.2125, "lift_m": 0.25,
            "pitch_amplitude_deg": 35.0, "lateral_offset_m": 0.06, "roll": {}, "impact": {}},
    # tread 0.28 m, rise 0.17 m, 90 steps/min
    "stairs": {"stride_m": 0.56, "cadence_steps_per_min": 90.0, "stance_fraction": 0.62, "lift_m": 0.2,
               "pitch_amplitude_deg": 15.0, "stairs": {}},
}
"""``gait.kind`` → the defaults it sets (keys the scenario gives win; ``walk``: the field defaults)."""


class GaitConfig(StrictModel):
    """The scenario's ``gait`` section (defaults: an ordinary walk at ≈ 1.26 m/s; other
    ``kind`` values change the defaults, :data:`GAIT_KINDS`).

    Give ``swing_s`` and ``stance_s`` together to set the cycle directly (they replace
    ``cadence_steps_per_min`` and ``stance_fraction``), e.g. the FB-RTS paper's pulse
    profile: ``{swing_s: 1, stance_s: 1, lift_m: 0, pitch_amplitude_deg: 0}``.
    ``roll``, ``impact``, ``stairs``: see the module docstring (``null``: none);
    ``pauses``: a list of ``{at_s, duration_s}``.
    """

    kind: GaitKind = "walk"
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
    roll: StanceRollConfig | None = None
    impact: ImpactConfig | None = None
    stairs: StairsConfig | None = None
    pauses: list[PauseConfig] = Field(default_factory=list)

    @model_validator(mode="before")
    @classmethod
    def _kind_defaults(cls, data: Any) -> Any:
        if isinstance(data, dict):
            defaults = GAIT_KINDS.get(data.get("kind", "walk"))
            if defaults:
                return {**defaults, **data}
        return data

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
_LIFT_PEAK_CURVATURE = 32.0  # −d²(256 τ⁴(1−τ)⁴)/dτ² at τ = ½, its largest value


def _quat_z(angle: np.ndarray) -> np.ndarray:
    a = 0.5 * np.asarray(angle, dtype=float)
    z = np.zeros_like(a)
    return np.stack([np.cos(a), z, z, np.sin(a)], axis=-1)


def _quat_y(angle: np.ndarray) -> np.ndarray:
    a = 0.5 * np.asarray(angle, dtype=float)
    z = np.zeros_like(a)
    return np.stack([np.cos(a), z, np.sin(a), z], axis=-1)


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
    """A resolved :class:`StanceRollConfig`: pitches (rad), roll lengths in samples, and the
    IMU's offsets (forward, up; m) from the heel and from the ball of the foot."""

    touchdown_rad: float
    toeoff_rad: float
    heel_n: int
    toe_n: int
    from_heel: tuple[float, float]
    from_ball: tuple[float, float]


@dataclass(frozen=True)
class Impact:
    """A resolved :class:`ImpactConfig`: the dip ``depth_m`` (m) over ``n`` samples."""

    depth_m: float
    n: int


def _ground_motion_samples(roll: Roll | None, impact: Impact | None) -> tuple[int, int]:
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
        before, after = _ground_motion_samples(self.roll, self.impact)
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


def _samples(seconds: float, rate_hz: float, key: str) -> int:
    """``seconds`` as a whole number (≥ 1) of sample intervals."""
    n = int(round(seconds * rate_hz))
    if n < 1:
        raise ConfigError(key, f"{seconds:g} s is shorter than one sample at {rate_hz:g} Hz")
    return n


def _footprint_heights(stairs: StairsConfig | None, n_steps: int, key: str) -> np.ndarray:
    """Height (m) of the footprint m step lengths along the path, m = 0 … n_steps."""
    if stairs is None:
        return np.zeros(n_steps + 1)
    risers = np.zeros(n_steps + 1, dtype=np.int64)  # +1 up, −1 down, 0 level, per step
    sign = {"up": 1, "down": -1, "level": 0}
    m = 1
    for i, flight in enumerate(stairs.flights):
        if flight.steps is None and i < len(stairs.flights) - 1:
            raise ConfigError(f"{key}.stairs.flights.{i}.steps", "only the last flight may run to the end of the walk")
        count = n_steps + 1 - m if flight.steps is None else flight.steps
        if m + count - 1 > n_steps:
            need = sum(f.steps or 0 for f in stairs.flights)
            raise ConfigError(f"{key}.stairs.flights.{i}.steps",
                              f"the flights need {need} steps but the path has {n_steps}")
        risers[m:m + count] = sign[flight.direction]
        m += count
    return stairs.rise_m * np.cumsum(risers)


def _insert_pauses(k_start: np.ndarray, pauses: list[PauseConfig], rate_hz: float, n_swing: int,
                   n_after: int, n_before: int, key: str) -> np.ndarray:
    """Swing starts (samples, both feet in walking order) delayed by ``pauses``: before the
    first swing starting at or after ``at_s`` both feet rest together for ``duration_s``
    (rest from the previous swing's end plus ``n_after`` to this swing's start minus ``n_before``)."""
    k = k_start.copy()
    resumed = -1
    for p, pause in enumerate(pauses):
        name = f"{key}.pauses.{p}"
        n_pause = _samples(pause.duration_s, rate_hz, f"{name}.duration_s")
        a = int(round(pause.at_s * rate_hz))
        e = int(np.searchsorted(k, a))  # the first swing starting at or after at_s
        if a <= resumed:
            raise ConfigError(f"{name}.at_s",
                              f"before the previous pause ends (walking resumes at {resumed / rate_hz:.3f} s)")
        if e == 0:
            raise ConfigError(f"{name}.at_s", f"before the first step ({k[0] / rate_hz:.3f} s)")
        if e == k.size:
            raise ConfigError(f"{name}.at_s", f"after the last step ({k[-1] / rate_hz:.3f} s)")
        rest_from = int(k[e - 1]) + n_swing + n_after  # the swing before has landed and settled
        k[e:] += max(0, rest_from + n_pause + n_before - int(k[e]))
        resumed = int(k[e])
    return k


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
    roll = impact = None
    if gait.roll is not None:
        r = gait.roll
        roll = Roll(math.radians(r.touchdown_pitch_deg), math.radians(r.toeoff_pitch_deg),
                    _samples(r.heel_s, rate_hz, f"{key}.roll.heel_s"), _samples(r.toe_s, rate_hz, f"{key}.roll.toe_s"),
                    (r.heel_m, r.height_m), (-r.ball_m, r.height_m))
    if gait.impact is not None:
        n_impact = _samples(gait.impact.duration_s, rate_hz, f"{key}.impact.duration_s")
        impact = Impact(gait.impact.peak_g * STANDARD_GRAVITY * (n_impact / rate_hz) ** 2 / _LIFT_PEAK_CURVATURE,
                        n_impact)
    n_before, n_after = _ground_motion_samples(roll, impact)
    if n_cycle - n_swing < n_before + n_after + 1:
        raise ConfigError(f"{key}.roll" if roll is not None else f"{key}.impact",
                          f"a stance of {(n_cycle - n_swing) / rate_hz:.3g} s leaves no rest between "
                          f"{n_after / rate_hz:.3g} s after touchdown and {n_before / rate_hz:.3g} s before toe-off")
    n_steps = max(1, int(round(path.length / (0.5 * gait.stride_m))))
    step = path.length / n_steps
    heights = _footprint_heights(gait.stairs, n_steps, key)

    # event i = 1 … n+1 moves foot (lead if i odd) to min(i, n)·step along the path
    i = np.arange(1, n_steps + 2)
    k_event = n0 + n_before + (i - 1) // 2 * n_cycle + np.where(i % 2 == 1, 0, n_half)
    k_event = _insert_pauses(k_event, gait.pauses, rate_hz, n_swing, n_after, n_before, key)
    target = np.minimum(i, n_steps)

    side = {"left": 1.0, "right": -1.0}
    lead: Foot = gait.first_foot
    trail: Foot = "right" if lead == "left" else "left"
    feet: dict[str, FootMotion] = {}
    for foot, mine in ((lead, i % 2 == 1), (trail, i % 2 == 0)):
        s = np.concatenate([[0.0], target[mine] * step])
        xy, az = path.at(s)
        xy = xy + side[foot] * gait.lateral_offset_m * left_normal(az)
        footprints = np.column_stack([xy, np.concatenate([[0.0], heights[target[mine]]])])
        k_start = k_event[mine]
        feet[foot] = FootMotion(foot, float(rate_hz), footprints, az, k_start, k_start + n_swing,
                                gait.lift_m, math.radians(gait.pitch_amplitude_deg), roll=roll, impact=impact)
    last = int(k_event[-1]) + n_swing + n_after
    n_samples = last + int(round(gait.end_still_s * rate_hz)) + 1
    return GaitPlan(float(rate_hz), n_samples, {"left": feet["left"], "right": feet["right"]}, path, step, n0)
