"""The pedestrian's walk along a body path: when each foot swings and where it lands.

Timing. One gait cycle of a foot lasts ``T`` = 2 / cadence (cadence counts steps of
either foot) with ``stance_fraction`` of it on the ground; or, for the "pulse" profile
of [Shen2025]'s simulation, ``swing_s`` + ``stance_s``. The other foot runs half a
cycle later; with a stance fraction below ½ (running) both feet are in the air for
``T (½ − stance_fraction)`` after each toe-off (the flight phase). Every swing, roll and
impact starts and ends ON an IMU sample instant (the cycle, the swing, the half-cycle
offset and the roll and impact durations are rounded to whole samples, each at most half a
sample off the configured value), so a sample interval never straddles two phases.
A stance must leave at least one still sample interval between the rolls and the impact
(:mod:`bodyfusion.sim.foot_motion`: the stance label). The first toe roll starts at
``start_still_s`` and ``end_still_s`` starts after the last heel roll, so both feet are at
rest for those two times whatever the gait.

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

The plugins take the pedestrian from here: the plan (:func:`plan_gait`, :class:`GaitPlan`),
the ``gait`` section (:class:`~bodyfusion.sim.gait_config.GaitConfig`) and a foot's stance
drift (:class:`~bodyfusion.sim.gait_config.StanceNoiseConfig`,
:func:`~bodyfusion.sim.foot_motion.stance_drift`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bodyfusion.base.errors import ConfigError
from bodyfusion.sim.foot_motion import FootMotion, Impact, Roll, ground_motion_samples
from bodyfusion.sim.gait_config import Foot, GaitConfig, PauseConfig, StairsConfig
from bodyfusion.sim.paths import BodyPath, left_normal

MAX_SAMPLES = 20_000_000
"""Most samples a simulated walk may have (55 h at 100 Hz; every system holds them in memory)."""

# GaitConfig, StanceNoiseConfig and stance_drift: re-exported for the plugins (see the module docstring)
__all__ = ["FootTrack", "GaitPlan", "plan_gait"]


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


def _check_samples(n_samples: int, rate_hz: float) -> None:
    if n_samples > MAX_SAMPLES:
        raise ConfigError("path", f"the walk lasts {n_samples / rate_hz / 3600:.1f} h, {n_samples:,} samples at "
                          f"{rate_hz:g} Hz: at most {MAX_SAMPLES:,} samples are simulated")


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
        impact = Impact.of(gait.impact.peak_g, n_impact, rate_hz)
    n_before, n_after = ground_motion_samples(roll, impact)
    if n_cycle - n_swing < n_before + n_after + 1:
        raise ConfigError(f"{key}.roll" if roll is not None else f"{key}.impact",
                          f"a stance of {(n_cycle - n_swing) / rate_hz:.3g} s leaves no rest between "
                          f"{n_after / rate_hz:.3g} s after touchdown and {n_before / rate_hz:.3g} s before toe-off")
    n_steps = max(1, int(round(path.length / (0.5 * gait.stride_m))))
    _check_samples(n0 + (n_steps // 2 + 1) * n_cycle, rate_hz)  # before the footprints are made
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
    _check_samples(n_samples, rate_hz)
    return GaitPlan(float(rate_hz), n_samples, {"left": feet["left"], "right": feet["right"]}, path, step, n0)
