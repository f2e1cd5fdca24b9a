"""Built-in plugin: the foot-mounted INS with zero-velocity updates."""

from fusion.plugins import hookimpl
from fusion_plugins.foot_ins.system import FootIns

__all__ = ["FootIns", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [FootIns]
