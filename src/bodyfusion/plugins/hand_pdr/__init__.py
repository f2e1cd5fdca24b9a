"""Built-in plugin: a hand-held phone running PDR corrected by GNSS."""

from bodyfusion.core.registry import hookimpl
from bodyfusion.plugins.hand_pdr.system import HandPdr

__all__ = ["HandPdr", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [HandPdr]
