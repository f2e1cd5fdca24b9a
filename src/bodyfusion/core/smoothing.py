"""Smoothing after the fuser: each system's own smoother, then (by default) the layout's distance
constraints on the smoothed tracks.

The core knows no smoother: it calls the :meth:`~bodyfusion.core.capabilities.Smoothing.smooth`
hook of every system that offers one with the layout's ``smoother`` section (the foot INS: RTS,
FB, FB-RTS), which returns its diagnostics, or None when it did not smooth. With
``smoother.constrain_smoothed`` the constraints are applied once more to the smoothed trajectories
(:func:`constrain_trajectories`), in position space, with the fuser's solver.
"""

from __future__ import annotations

from collections.abc import Mapping, Set
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

from bodyfusion.base.interrupts import deferred
from bodyfusion.base.errors import FusionError
from bodyfusion.core.capabilities import Smoothing, offers
from bodyfusion.core.constraints import violations
from bodyfusion.core.constraints.solvers import constraint_solver, distance_constraints
from bodyfusion.core.joint_smoothing import JointCorrections, smooth_jointly
from bodyfusion.core.layout import ConstraintConfig, FuserConfig, SmootherConfig
from bodyfusion.core.system import SensorSystem
from bodyfusion.base.types import LOG, Trajectory


def smoothing_systems(systems: Mapping[str, SensorSystem]) -> dict[str, SensorSystem]:
    """The systems that smooth their own run (:class:`~bodyfusion.core.capabilities.Smoothing`)."""
    return {name: s for name, s in systems.items() if offers(s, Smoothing)}


def plan_smoothing(systems: Mapping[str, SensorSystem], cfg: SmootherConfig) -> None:
    """Before the run, tell every system that smooths the layout's smoother
    (:meth:`~bodyfusion.core.capabilities.Smoothing.plan_smoothing`: the foot INS then records
    what its smoother needs as it runs)."""
    for system in smoothing_systems(systems).values():
        system.plan_smoothing(cfg)


def smooth_jointly_or_say_why(systems: Mapping[str, SensorSystem], cfg: SmootherConfig,
                              corrections: JointCorrections) -> tuple[dict[str, dict], str | None]:
    """The joint RTS of the fuser's joint state (:mod:`bodyfusion.core.joint_smoothing`) when every
    member can take part: ({member: its diagnostics}, None); else ({}, why not)."""
    try:
        members = {}
        for name in corrections.names:
            if name not in systems:
                raise FusionError(f"{name} cannot be smoothed")
            try:
                members[name] = systems[name].joint_smoothing_member(cfg)
            except FusionError as err:
                raise FusionError(f"{name}: {err}") from None
        return smooth_jointly(members, corrections), None
    except FusionError as err:
        LOG.info("smoothing each system on its own: %s", err)
        return {}, str(err)


def smooth_systems(systems: Mapping[str, SensorSystem], cfg: SmootherConfig,
                   corrections: JointCorrections | None = None) -> dict[str, dict]:
    """Smooth every system that smooths; returns {system: its smoothing diagnostics}, in the
    layout's order. With the fuser's ``corrections`` of a tracked joint state, its members are
    smoothed together first (:func:`smooth_jointly_or_say_why`; why not, where they cannot, is
    in each system's diagnostics under ``joint_skipped``). Systems that smooth in a thread
    (:attr:`~bodyfusion.core.capabilities.Smoothing.smooths_in_a_thread`) are smoothed at the
    same time, one thread each; the others here, one after another. A signal taken meanwhile is
    answered once every smoother is done (:func:`~bodyfusion.base.interrupts.deferred`): raised
    while a thread waits on a lock the main thread holds, it would leave them both waiting."""
    systems = smoothing_systems(systems)
    joint, why_not = smooth_jointly_or_say_why(systems, cfg, corrections) if corrections is not None else ({}, None)
    alone = {name: system for name, system in systems.items() if name not in joint}
    threaded = [name for name, system in alone.items() if system.smooths_in_a_thread]
    done = dict(joint)
    with deferred(), ThreadPoolExecutor(max_workers=max(1, len(threaded) - 1)) as pool:
        futures = {name: pool.submit(systems[name].smooth, cfg) for name in threaded[1:]}
        for name, system in alone.items():
            if name not in futures:
                done[name] = system.smooth(cfg)
        done |= {name: future.result() for name, future in futures.items()}
    if why_not is not None:
        for diagnostics in done.values():
            if diagnostics is not None:
                diagnostics["joint_skipped"] = why_not
    return {name: done[name] for name in systems if done[name] is not None}


def constrain_trajectories(trajectories: Mapping[str, Trajectory], smoothed: Set[str],
                           constraints: list[ConstraintConfig], fuser: FuserConfig) -> tuple[dict[str, Trajectory], dict]:
    """The smoothed tracks with the layout's distance constraints enforced: on the first
    constrained system's sample times, at every sample where they are violated, the
    position-space solve (the fuser's solver, projection when the fuser is off) with each
    track's position variances (m²); corrections interpolated back to each system's times.
    Every constrained system must be among ``smoothed`` (else nothing is done). Returns the
    trajectories (constrained ones replaced) and counts for metrics.json. Never fails a run:
    a solver error is counted and the tracks are left as they were."""
    order = list(dict.fromkeys(name for c in constraints for name in c.between))
    out = dict(trajectories)
    if any(name not in smoothed for name in order):
        return out, {"constrained_samples": 0, "skipped": "not every constrained system was smoothed"}
    method = fuser.method if fuser.method != "none" else "projection"
    try:
        cons = distance_constraints(constraints, order)
        solver = constraint_solver(method, len(order), cons, fuser)
        trajs = [trajectories[name] for name in order]
        grid = trajs[0].t
        pos = np.column_stack([np.interp(grid, tr.t, tr.pos_n[:, ax]) for tr in trajs for ax in range(3)])
        var = np.column_stack([np.interp(grid, tr.t, tr.pos_sd[:, ax] ** 2) for tr in trajs for ax in range(3)])
        corr = np.zeros_like(pos)
        count = 0
        for i in range(grid.size):
            if np.max(violations(pos[i], cons), initial=0.0) <= fuser.tolerance_m:
                continue
            corr[i] = solver.solve(pos[i], np.diag(np.maximum(var[i], 1e-12))).p - pos[i]
            count += 1
    except Exception as err:  # noqa: BLE001 - a post-processing step never fails the run
        LOG.warning("constraints on the smoothed tracks failed: %s", err)
        return out, {"constrained_samples": 0, "error": f"{type(err).__name__}: {err}"}
    for k, name in enumerate(order):
        tr = trajectories[name]
        dp = np.column_stack([np.interp(tr.t, grid, corr[:, 3 * k + ax]) for ax in range(3)])
        out[name] = replace(tr, pos_n=tr.pos_n + dp)
    return out, {"constrained_samples": count, "method": method}
