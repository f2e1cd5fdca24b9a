"""The scenario's ``gait`` section (:class:`GaitConfig` and its parts) and a foot's ``stance_noise``.

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

What the parts do: the timing, footprints, stairs and pauses of the walk in
:mod:`bodyfusion.sim.gait`; the swing, the stance roll, the impact and the stance drift of one
foot in :mod:`bodyfusion.sim.foot_motion`.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, model_validator

from bodyfusion.base.sections import StrictModel

__all__ = ["FlightConfig", "Foot", "GAIT_KINDS", "GaitConfig", "GaitKind", "ImpactConfig", "PauseConfig",
           "StairsConfig", "StanceNoiseConfig", "StanceRollConfig"]

Foot = Literal["left", "right"]
GaitKind = Literal["walk", "run", "stairs"]


class StanceRollConfig(StrictModel):
    """Heel-to-toe roll in stance (:mod:`bodyfusion.sim.foot_motion`): the foot lands toe-up by
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
    gravities) halfway through ``duration_s`` after touchdown (:mod:`bodyfusion.sim.foot_motion`)."""

    peak_g: float = Field(default=4.0, gt=0, le=20)
    duration_s: float = Field(default=0.03, gt=0)


class FlightConfig(StrictModel):
    """``steps`` treads ``up``, ``down`` or ``level`` (a landing); no ``steps``: to the end of the walk."""

    direction: Literal["up", "down", "level"]
    steps: int | None = Field(default=None, ge=1, le=100_000)


class StairsConfig(StrictModel):
    """Stairs: each footprint ``rise_m`` (m) above or below the previous one, by ``flights``
    from the first step on (the tread is the step length, stride_m / 2; :mod:`bodyfusion.sim.gait`)."""

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


MAX_SPEED_MPS = 13.0
"""Fastest walk or run a gait may describe (m/s; the fastest sprinters peak near 12.4 m/s)."""


class GaitConfig(StrictModel):
    """The scenario's ``gait`` section (defaults: an ordinary walk at ≈ 1.26 m/s; other
    ``kind`` values change the defaults, :data:`GAIT_KINDS`).

    Give ``swing_s`` and ``stance_s`` together to set the cycle directly (they replace
    ``cadence_steps_per_min`` and ``stance_fraction``), e.g. [Shen2025]'s pulse
    profile: ``{swing_s: 1, stance_s: 1, lift_m: 0, pitch_amplitude_deg: 0}``.
    ``roll``, ``impact`` (:mod:`bodyfusion.sim.foot_motion`), ``stairs`` (:mod:`bodyfusion.sim.gait`):
    ``null``: none; ``pauses`` (:mod:`bodyfusion.sim.gait`): a list of ``{at_s, duration_s}``.
    """

    kind: GaitKind = "walk"
    stride_m: float = Field(default=1.4, gt=0, le=6.0)  # a sprinter's stride is ~5 m
    cadence_steps_per_min: float = Field(default=108.0, gt=0, le=400.0)
    stance_fraction: float = Field(default=0.6, gt=0, lt=1)
    swing_s: float | None = Field(default=None, gt=0, le=10.0)
    stance_s: float | None = Field(default=None, gt=0, le=600.0)
    lift_m: float = Field(default=0.1, ge=0, le=1.0)
    pitch_amplitude_deg: float = Field(default=30.0, ge=0, lt=90)
    lateral_offset_m: float = Field(default=0.1, ge=0, le=0.5)
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
        cycle_s = self.swing_s + self.stance_s if self.swing_s is not None else 120.0 / self.cadence_steps_per_min
        if self.stride_m / cycle_s > MAX_SPEED_MPS:
            raise ValueError(f"a stride of {self.stride_m:g} m every {cycle_s:.3g} s is {self.stride_m / cycle_s:.3g} m/s, "
                             f"faster than any person runs ({MAX_SPEED_MPS:g} m/s)")
        return self

    def cycle_s(self) -> tuple[float, float]:
        """(gait cycle of one foot, swing duration) in seconds."""
        if self.swing_s is not None and self.stance_s is not None:
            return self.swing_s + self.stance_s, self.swing_s
        cycle = 2.0 * 60.0 / self.cadence_steps_per_min
        return cycle, cycle * (1.0 - self.stance_fraction)


class StanceNoiseConfig(StrictModel):
    """A foot that is not perfectly still in stance (the coloured measurement noise of the
    [Xu2024] and [Deng2026]): inside each stance run its velocity (ENU, every axis)
    follows v_k = colour_factor · v_{k−1} + ξ_k, ξ_k ~ N(0, sigma_mps²), zero at both ends
    of the run (heel strike and toe-off) and in swing (:func:`bodyfusion.sim.foot_motion.stance_drift`)."""

    colour_factor: float = Field(default=0.9, ge=0, lt=1)
    sigma_mps: float = Field(default=0.005, ge=0)
