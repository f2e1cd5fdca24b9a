"""Built-in plugin: the foot-mounted INS with zero-velocity updates."""

from typing import Any

from bodyfusion.core.registry import hookimpl
from bodyfusion.plugins.foot_ins.system import FootIns

__all__ = ["FootIns", "fusion_simulation_kinds", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [FootIns]


@hookimpl
def fusion_simulation_kinds() -> list[Any]:
    from bodyfusion.plugins.foot_ins.simulation import SIMULATION_KINDS  # the simulator loads only to simulate

    return SIMULATION_KINDS
