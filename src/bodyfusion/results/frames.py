"""A run's results as pandas DataFrames in long form, one set of column names for every plugin
(the methods of :class:`bodyfusion.results.run_result.RunResult` call these with its parts). Units are in the column
names (``_m``, ``_mps``, ``_deg``, ``_s``); positions are ENU in the navigation frame, before any
evaluation alignment, except the ``errors`` table's aligned estimate."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import pandas as pd

from bodyfusion.base.types import Trajectory, TruthTrack
from bodyfusion.core.constraint_log import ConstraintLog
from bodyfusion.core.system import Plugin, SensorSystem
from bodyfusion.evaluation.metrics import SystemScore

TRAJECTORY_EXTRAS = ("v_east_mps", "v_north_mps", "v_up_mps", "heading_deg", "pitch_deg", "roll_deg")
"""Columns of a system's :meth:`~bodyfusion.core.system.SensorSystem.states` that
:func:`trajectories` adds where the system has them (velocity, attitude)."""


def _long(parts: Iterable[tuple[str, Mapping[str, object]]], columns: Iterable[str]) -> pd.DataFrame:
    """One frame of ``system`` + columns from (name, equal-length columns) parts; a column a part
    lacks is NaN in its rows; with no part, the empty frame with ``columns``."""
    frames = [pd.DataFrame({"system": name, **dict(cols)}) for name, cols in parts if len(next(iter(cols.values()), ()))]
    if not frames:
        return pd.DataFrame(columns=["system", *columns])
    return pd.concat(frames, ignore_index=True)


def trajectories(tracks: Mapping[str, Trajectory], systems: Mapping[str, SensorSystem]) -> pd.DataFrame:
    """``system``, ``t`` (s), ``east_m``, ``north_m``, ``up_m``, their one-sigma ``sd_east_m``,
    ``sd_north_m``, ``sd_up_m`` and ``cov_east_north_m2``, then the velocity (``v_east_mps``...)
    and attitude (``heading_deg``, ``pitch_deg``, ``roll_deg``) where the system estimates them:
    every epoch of every system's trajectory (smoothed where smoothed), as trajectories.csv."""
    parts = []
    for name, traj in tracks.items():
        cols: dict[str, object] = {"t": traj.t, "east_m": traj.pos_n[:, 0], "north_m": traj.pos_n[:, 1],
                                   "up_m": traj.pos_n[:, 2], "sd_east_m": traj.pos_sd[:, 0],
                                   "sd_north_m": traj.pos_sd[:, 1], "sd_up_m": traj.pos_sd[:, 2],
                                   "cov_east_north_m2": traj.horizontal_covariance()[:, 0, 1]}
        states = systems[name].states()
        if len(states.get("t", ())) == len(traj.t):
            cols.update({k: states[k] for k in TRAJECTORY_EXTRAS if k in states})
        parts.append((name, cols))
    return _long(parts, ["t", "east_m", "north_m", "up_m", "sd_east_m", "sd_north_m", "sd_up_m",
                         "cov_east_north_m2"])


def truth(truths: Mapping[str, TruthTrack]) -> pd.DataFrame:
    """``system``, ``t`` (s), ``east_m``, ``north_m``, ``up_m`` of every truth track (ENU, m)."""
    return _long(((name, {"t": tr.t, "east_m": tr.pos_n[:, 0], "north_m": tr.pos_n[:, 1], "up_m": tr.pos_n[:, 2]})
                  for name, tr in truths.items()), ["t", "east_m", "north_m", "up_m"])


def errors(scores: Mapping[str, SystemScore]) -> pd.DataFrame:
    """At every truth epoch of every scored system: ``t`` (s), the estimate after the evaluation
    alignment (``east_m``, ``north_m``, ``up_m``), the truth (``truth_east_m``...), and the
    ``horizontal_error_m`` and ``vertical_error_m``."""
    parts = []
    for name, score in scores.items():
        est, ref = score.pos_est_aligned, score.pos_truth
        parts.append((name, {"t": score.t, "east_m": est[:, 0], "north_m": est[:, 1], "up_m": est[:, 2],
                             "truth_east_m": ref[:, 0], "truth_north_m": ref[:, 1], "truth_up_m": ref[:, 2],
                             "horizontal_error_m": score.horizontal_error_m,
                             "vertical_error_m": score.vertical_error_m}))
    return _long(parts, ["t", "horizontal_error_m", "vertical_error_m"])


def strides(systems: Mapping[str, SensorSystem]) -> pd.DataFrame:
    """``system`` and every foot system's strides (:meth:`~bodyfusion.core.system.SensorSystem.strides`)."""
    parts = [pd.DataFrame({"system": name, **cols}) for name, s in systems.items() if len(cols := s.strides())
             and len(cols["stride"])]
    columns = ["system", "stride", "t_start", "t_end", "length_m", "duration_s", "speed_mps"]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame({c: [] for c in columns})


def events(systems: Mapping[str, SensorSystem]) -> pd.DataFrame:
    """``system``, ``event`` (``stance``, ``step``), ``t`` and ``t_end`` (s), ``duration_s`` and,
    where the system measures it, ``length_m``: every system's gait events."""
    frame = _long(((name, s.events()) for name, s in systems.items()), ["event", "t", "t_end"])
    frame.insert(4, "duration_s", frame["t_end"] - frame["t"])
    return frame


def innovations(sources: Mapping[str, Plugin]) -> pd.DataFrame:
    """``system`` (or aiding source), ``t`` (s), ``aiding`` (the aiding type), ``nis`` (before
    any gate), ``dof``, ``accepted``, and a source's own columns (a range's ``end``): every update
    of every system and aiding source that records them."""
    return _long(((name, s.innovations()) for name, s in sources.items()), ["t", "aiding", "nis", "dof", "accepted"])


def constraint_events(log: ConstraintLog | None) -> pd.DataFrame:
    """One row per constraint per sync epoch: ``t`` (s), ``pair``, ``system_a``, ``system_b``,
    ``kind``, ``limit_m``, ``distance_before_m`` and ``distance_after_m`` (the constrained
    separation at the estimates and after the solve), ``multiplier`` (λ), ``active`` and
    ``tail_truncated`` (held, but the estimate's density crossed the limit and was cut there)."""
    columns = ["t", "pair", "system_a", "system_b", "kind", "limit_m", "distance_before_m", "distance_after_m",
               "multiplier", "active", "tail_truncated"]
    return pd.DataFrame(log.columns() if log is not None else {c: [] for c in columns}, columns=columns)
