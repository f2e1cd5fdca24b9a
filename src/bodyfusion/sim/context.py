"""What a simulated system kind is given and what it returns.

A *kind* (``systems.<name>.kind`` in a scenario file) is owned by the plugin whose layout
section it writes (MaRS-style: each sensor's folder holds its whole model, simulation
included): the plugin returns :class:`SystemKind` objects from its
``fusion_simulation_kinds`` hook, and :mod:`bodyfusion.sim.scenario` runs them with a
:class:`SimContext`. Each kind builds its layout section with its plugin's own config model,
so a renamed config field breaks the simulation at once, not the run that reads it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import BaseModel

from bodyfusion.sim.files import SimFile
from bodyfusion.sim.gait import GaitPlan
from bodyfusion.sim.gait_config import GaitConfig

DEFAULT_GEODETIC_ORIGIN = (49.4613, 11.1109, 390.0)
"""Latitude (deg), longitude (deg), ellipsoidal height (m) of the ENU frame when a scenario gives none."""


@dataclass
class SimContext:
    """What every system kind sees: the scenario's rate (Hz), gravity (m/s^2) and gait, the
    planned walk and its sample times (s), the seed, the geodetic origin of the ENU frame, and
    the systems simulated so far (aiding kinds read their hosts' truth)."""

    rate_hz: float
    gravity_mps2: float
    gait: GaitConfig
    plan: GaitPlan
    t: np.ndarray
    seed: int
    geodetic_origin: tuple[float, float, float] = DEFAULT_GEODETIC_ORIGIN
    outputs: dict[str, SystemOutput] = field(default_factory=dict)


@dataclass
class SystemOutput:
    """One simulated system: its truth track, its layout section (naming its files) and its
    files (:class:`~bodyfusion.sim.files.SimFile`: each written to the output folder, or held in
    memory for the section that reads it)."""

    truth_t: np.ndarray
    truth_pos: np.ndarray
    layout: dict[str, Any]
    samples: int
    files: list[SimFile] = field(default_factory=list)
    outages: list[dict[str, Any]] = field(default_factory=list)
    """Entries for the layout's ``outages`` list (system, start_s, duration_s)."""
    uses_geodetic_origin: bool = False
    """The system's data is geodetic (GNSS): the layout needs the scenario's origin."""


@dataclass(frozen=True)
class SystemKind:
    """A ``systems.<name>.kind``: its scenario section model, its simulation function
    (name, validated section, context) → :class:`SystemOutput`, and the plugin whose layout
    section it writes. ``aids``: an aiding kind (a UWB tag), simulated after the systems
    whose truth it needs."""

    kind: str
    config: type[BaseModel]
    simulate: Callable[[str, Any, SimContext], SystemOutput]
    plugin: str
    aids: bool = False


def layout_section(config: BaseModel) -> dict[str, Any]:
    """A plugin config model as the plain layout section written into config.yaml: the
    fields that were set, JSON types (paths as strings, tuples as lists)."""
    return config.model_dump(mode="json", exclude_unset=True)
