"""The central fuser: constraints enforced at sync epochs, corrections spread to full states."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fusion.config import load_layout
from fusion.constraints import DistanceConstraint, constrained_covariance, solve_projection
from fusion.fuser import spread_correction
from fusion.run import run, run_layout
from fusion.sim import simulate

ROOT = Path(__file__).resolve().parents[1]
WALKERS = ROOT / "configs" / "paper_constraint_monte_carlo.yaml"
VICON = ROOT / "configs" / "dual_foot_vicon.yaml"


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
    assert result.fuser.activations > 100
    assert horizontal_separation(result).max() <= 1.5 + 1e-6
    assert result.fuser.max_violation_after_m < 1e-6


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
    ref = run_layout(load_layout(VICON, ["fuser.method=projection"]))
    other = run_layout(load_layout(VICON, [f"fuser.method={method}"]))
    assert other.fuser.activations == ref.fuser.activations > 0
    assert other.fuser.solver_fallbacks == 0
    for name in ref.trajectories:
        np.testing.assert_allclose(other.trajectories[name].pos_n, ref.trajectories[name].pos_n, atol=1e-5)


def test_spread_correction_of_position_only_states_is_the_position_projection():
    rng = np.random.default_rng(1)
    covs = []
    for _ in range(2):
        A = rng.normal(size=(3, 3))
        covs.append(A @ A.T + 0.1 * np.eye(3))
    p_hat = np.array([0.0, 0.0, 0.0, 2.0, 0.5, 0.1])
    c = [DistanceConstraint(0, 1, "max", 1.0)]
    sigma = np.zeros((6, 6))
    sigma[:3, :3], sigma[3:, 3:] = covs
    sol = solve_projection(p_hat, sigma, c)
    dxs, Ps = spread_correction(covs, [np.arange(3), np.arange(3)], sol)
    np.testing.assert_allclose(np.concatenate(dxs), sol.p - p_hat, atol=1e-10)
    full = constrained_covariance(sigma, sol.gain)
    np.testing.assert_allclose(Ps[0], full[:3, :3], atol=1e-10)
    np.testing.assert_allclose(Ps[1], full[3:, 3:], atol=1e-10)


def test_spread_correction_moves_correlated_states_by_regression():
    """A velocity correlated with position moves by P_vp P_pp⁻¹ δp; P stays symmetric PSD."""
    rng = np.random.default_rng(2)
    covs = []
    for _ in range(2):
        A = rng.normal(size=(6, 6))
        covs.append(A @ A.T + 0.01 * np.eye(6))
    idx = [np.arange(3), np.arange(3)]
    p_hat = np.array([0.0, 0.0, 0.0, 3.0, 0.0, 0.0])
    sigma = np.zeros((6, 6))
    sigma[:3, :3], sigma[3:, 3:] = covs[0][:3, :3], covs[1][:3, :3]
    sol = solve_projection(p_hat, sigma, [DistanceConstraint(0, 1, "max", 1.0)])
    dxs, Ps = spread_correction(covs, idx, sol)
    for k, (P, dx) in enumerate(zip(covs, dxs)):
        dp = sol.p[3 * k:3 * k + 3] - p_hat[3 * k:3 * k + 3]
        np.testing.assert_allclose(dx[:3], dp, atol=1e-10)
        np.testing.assert_allclose(dx[3:], P[3:, :3] @ np.linalg.solve(P[:3, :3], dp), atol=1e-9)
        np.testing.assert_allclose(Ps[k], Ps[k].T, atol=1e-12)
        assert np.linalg.eigvalsh(Ps[k]).min() > -1e-10


def test_a_limit_the_truth_obeys_does_not_disturb_error_free_feet(tmp_path):
    config = simulate(ROOT / "configs" / "sim_perfect_walk.yaml", tmp_path, seed=0).config_path
    free = run_layout(load_layout(config))
    truth = free.truths
    t = truth["left_foot"].t
    sep = np.hypot(*(truth["left_foot"].pos_n - np.array([np.interp(t, truth["right_foot"].t, c)
                                                           for c in truth["right_foot"].pos_n.T]).T)[:, :2].T)
    limit = float(np.round(sep.max() + 0.05, 2))
    constrained = run_layout(load_layout(config, [
        "fuser.method=projection",
        f"constraints=[{{between: [left_foot, right_foot], kind: max, distance_m: {limit}}}]"]))
    for name, score in constrained.scores.items():
        assert score.metrics["horizontal_error_m"]["max"] < 0.01, name


def test_run_writes_the_constraints_block(tmp_path):
    _, out = run(VICON, [], tmp_path)
    block = json.loads((out / "metrics.json").read_text())["constraints"]
    for key in ("method", "epochs", "activations", "solver_fallbacks", "max_violation_after_m", "solve_time_us"):
        assert key in block
    assert block["method"] == "projection"
    assert block["activations"] > 0
    assert block["max_violation_after_m"] < 1e-6
    assert set(block["solve_time_us"]) == {"median", "p99"}
