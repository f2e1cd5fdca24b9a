"""Built-in plugin: a UWB tag ranging to fixed anchors and to tags on other systems."""

from typing import Any

from bodyfusion.core.registry import hookimpl
from bodyfusion.plugins.uwb.system import UwbTag

__all__ = ["UwbTag", "fusion_simulation_kinds", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [UwbTag]


@hookimpl
def fusion_simulation_kinds() -> list[Any]:
    from bodyfusion.plugins.uwb.simulation import SIMULATION_KINDS  # the simulator loads only to simulate

    return SIMULATION_KINDS
