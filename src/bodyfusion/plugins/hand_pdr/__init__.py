"""Built-in plugin: a hand-held phone running PDR corrected by GNSS."""

from typing import Any

from bodyfusion.core.registry import hookimpl
from bodyfusion.plugins.hand_pdr.system import HandPdr

__all__ = ["HandPdr", "fusion_simulation_kinds", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [HandPdr]


@hookimpl
def fusion_simulation_kinds() -> list[Any]:
    from bodyfusion.plugins.hand_pdr.simulation import SIMULATION_KINDS  # the simulator loads only to simulate

    return SIMULATION_KINDS
