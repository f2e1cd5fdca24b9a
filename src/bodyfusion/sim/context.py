"""What a simulated system kind is given and what it returns (:mod:`bodyfusion.sim.scenario`
runs the kinds; each kind's module builds on these)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bodyfusion.sim.gait import GaitPlan

if TYPE_CHECKING:
    from bodyfusion.sim.scenario import Scenario

DEFAULT_GEODETIC_ORIGIN = (49.4613, 11.1109, 390.0)
"""Latitude (deg), longitude (deg), ellipsoidal height (m) of the ENU frame when a scenario gives none."""


@dataclass
class SimContext:
    """What every system kind sees: the scenario, the walk, the seed and the output folder."""

    scenario: Scenario
    plan: GaitPlan
    t: np.ndarray
    seed: int
    out_dir: Path
    outputs: dict[str, SystemOutput] = field(default_factory=dict)
    """Systems simulated so far (aiding kinds such as ``uwb_tag`` read their hosts' truth)."""

    @property
    def geodetic_origin(self) -> tuple[float, float, float]:
        """The scenario's geodetic origin, or :data:`DEFAULT_GEODETIC_ORIGIN`."""
        origin = self.scenario.geodetic_origin
        return tuple(float(v) for v in (origin if origin is not None else DEFAULT_GEODETIC_ORIGIN))  # type: ignore[return-value]


@dataclass
class SystemOutput:
    """One simulated system: its truth track, its layout section and the files it wrote."""

    truth_t: np.ndarray
    truth_pos: np.ndarray
    layout: dict[str, Any]
    samples: int
    files: list[Path] = field(default_factory=list)
    outages: list[dict[str, Any]] = field(default_factory=list)
    """Entries for the layout's ``outages`` list (system, start_s, duration_s)."""
    uses_geodetic_origin: bool = False
    """The system's data is geodetic (GNSS): the layout needs the scenario's origin."""
