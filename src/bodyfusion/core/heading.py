"""One navigation frame for systems worn together.

IMUs on two feet are rarely mounted with the same yaw, and a heading set by hand is
rarely right. Systems whose layout says ``heading_deg: auto`` are rotated about their
start point so that their first ``distance_m`` of travel points the same way as the
reference system's. Azimuths are clockwise from North, radians.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from bodyfusion.core.layout import HeadingAlignmentConfig
from bodyfusion.base.errors import FusionError
from bodyfusion.core.system import SensorSystem


def wrap_angle(a: float) -> float:
    """Wrap to (−π, π]."""
    return float(-((-a + np.pi) % (2 * np.pi) - np.pi))


def align_headings(systems: Mapping[str, SensorSystem], cfg: HeadingAlignmentConfig) -> dict[str, float]:
    """Rotate every ``auto`` system onto the reference; returns the rotation applied (rad) per system."""
    auto = [name for name, s in systems.items() if s.heading_is_auto]
    if not auto:
        return {}
    ref, ref_azimuth = cfg.reference, None
    if ref is None:  # the first system with a fixed heading that travels far enough, else the first that does
        candidates = [n for n, s in systems.items() if not s.heading_is_auto] or list(systems)
        for name in candidates:
            ref_azimuth = systems[name].initial_travel_azimuth(cfg.distance_m)
            if ref_azimuth is not None:
                ref = name
                break
        if ref is None:
            raise FusionError(f"heading alignment: no system travels {cfg.distance_m} m to serve as reference")
    else:
        ref_azimuth = systems[ref].initial_travel_azimuth(cfg.distance_m)
    if ref_azimuth is None:
        raise FusionError(f"heading alignment: reference system {ref!r} never travels {cfg.distance_m} m")
    applied: dict[str, float] = {}
    for name in auto:
        if name == ref:
            continue
        azimuth = systems[name].initial_travel_azimuth(cfg.distance_m)
        if azimuth is None:
            raise FusionError(f"heading alignment: system {name!r} never travels {cfg.distance_m} m")
        delta = wrap_angle(ref_azimuth - azimuth)
        systems[name].rotate_initial_heading(delta)
        applied[name] = delta
    return applied
