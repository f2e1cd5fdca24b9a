"""Consistency against truth: the horizontal NEES and its chi-square band."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.base.types import Trajectory, TruthTrack
from bodyfusion.evaluation.consistency import chi2_band, horizontal_nees, nees
from bodyfusion.evaluation.metrics import PlanarTransform, SystemScore, score_systems


def random_covariances(rng: np.random.Generator, n: int, k: int = 2) -> np.ndarray:
    """n random positive-definite (k, k) covariances with variances from 1e-4 to 1e2 m²."""
    A = rng.normal(size=(n, k, k)) * 10.0 ** rng.uniform(-2, 1, (n, 1, 1))
    return A @ np.swapaxes(A, 1, 2) + 1e-6 * np.eye(k)


def consistent_case(rng: np.random.Generator, n: int = 20000) -> tuple[Trajectory, TruthTrack]:
    """An estimate whose horizontal errors are drawn from its own east–north covariances."""
    t = np.arange(n) * 0.01
    truth = np.column_stack([1.2 * t, np.sin(0.1 * t), np.zeros(n)])
    cov = random_covariances(rng, n)
    err = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((n, 2)))
    est = truth.copy()
    est[:, :2] -= err  # error = truth − estimate
    sd = np.column_stack([np.sqrt(cov[:, 0, 0]), np.sqrt(cov[:, 1, 1]), np.full(n, 0.1)])
    return Trajectory(t, est, sd, cov[:, 0, 1]), TruthTrack(t, truth)


def test_chi2_band_of_two_dof_is_the_documented_one():
    lo, hi = chi2_band(2)
    assert lo == pytest.approx(0.0506, abs=1e-4) and hi == pytest.approx(7.378, abs=1e-3)
    lo20, hi20 = chi2_band(2, runs=20)  # the mean of 20 runs: a narrower band round 2
    assert lo < lo20 < 2.0 < hi20 < hi


def test_nees_of_a_consistent_estimate_averages_two_with_95_percent_in_band():
    traj, truth = consistent_case(np.random.default_rng(1))
    transform, scores = score_systems({"a": traj}, {"a": truth}, alignment="none")
    summary = horizontal_nees(traj, scores["a"], transform, "none").summary()
    assert summary["mean"] == pytest.approx(2.0, abs=0.08)
    assert summary["in_band_fraction"] == pytest.approx(0.95, abs=0.01)
    assert summary["frame_fitted"] is False and len(summary["profile"]["mean"]) == 10


def test_nees_after_an_alignment_turns_the_covariance_with_the_frame():
    """The same consistent estimate in a frame turned by 30°: the transform that turns it back
    turns its covariance too, so the NEES still averages 2 (and says the frame was fitted)."""
    traj, truth = consistent_case(np.random.default_rng(2))
    turn = PlanarTransform(np.deg2rad(-30.0), np.array([5.0, -2.0]), 0.0)
    R = turn.matrix
    cov = R @ traj.horizontal_covariance() @ R.T
    sd = np.column_stack([np.sqrt(cov[:, 0, 0]), np.sqrt(cov[:, 1, 1]), traj.pos_sd[:, 2]])
    turned = Trajectory(traj.t, turn.apply(traj.pos_n), sd, cov[:, 0, 1])
    back = PlanarTransform(np.deg2rad(30.0), -turn.matrix.T @ turn.translation_m, 0.0)
    aligned = back.apply(turned.pos_n)
    np.testing.assert_allclose(aligned, traj.pos_n, atol=1e-9)
    score = SystemScore(traj.t, aligned, truth.pos_n, np.zeros(traj.t.size), np.zeros(traj.t.size), {})
    summary = horizontal_nees(turned, score, back, "first_3m").summary()
    assert summary["mean"] == pytest.approx(2.0, abs=0.08) and summary["frame_fitted"] is True
    unturned = horizontal_nees(turned, score, PlanarTransform(0.0, np.zeros(2), 0.0), "none").summary()
    assert abs(unturned["mean"] - 2.0) > 0.1  # the covariance left in the other frame does not fit


def test_nees_is_nan_where_the_covariance_is_singular():
    values = nees(np.array([[1.0, 0.0], [0.0, 0.0], [1.0, 1.0]]), np.stack([np.eye(2), np.zeros((2, 2)), 4 * np.eye(2)]))
    assert values[0] == 1.0 and np.isnan(values[1]) and values[2] == pytest.approx(0.5)


@pytest.mark.parametrize("k", [2, 3])
def test_nees_is_the_quadratic_form_of_the_solved_covariance_in_closed_form_or_not(k):
    rng = np.random.default_rng(k)
    cov = random_covariances(rng, 2000, k)
    err = rng.normal(size=(2000, k))
    err[5] = np.inf
    cov[7] = np.diag([1.0] * (k - 1) + [-1.0])  # det < 0
    solved = np.einsum("ni,ni->n", err, np.linalg.solve(cov, err[..., None])[..., 0])
    values = nees(err, cov)
    assert np.isnan(values[[5, 7]]).all()
    keep = np.ones(2000, bool)
    keep[[5, 7]] = False
    np.testing.assert_allclose(values[keep], solved[keep], rtol=1e-9)


