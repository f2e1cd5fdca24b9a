"""Built-in plugin: a synthetic dead-reckoning system whose position error is a random walk."""

from bodyfusion.core.registry import hookimpl
from bodyfusion.plugins.random_walk.system import RandomWalk

__all__ = ["RandomWalk", "fusion_system_classes"]


@hookimpl
def fusion_system_classes() -> list[type]:
    return [RandomWalk]
