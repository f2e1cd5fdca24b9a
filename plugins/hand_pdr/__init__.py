"""Built-in plugin: a hand-held phone running PDR corrected by GNSS."""

from fusion.plugins import hookimpl
from fusion_plugins.hand_pdr.system import HandPdr

__all__ = ["HandPdr", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [HandPdr]
