"""Plugin system: pluggy hook specifications and the registry of sensor-system classes.

Built-in systems (package :mod:`bodyfusion.plugins`) are found exactly like third-party ones:
through the entry-point group ``bodyfusion.plugins`` (``fusion.plugins``, the group's name in
earlier releases, is read too). A plugin module
implements :func:`FusionHookSpec.fusion_system_classes` and returns its
:class:`bodyfusion.core.system.SensorSystem` subclasses.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import pluggy

from bodyfusion.base.errors import ConfigError

PROJECT = "bodyfusion"
ENTRY_POINT_GROUPS = ("bodyfusion.plugins", "fusion.plugins")
"""Entry-point groups searched for plugins: the current name first, then the earlier one."""

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


class FusionHookSpec:
    """Hooks a plugin may implement."""

    @hookspec
    def fusion_system_classes(self) -> list[type]:
        """Return the :class:`bodyfusion.core.system.SensorSystem` subclasses this plugin provides.

        Each class names itself in the layout by its ``plugin_name`` class attribute
        (``systems.<name>.plugin``) and validates its section with its ``Config`` model.
        """

    @hookspec
    def fusion_simulation_kinds(self) -> list[Any]:
        """Return the scenario system kinds this plugin simulates
        (:class:`bodyfusion.sim.context.SystemKind`: the ``kind`` name, its scenario section
        model, the function that simulates it and writes this plugin's layout section)."""


@dataclass(frozen=True)
class PluginInfo:
    """One discovered plugin: the system names it provides and where it came from."""

    systems: tuple[str, ...]
    module: str
    package: str
    version: str


class Registry:
    """Sensor-system classes by ``plugin_name``, collected from every registered plugin."""

    def __init__(self, pm: pluggy.PluginManager) -> None:
        self.pm = pm
        self._classes: dict[str, type] = {}
        self._origin: dict[str, str] = {}
        for plugin in pm.get_plugins():
            impl = getattr(plugin, "fusion_system_classes", None)
            if impl is None:
                continue
            for cls in impl():
                name = cls.plugin_name
                if name in self._classes and self._classes[name] is not cls:
                    raise ConfigError("plugins", f"two plugins provide system {name!r}: {self._origin[name]} and {pm.get_name(plugin)}")
                self._classes[name] = cls
                self._origin[name] = pm.get_name(plugin) or ""

    @property
    def names(self) -> list[str]:
        return sorted(self._classes)

    def simulation_kinds(self) -> dict[str, Any]:
        """Every plugin's simulated system kinds by ``kind`` name (a scenario's ``systems.<name>.kind``)."""
        kinds: dict[str, Any] = {}
        for batch in self.pm.hook.fusion_simulation_kinds():
            for kind in batch:
                if kind.kind in kinds:
                    raise ConfigError("plugins", f"two plugins simulate kind {kind.kind!r}")
                kinds[kind.kind] = kind
        return kinds

    def system_class(self, name: str, *, key: str = "plugin", path: str | Path | None = None) -> Any:
        """The class of plugin ``name`` (a layout's ``systems.<name>.plugin``); a ConfigError naming
        ``key`` when no plugin has that name, or the value is no name at all (a mapping, a list)."""
        if not isinstance(name, str):
            raise ConfigError(key, f"must be a plugin name (installed: {', '.join(self.names) or 'none'}), "
                                   f"got a {type(name).__name__}", path)
        try:
            return self._classes[name]
        except KeyError:
            raise ConfigError(key, f"unknown plugin {name!r} (installed: {', '.join(self.names) or 'none'})", path) from None

    def describe(self) -> list[PluginInfo]:
        """Each plugin with its source distribution and version (entry-point metadata)."""
        dists = {id(plugin): dist for plugin, dist in self.pm.list_plugin_distinfo()}
        out = []
        for plugin in self.pm.get_plugins():
            impl = getattr(plugin, "fusion_system_classes", None)
            if impl is None:
                continue
            dist = dists.get(id(plugin))
            package = dist.metadata["Name"] if dist is not None else "(registered in-process)"
            version = dist.version if dist is not None else "-"
            systems = tuple(sorted(cls.plugin_name for cls in impl()))
            out.append(PluginInfo(systems, getattr(plugin, "__name__", str(plugin)), package, version))
        return sorted(out, key=lambda p: p.systems)


def make_plugin_manager(load_entry_points: bool = True) -> pluggy.PluginManager:
    pm = pluggy.PluginManager(PROJECT)
    pm.add_hookspecs(FusionHookSpec)
    if load_entry_points:
        for group in ENTRY_POINT_GROUPS:
            pm.load_setuptools_entrypoints(group)
    return pm


@lru_cache(maxsize=1)
def get_registry() -> Registry:
    """The registry of every installed plugin (cached per process)."""
    return Registry(make_plugin_manager())
