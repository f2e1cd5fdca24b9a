"""Built-in plugin: a UWB tag ranging to fixed anchors and to tags on other systems."""

from bodyfusion.core.registry import hookimpl
from bodyfusion.plugins.uwb.system import UwbTag

__all__ = ["UwbTag", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [UwbTag]
