"""The fuser's compiled kernels compiled ahead, beside the run, on a machine's first run.

On an empty numba cache a run compiles every kernel it calls, one after the other: the
systems' while it builds them and runs to the first constraint epoch (the foot INS: ~12 s),
then the fuser's — the constraint solve, the density truncation, the covariance checks (~6 s).
The core knows its own kernels, so :func:`compile_fuser_ahead` calls the cheapest of them
first and, when numba compiled it rather than loading it from its cache, forks a process
(:class:`~bodyfusion.base.forking.Forked`) that compiles the others into the cache — it solves
and truncates a violated constraint of the layout with the layout's solver and checks a few
covariances — while this process compiles the systems'. Systems add their own to the run's
:attr:`~bodyfusion.core.system.LayoutContext.compiling_ahead`; the run waits for all of them
once the systems are built (:func:`finish_compiling_ahead`), and numba loads those kernels
from the cache when they are first called. The compiled code is the same either way; a run on a filled cache, a
process that has loaded the kernels already, or one where forking is not safe forks nothing.
"""

from __future__ import annotations

import logging

import numpy as np

from bodyfusion.base.forking import Forked, fork_is_safe
from bodyfusion.core.constraints.kernels import _all_finite
from bodyfusion.core.constraints.truncation import DensityTruncation
from bodyfusion.core.constraints.solvers import constraint_solver, distance_constraints
from bodyfusion.core.layout import Layout
from bodyfusion.nav.kalman import gated_update
from bodyfusion.nav.filter_health import CovarianceHealth

log = logging.getLogger(__name__)

FIRST_RUN_NOTICE = "compiling the navigation kernels, once: about 10-20 s; later runs load them and start at once"
"""What a first run says (at INFO on this module's logger, which the command line shows on a
terminal or with ``-v``) while it compiles."""


def compile_fuser_kernels(layout: Layout) -> None:
    """Call the kernels the fuser calls for ``layout``, with their argument types: its solver
    (``fuser.method``) on stacked positions that put every pair of constrained systems 2 d + 1 m
    apart (d: the largest limit; every maximum separation violated) and on coincident ones
    (every minimum violated), the density truncation of each solution when the fuser truncates,
    the covariance checks and the gated update of an aiding measurement or a heading tie. On a
    filled cache this loads them (~10 ms each): a live run does so at its start
    (:mod:`bodyfusion.live.engine`), not in the pass that first needs one."""
    health = CovarianceHealth()
    health.add_many(np.stack([np.eye(15), 2.0 * np.eye(15)]), np.array([0.0, 1.0]))
    gated_update(np.eye(3), np.array([1.0, 0.0, 0.0]), 1.0, 0.5, 10.0)
    if layout.fuser.method == "none" or not layout.constraints:
        return
    order = list(dict.fromkeys(name for c in layout.constraints for name in c.between))
    numeric = [c.model_copy(update={"distance_m": 1.0}) if c.distance_m == "body" else c for c in layout.constraints]
    limits = distance_constraints(numeric, order)  # a body limit's value does not change what compiles
    n = len(order)
    solver = constraint_solver(layout.fuser.method, n, limits, layout.fuser)
    truncation = DensityTruncation(limits, n, layout.fuser.correct == "positions")
    spacing = 2.0 * max(c.distance_m for c in limits) + 1.0
    pos = np.arange(3 * n, dtype=np.int64)
    P = 0.01 * np.eye(3 * n + 3)
    for gap in (spacing, 0.0):
        p_hat = np.zeros(3 * n)
        p_hat[0::3] = gap * np.arange(n)
        solution = solver.solve(p_hat, 0.01 * np.eye(3 * n))
        if layout.fuser.inequality == "truncation":
            truncation.correct(P, pos, p_hat, solution)


def _compile_quietly(layout: Layout) -> str | None:
    """:func:`compile_fuser_kernels`, its failure as text (compiling ahead never fails a run)."""
    try:
        compile_fuser_kernels(layout)
    except Exception as err:  # noqa: BLE001 - the run compiles what this did not
        return f"{type(err).__name__}: {err}"
    return None


def compile_fuser_ahead(layout: Layout) -> Forked | None:
    """On a first run (see the module docstring) the process compiling the fuser's kernels for
    ``layout``; None when there is nothing to compile ahead or forking is not safe."""
    if _all_finite.signatures:  # loaded in this process already
        return None
    _all_finite(np.zeros(3), np.eye(3))
    if not sum(_all_finite.stats.cache_misses.values()):  # loaded from the cache: so will the others be
        return None
    log.info(FIRST_RUN_NOTICE)
    return Forked(lambda: _compile_quietly(layout)) if fork_is_safe() else None


def finish_compiling_ahead(compiling_ahead: dict[str, Forked] | None) -> None:
    """Wait for every process compiling ahead for the run (the run's
    :attr:`~bodyfusion.core.system.LayoutContext.compiling_ahead`; None: none). A failure is
    logged: the run compiles what it did not."""
    for name, ahead in (compiling_ahead or {}).items():
        try:
            failure = ahead.result()
        except Exception as err:  # noqa: BLE001 - the process itself failed (killed, say)
            failure = f"{type(err).__name__}: {err}"
        if failure:
            log.debug("compiling %s ahead failed: %s", name, failure)
