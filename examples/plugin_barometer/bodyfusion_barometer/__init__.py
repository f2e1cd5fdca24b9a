"""bodyfusion plugin: a barometric altimeter (``plugin: barometer``).

The entry point ``bodyfusion.core.registry: barometer = "bodyfusion_barometer"`` points at this
module; it implements the one hook, :func:`fusion_system_classes`.
"""

from bodyfusion.core.registry import hookimpl
from bodyfusion_barometer.system import Barometer

__all__ = ["Barometer", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [Barometer]
