"""A system's results as one labelled array set: an :class:`xarray.Dataset` (the optional
dependency xarray: ``pip install "bodyfusion[xarray]"``), for those who slice by time and state
names rather than by columns.

Dimensions and coordinates: ``t`` (s) the trajectory's epochs; ``t_covariance`` (s) the epochs
of the covariance history as the system stores it (the foot INS every sample, the hand PDR each
step and update), with ``state`` and ``state_other`` its error states' names; ``t_truth`` (s) the
truth epochs where the system is scored. Every variable's ``attrs`` give its ``units``; the
dataset's ``attrs`` the navigation frame (JSON) and the system's name.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import numpy as np

from bodyfusion.base.extras import import_optional
from bodyfusion.base.types import Trajectory
from bodyfusion.core.system import SensorSystem
from bodyfusion.evaluation.metrics import SystemScore
from bodyfusion.results.frames import TRAJECTORY_EXTRAS

if TYPE_CHECKING:
    import xarray as xr

_UNITS = {"east_m": "m", "north_m": "m", "up_m": "m", "sd_east_m": "m", "sd_north_m": "m", "sd_up_m": "m",
          "cov_east_north_m2": "m^2", "v_east_mps": "m/s", "v_north_mps": "m/s", "v_up_mps": "m/s",
          "heading_deg": "deg (azimuth, clockwise from North)", "pitch_deg": "deg", "roll_deg": "deg",
          "horizontal_error_m": "m", "vertical_error_m": "m",
          "covariance": "the states' units squared (NaN: not stored)"}


def system_dataset(name: str, system: SensorSystem, traj: Trajectory, score: SystemScore | None,
                   frame: dict) -> xr.Dataset:
    """System ``name``'s trajectory (position, its σ and east–north covariance, velocity and
    attitude where it estimates them), its covariance history and, where scored, its errors
    against truth (module docstring)."""
    xr = import_optional("xarray", "xarray", "exporting a result to xarray")
    data: dict[str, tuple] = {
        "east_m": ("t", traj.pos_n[:, 0]), "north_m": ("t", traj.pos_n[:, 1]), "up_m": ("t", traj.pos_n[:, 2]),
        "sd_east_m": ("t", traj.pos_sd[:, 0]), "sd_north_m": ("t", traj.pos_sd[:, 1]),
        "sd_up_m": ("t", traj.pos_sd[:, 2]), "cov_east_north_m2": ("t", traj.horizontal_covariance()[:, 0, 1])}
    states = system.states()
    if len(states.get("t", ())) == len(traj.t):
        data.update({k: ("t", np.asarray(states[k])) for k in TRAJECTORY_EXTRAS if k in states})
    history = system.covariance_history()
    data["covariance"] = (("t_covariance", "state", "state_other"), history.matrix)
    coords = {"t": traj.t, "t_covariance": history.t, "state": list(history.states),
              "state_other": list(history.states)}
    if score is not None:
        data["horizontal_error_m"] = ("t_truth", score.horizontal_error_m)
        data["vertical_error_m"] = ("t_truth", score.vertical_error_m)
        coords["t_truth"] = score.t
    ds = xr.Dataset(data, coords=coords,
                    attrs={"system": name, "frame": json.dumps(frame), "covariance_stored": history.stored})
    for key, unit in _UNITS.items():
        if key in ds:
            ds[key].attrs["units"] = unit
    for key in ("t", "t_covariance", "t_truth"):
        if key in ds.coords:
            ds[key].attrs["units"] = "s"
    return ds
