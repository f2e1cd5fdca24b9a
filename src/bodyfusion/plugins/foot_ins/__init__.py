"""Built-in plugin: the foot-mounted INS with zero-velocity updates."""

from bodyfusion.core.registry import hookimpl
from bodyfusion.plugins.foot_ins.system import FootIns

__all__ = ["FootIns", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [FootIns]
