"""A layout's systems built and their frame set up: the run's context (gravity, latitude, seed,
outages), one system or aiding source per layout entry (found through the plugin registry), the
ENU frame (its geodetic origin and heading reference), and the truth tracks read in that frame."""

from __future__ import annotations

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.forking import Forked
from bodyfusion.base.types import NavigationFrame, TruthTrack
from bodyfusion.core import registry as plugin_registry
from bodyfusion.core.heading import heading_reference, with_heading
from bodyfusion.core.layout import LoadedLayout
from bodyfusion.core.system import AidingSource, LayoutContext, SensorSystem
from bodyfusion.nav.earth import normal_gravity
from bodyfusion.runner.truth import read_truth


def layout_context(loaded: LoadedLayout, seed: int = 0, compiling_ahead: dict[str, Forked] | None = None,
                   growing: bool = False) -> LayoutContext:
    """The run's :class:`~bodyfusion.core.system.LayoutContext` (``compiling_ahead``: on a first
    run, the processes compiling ahead so far, for the systems to add theirs to; ``growing``: the
    recordings are a live run's first part)."""
    lay = loaded.layout
    g = lay.gravity_mps2 if lay.gravity_mps2 is not None else normal_gravity(lay.latitude_deg, lay.height_m)
    outages: dict[str, tuple[tuple[float, float], ...]] = {}
    for o in lay.outages:
        outages[o.system] = (*outages.get(o.system, ()), (o.start_s, o.duration_s))
    return LayoutContext(gravity_mps2=g, latitude_deg=lay.latitude_deg, base_dir=loaded.base_dir,
                         seed=seed, geodetic_origin=lay.geodetic_origin, outages=outages,
                         compiling_ahead=compiling_ahead, growing=growing)


def build_systems(loaded: LoadedLayout, context: LayoutContext) -> dict[str, SensorSystem | AidingSource]:
    """One system (or aiding source) per layout entry; a plugin's config error is reported
    against the layout file."""
    registry = plugin_registry.get_registry()
    systems = {}
    for name, cfg in loaded.system_configs.items():
        try:
            systems[name] = registry.system_class(cfg.plugin)(name, cfg, context)
        except ConfigError as err:
            if err.path is not None:
                raise
            raise ConfigError(err.key, err.reason, loaded.path) from None
    return systems


def geodetic_origin(loaded: LoadedLayout, systems: dict[str, SensorSystem]) -> tuple[float, float, float] | None:
    """The ENU frame's origin: the layout's, else the first system's that has one (its first fix)."""
    if loaded.layout.geodetic_origin is not None:
        return loaded.layout.geodetic_origin
    return next((s.geodetic_origin for s in systems.values() if s.geodetic_origin is not None), None)


def navigation_frame(loaded: LoadedLayout, systems: dict[str, SensorSystem],
                     origin: tuple[float, float, float] | None) -> NavigationFrame:
    """The run's frame: ENU about ``origin``; azimuths from North where the heading reference
    (:func:`~bodyfusion.core.heading.heading_reference`) has a geographic heading or one set in
    the layout, else from that reference system's initial heading (``unknown``: no system has a
    heading, and the positions are as the data give them)."""
    ref = heading_reference(systems, loaded.layout.heading_alignment)
    if ref is None:
        return NavigationFrame(origin, "north" if origin is not None else "unknown")
    system = with_heading(systems)[ref]
    return NavigationFrame(origin, ref if system.heading_is_auto and not system.heading_is_absolute else "north")


def load_truth(loaded: LoadedLayout, origin: tuple[float, float, float] | None = None) -> dict[str, TruthTrack]:
    """The layout's truth tracks (:func:`bodyfusion.runner.truth.read_truth`); an error names the layout file."""
    truth = loaded.layout.truth
    if truth is None:
        return {}
    try:
        return read_truth(truth, origin, loaded.layout.systems)
    except ConfigError as err:
        if err.path is not None:
            raise
        raise ConfigError(err.key, err.reason, loaded.path) from None
