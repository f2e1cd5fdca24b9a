"""bodyfusion plugin: a barometric altimeter (``plugin: barometer``).

The entry point ``fusion.plugins: barometer = "fusion_barometer"`` points at this
module; it implements the one hook, :func:`fusion_system_classes`.
"""

from fusion.plugins import hookimpl
from fusion_barometer.system import Barometer

__all__ = ["Barometer", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [Barometer]
