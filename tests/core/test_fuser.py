"""The central fuser: constraints enforced at sync epochs, corrections spread to full states."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bodyfusion.core.constraints import (
    DistanceConstraint,
    ProjectionSolver,
    constrained_covariance,
    solve_projection,
)
from bodyfusion.core.constraints.truncation import DensityTruncation, truncated_moments
from bodyfusion.core.fuser import spread_correction
from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run, run_layout
from bodyfusion.sim import simulate
from tests.paths import ROOT

WALKERS = ROOT / "configs" / "paper_constraint_monte_carlo.yaml"
VICON = ROOT / "configs" / "dual_foot_vicon.yaml"
TIGHT = "constraints.0.distance_m=0.55"
"""A limit the Vicon walk's estimates break now and then (its truth's feet part by up to 0.52 m)."""


def walkers(method: str, seconds: float, seed: int = 0):
    overrides = [f"fuser.method={method}", f"systems.system_1.duration_s={seconds}",
                 f"systems.system_2.duration_s={seconds}"]
    return run_layout(load_layout(WALKERS, overrides), seed=seed)


def horizontal_separation(result) -> np.ndarray:
    a, b = (result.trajectories[n].pos_n for n in ("system_1", "system_2"))
    return np.hypot(*(a - b)[:, :2].T)


def test_maximum_separation_holds_after_every_epoch():
    result = walkers("projection", 20.0)
    assert result.fuser.epochs == 2000
    # the truncation cuts the estimates' tails before their means cross the limit
    assert result.fuser.activations + result.fuser.tail_truncations > 100
    assert horizontal_separation(result).max() <= 1.5 + 1e-6
    assert result.fuser.max_violation_after_m < 1e-6


@pytest.mark.slow
def test_constraint_averages_two_independent_random_walks():
    """Errors ≫ d: the constrained pair tends to the mean of the two, RMSE × 1/√2."""
    before, after = [], []
    for seed in range(8):
        for method, out in (("none", before), ("projection", after)):
            res = walkers(method, 60.0, seed)
            for name, system in res.systems.items():
                err = res.trajectories[name].pos_n[-1, :2] - system.truth_pos_n[-1, :2]
                out.append(err @ err)
    ratio = np.sqrt(np.mean(after) / np.mean(before))
    assert 0.5 < ratio < 0.9, ratio


def test_unconstrained_method_changes_nothing():
    a = walkers("none", 5.0)
    assert a.fuser.epochs == 0
    b = walkers("projection", 5.0)
    assert not np.array_equal(a.trajectories["system_1"].pos_n, b.trajectories["system_1"].pos_n)


@pytest.mark.parametrize("method", ["qp", "socp"])
def test_every_method_gives_the_projection_trajectory_on_the_vicon_walk(method):
    # 0.55 m (the truth's feet part by up to 0.52 m): a limit the estimates break now and then
    ref = run_layout(load_layout(VICON, ["fuser.method=projection", TIGHT]))
    other = run_layout(load_layout(VICON, [f"fuser.method={method}", TIGHT]))
    assert other.fuser.activations == ref.fuser.activations > 0
    assert other.fuser.solver_fallbacks == 0
    for name in ref.trajectories:
        np.testing.assert_allclose(other.trajectories[name].pos_n, ref.trajectories[name].pos_n, atol=1e-5)


def joint(covs: list[np.ndarray]) -> np.ndarray:
    n = sum(c.shape[0] for c in covs)
    out, k = np.zeros((n, n)), 0
    for c in covs:
        out[k:k + len(c), k:k + len(c)] = c
        k += len(c)
    return out


def random_spd(rng: np.random.Generator, n: int, floor: float) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + floor * np.eye(n)


def test_spread_correction_of_position_only_states_is_the_position_projection():
    rng = np.random.default_rng(1)
    sigma = joint([random_spd(rng, 3, 0.1), random_spd(rng, 3, 0.1)])
    p_hat = np.array([0.0, 0.0, 0.0, 2.0, 0.5, 0.1])
    sol = solve_projection(p_hat, sigma, [DistanceConstraint(0, 1, "max", 1.0)])
    dx, P_new = spread_correction(sigma, np.arange(6), sol)
    np.testing.assert_allclose(dx, sol.p - p_hat, atol=1e-10)
    np.testing.assert_allclose(P_new, constrained_covariance(sigma, sol.gain), atol=1e-10)


def test_spread_correction_moves_correlated_states_by_regression():
    """A velocity correlated with position moves by P_vp P_pp⁻¹ δp; P stays symmetric PSD."""
    rng = np.random.default_rng(2)
    covs = [random_spd(rng, 6, 0.01), random_spd(rng, 6, 0.01)]
    P = joint(covs)
    pos = np.array([0, 1, 2, 6, 7, 8])
    p_hat = np.array([0.0, 0.0, 0.0, 3.0, 0.0, 0.0])
    sol = solve_projection(p_hat, P[pos][:, pos], [DistanceConstraint(0, 1, "max", 1.0)])
    dx, P_new = spread_correction(P, pos, sol)
    for k, C in enumerate(covs):
        dp = sol.p[3 * k:3 * k + 3] - p_hat[3 * k:3 * k + 3]
        block = dx[6 * k:6 * k + 6]
        np.testing.assert_allclose(block[:3], dp, atol=1e-10)
        np.testing.assert_allclose(block[3:], C[3:, :3] @ np.linalg.solve(C[:3, :3], dp), atol=1e-9)
    np.testing.assert_allclose(P_new, P_new.T, atol=1e-12)
    assert np.linalg.eigvalsh(P_new).min() > -1e-10


def test_a_limit_the_truth_obeys_does_not_disturb_error_free_feet_under_the_projection(tmp_path):
    """The projection acts only where the estimates break the limit. (The truncation also cuts
    the tail of their density beyond it, which moves estimates whose covariance exceeds their
    error — these have none — by the cut tail's mean.)"""
    config = simulate(ROOT / "configs" / "sim_perfect_walk.yaml", tmp_path, seed=0).config_path
    free = run_layout(load_layout(config, ["heading_alignment.continuous=false"]))
    truth = free.truths
    t = truth["left_foot"].t
    sep = np.hypot(*(truth["left_foot"].pos_n - np.array([np.interp(t, truth["right_foot"].t, c)
                                                           for c in truth["right_foot"].pos_n.T]).T)[:, :2].T)
    limit = float(np.round(sep.max() + 0.05, 2))
    constrained = run_layout(load_layout(config, [
        "fuser.method=projection", "fuser.inequality=projection", "heading_alignment.continuous=false",
        f"constraints=[{{between: [left_foot, right_foot], kind: max, distance_m: {limit}}}]"]))
    for name, score in constrained.scores.items():
        assert score.metrics["horizontal_error_m"]["max"] < 0.01, name


def test_run_writes_the_constraints_block(tmp_path):
    _, out = run(VICON, [TIGHT], tmp_path)
    block = json.loads((out / "metrics.json").read_text())["constraints"]
    for key in ("method", "epochs", "activations", "solver_fallbacks", "max_violation_after_m", "solve_time_us"):
        assert key in block
    assert block["method"] == "projection"
    assert block["activations"] > 0
    assert block["max_violation_after_m"] < 1e-6
    assert set(block["solve_time_us"]) == {"median", "p99"}


def test_tracking_cross_covariances_keeps_the_filter_consistent():
    """Dropping the cross-covariances a constraint creates makes both systems overconfident
    (NEES ≫ 2); tracking them keeps the NEES near 2, with the same estimates."""
    nees = {}
    for tracked in (False, True):
        values = []
        for seed in range(4):
            res = run_layout(load_layout(WALKERS, [
                "fuser.method=projection", f"fuser.cross_covariance={str(tracked).lower()}",
                "systems.system_1.duration_s=30", "systems.system_2.duration_s=30"]), seed=seed)
            for system in res.systems.values():
                values.append(system.horizontal_nees()[1500:])
        nees[tracked] = float(np.nanmean(np.concatenate(values)))
    assert nees[False] > 20
    assert 1.0 < nees[True] < 4.0


def test_cross_covariance_tracking_runs_with_foot_systems():
    # a limit tighter than the walk's (its feet part by up to 0.52 m), so that it acts
    res = run_layout(load_layout(VICON, ["fuser.cross_covariance=true", "constraints.0.distance_m=0.4"]))
    assert res.fuser.activations > 0
    for system in res.systems.values():
        assert np.linalg.eigvalsh(system.P).min() > -1e-12


def test_positions_only_correction_leaves_the_other_states_and_their_variances():
    rng = np.random.default_rng(3)
    covs = [random_spd(rng, 6, 0.01), random_spd(rng, 6, 0.01)]
    P = joint(covs)
    pos = np.array([0, 1, 2, 6, 7, 8])
    sol = solve_projection(np.array([0.0, 0, 0, 3.0, 0, 0]), P[pos][:, pos], [DistanceConstraint(0, 1, "max", 1.0)])
    dx_all, P_all = spread_correction(P, pos, sol)
    dx, P_new = spread_correction(P, pos, sol, positions_only=True)
    others = np.array([3, 4, 5, 9, 10, 11])
    np.testing.assert_array_equal(dx[others], 0.0)
    np.testing.assert_allclose(dx[pos], dx_all[pos], atol=1e-12)
    np.testing.assert_allclose(P_new[np.ix_(others, others)], P[np.ix_(others, others)], atol=1e-12)
    assert np.linalg.eigvalsh(P_new).min() > -1e-10


@pytest.mark.parametrize("violation_sd", [-1.0, 0.3, 1.5, 2.5])
def test_truncation_gives_the_moments_of_the_density_cut_at_the_bound(violation_sd):
    """Two positions 100 m apart (the bound nearly linear over their spread) whose separation
    σ is 0.6 m, a ``max`` limit the estimate violates by ``violation_sd`` σ (−1: inside, the
    solver finds it inactive, but a sixth of the density lies beyond it): the corrected mean
    and covariance of both positions match the Monte-Carlo moments of the Gaussian with the
    infeasible samples cut away (the projection, which puts the mean on the bound, misses them
    by 0.2–0.3 m, and leaves the inactive case as it was)."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    Sigma = 0.02 * A @ A.T + np.diag([0.1, 0.1, 0.01, 0.05, 0.05, 0.01])
    p_hat = np.array([0.0, 0.0, 0.0, 100.0, 10.0, 0.0])
    g = np.zeros(6)
    g[0:2], g[3:5] = -p_hat[3:5] / np.linalg.norm(p_hat[3:5]), p_hat[3:5] / np.linalg.norm(p_hat[3:5])
    s = np.sqrt(g @ Sigma @ g)
    limit = np.linalg.norm(p_hat[3:5]) - violation_sd * s
    cons = [DistanceConstraint(0, 1, "max", limit)]
    sol = ProjectionSolver(2, cons).solve(p_hat, Sigma)
    assert bool(sol.active) == (violation_sd > 0)
    dx, P, _ = DensityTruncation(cons, 2).correct(Sigma, np.arange(6), p_hat, sol)
    draws = rng.multivariate_normal(p_hat, Sigma, size=1_000_000)
    kept = draws[np.linalg.norm(draws[:, 3:5] - draws[:, 0:2], axis=1) <= limit]
    assert kept.shape[0] > 5000
    np.testing.assert_allclose(p_hat + dx, kept.mean(axis=0), atol=0.02)  # Monte-Carlo noise: 0.6 m / √5000
    np.testing.assert_allclose(P, np.cov(kept.T), atol=0.02)
    assert np.linalg.eigvalsh(P).min() > 0
    if sol.active:
        dx_projected, _ = spread_correction(Sigma, np.arange(6), sol)
        assert np.abs(p_hat + dx_projected - kept.mean(axis=0)).max() > 0.1


def test_a_positions_only_truncation_is_the_joseph_update_of_the_masked_gain():
    """Two 6-state systems (position, velocity), a ``max`` limit broken by 1 σ: with
    ``positions_only`` the velocities keep their estimate and covariance, and P* is the
    Joseph form (I − K h) P (I − K h)ᵀ + R K Kᵀ of the gain with its velocity rows zeroed."""
    rng = np.random.default_rng(5)
    A = rng.normal(size=(12, 12))
    P = 0.02 * A @ A.T + 0.01 * np.eye(12)
    pos = np.array([0, 1, 2, 6, 7, 8])
    p_hat = np.array([0.0, 0.0, 0.0, 1.0, 0.2, 0.0])
    h_p = np.concatenate([-p_hat[3:] / np.linalg.norm(p_hat[3:]), p_hat[3:] / np.linalg.norm(p_hat[3:])])
    s2 = h_p @ P[np.ix_(pos, pos)] @ h_p
    cons = [DistanceConstraint(0, 1, "max", float(np.linalg.norm(p_hat[3:]) - np.sqrt(s2)))]
    sol = ProjectionSolver(2, cons).solve(p_hat, P[np.ix_(pos, pos)])
    assert sol.active
    dx, P_new, _ = DensityTruncation(cons, 2, positions_only=True).correct(P, pos, p_hat, sol)
    others = np.setdiff1d(np.arange(12), pos)
    assert not dx[others].any()
    np.testing.assert_allclose(P_new[np.ix_(others, others)], P[np.ix_(others, others)], atol=1e-15)
    h = np.zeros(12)
    h[pos] = sol.jacobian[0]
    s2 = h @ P @ h
    beta = (h[pos] @ (sol.p - p_hat)) / np.sqrt(s2)
    _, var_t = truncated_moments(beta)
    V = s2 * var_t
    K = P @ h * (s2 - V) / s2**2
    K[others] = 0.0
    IKH = np.eye(12) - np.outer(K, h)
    np.testing.assert_allclose(P_new, IKH @ P @ IKH.T + V * s2 / (s2 - V) * np.outer(K, K), atol=1e-13)
    assert np.linalg.eigvalsh(P_new).min() > 0


def test_a_limit_far_beyond_the_estimates_density_is_not_truncated():
    Sigma = 0.001 * np.eye(6)
    p_hat = np.array([0.0, 0.0, 0.0, 0.5, 0.0, 0.0])
    cons = [DistanceConstraint(0, 1, "max", 1.0), DistanceConstraint(0, 1, "min", 0.05)]
    sol = ProjectionSolver(2, cons).solve(p_hat, Sigma)
    dx, P, tail = DensityTruncation(cons, 2).correct(Sigma, np.arange(6), p_hat, sol)
    assert not sol.active and not tail.any() and not dx.any()
    np.testing.assert_array_equal(P, Sigma)  # 0.45 m and more from either limit, σ 0.045 m: β ≥ 10


def test_truncated_moments_are_stable_in_both_tails():
    mean, var = truncated_moments(40.0)  # nothing cut
    assert mean == pytest.approx(0.0, abs=1e-12) and var == pytest.approx(1.0)
    mean, var = truncated_moments(-40.0)  # all but the edge cut: the bound itself
    assert mean == pytest.approx(-40.0, rel=1e-3) and 0.0 <= var < 1e-3
    mean, var = truncated_moments(-1e30)  # an estimate 1e6 m beyond a 1 µm σ: no overflow
    assert mean == pytest.approx(-1e30) and 0.0 <= var < 1e-59
    (m0, v0), (m1, v1) = truncated_moments(-29.999), truncated_moments(-30.001)  # either side of the switch
    assert m0 == pytest.approx(m1, rel=1e-4) and v0 == pytest.approx(v1, abs=1e-5)


def test_an_equality_is_the_projection_under_truncation_too():
    rng = np.random.default_rng(4)
    A = rng.normal(size=(6, 6))
    Sigma = 0.05 * A @ A.T + 0.01 * np.eye(6)
    p_hat = np.array([0.0, 0.0, 0.0, 1.2, 0.3, 0.0])
    cons = [DistanceConstraint(0, 1, "fixed", 1.0)]
    sol = ProjectionSolver(2, cons).solve(p_hat, Sigma)
    dx_t, P_t, _ = DensityTruncation(cons, 2).correct(Sigma, np.arange(6), p_hat, sol)
    dx_p, P_p = spread_correction(Sigma, np.arange(6), sol)
    np.testing.assert_allclose(dx_t, dx_p, atol=1e-9)
    np.testing.assert_allclose(P_t, P_p, atol=1e-9)
