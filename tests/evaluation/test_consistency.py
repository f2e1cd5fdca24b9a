"""Consistency measures: covariance checks, NIS tallies, the horizontal NEES."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.base.types import Trajectory, TruthTrack
from bodyfusion.evaluation.consistency import (CovarianceHealth, NisTally, chi2_band, covariance_defects,
                                               horizontal_nees, nees, nis, quaternion_norm_deviation)
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


def test_a_psd_covariance_of_mixed_units_passes_and_defects_are_caught():
    good = np.diag([4.0, 1e-12, 1e-10])
    good[0, 1] = good[1, 0] = 0.5 * np.sqrt(4.0 * 1e-12)
    asym, lam, bad = covariance_defects(good)
    assert asym == 0.0 and lam > 0 and not bad
    negative = good.copy()
    negative[1, 1] = -1e-14  # tiny against the 4 m², yet a negative variance
    assert covariance_defects(negative)[2]
    not_psd = good.copy()
    not_psd[0, 1] = not_psd[1, 0] = 2.0 * np.sqrt(4.0 * 1e-12)  # a correlation of 2
    assert covariance_defects(not_psd)[2]
    asymmetric = good.copy()
    asymmetric[0, 2] += 1e-3
    asym, _, bad = covariance_defects(asymmetric)
    assert asym == pytest.approx(1e-3) and bad
    nan = good.copy()
    nan[2, 2] = np.nan
    assert covariance_defects(nan)[2]
    zero_variance = np.diag([1.0, 0.0, 1.0])  # a state known exactly is PSD
    assert not covariance_defects(zero_variance)[2]


def test_covariance_health_counts_checks_violations_and_the_first_one():
    health = CovarianceHealth()
    health.add(np.eye(2), 0.0)
    health.add_many(np.stack([np.eye(2), [[1.0, 2.0], [2.0, 1.0]], np.eye(2)]), np.array([1.0, 2.0, 3.0]))
    d = health.to_dict()
    assert d["checks"] == 4 and d["violations"] == 1 and d["first_violation_t_s"] == 2.0
    assert d["min_eigenvalue"] == pytest.approx(-1.0) and d["end"]["min_eigenvalue"] == pytest.approx(1.0)


def test_nis_tally_mean_beside_its_expected_value():
    tally = NisTally(3)
    for value, ok in ((1.0, True), (2.0, True), (30.0, False)):
        tally.add(value, ok)
    assert tally.to_dict() == {"dof": 3, "expected": 3.0, "count": 3, "mean": 11.0, "beyond_gate": 1}
    assert NisTally(3, 5, None).to_dict()["mean"] is None  # only the count is kept
    assert nis(np.array([2.0]), np.array([[4.0]])) == pytest.approx(1.0)


def test_quaternion_norm_deviation():
    q = np.array([[1.0, 0, 0, 0], [0.5, 0.5, 0.5, 0.5 + 1e-6]])
    assert quaternion_norm_deviation(q) == pytest.approx(0.5e-6, rel=1e-3)


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


def test_covariance_health_checked_in_pieces_is_that_of_all_at_once():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(1000, 3, 3))
    covs = A @ A.transpose(0, 2, 1)
    covs[700] = np.diag([1.0, -1e-3, 1.0])  # a violation in the third piece
    covs[900, 0, 1] += 1e-3  # an asymmetric one
    t = np.arange(1000) * 0.01
    whole = CovarianceHealth()
    whole.add_many(covs, t)
    assert CovarianceHealth.of(covs, t, piece=300) == whole
    assert whole.violations == 2 and whole.first_violation_t_s == 7.0


def test_the_closed_form_smallest_eigenvalue_of_a_2x2_covariance_is_lapacks():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(5000, 2, 2)) * rng.uniform(1e-4, 1e3, size=(5000, 1, 1))
    covs = A @ A.transpose(0, 2, 1)
    covs[:3] = [np.diag([1.0, -1e-3]), np.ones((2, 2)), np.zeros((2, 2))]
    _, lam, bad = covariance_defects(covs)
    exact = np.linalg.eigvalsh(covs)[:, 0]
    assert (np.abs(lam - exact) <= 1e-12 * np.abs(covs).max(axis=(1, 2)).clip(1.0)).all()
    assert bad.tolist()[:3] == [True, False, False] and not bad[3:].any()


def test_the_running_checks_give_the_figures_of_decomposing_every_covariance():
    """Batches of 15-state covariances of mixed units (variances 1e-12 … 1e2), some shrinking
    below the running minimum, one indefinite, one with a NaN: only the covariances that may
    hold the minimum are decomposed, and the figures are those of decomposing every one."""
    rng = np.random.default_rng(4)
    K, n = 600, 15
    A = rng.normal(size=(K, n, n)) * np.logspace(-6, 1, n)[None, :, None]
    covs = A @ A.transpose(0, 2, 1) * np.linspace(1.0, 1e-3, K)[:, None, None]  # shrinks: each batch a new floor
    covs[250] = covs[249] - 2.0 * np.linalg.eigvalsh(covs[249])[0] * np.eye(n)  # indefinite
    covs[420, 3, 3] = np.nan
    t = np.arange(K) * 0.1
    health = CovarianceHealth.of(covs, t, piece=128)
    asym, lam, bad = covariance_defects(covs)
    assert health.checks == K and health.violations == int(bad.sum()) == 2
    assert health.first_violation_t_s == 25.0
    assert health.min_eigenvalue == float(lam.min()) and health.max_asymmetry == float(asym.max())
    assert health.end_min_eigenvalue == float(lam[-1])
    floor = float(np.median(lam[:128]))
    _, above, _ = covariance_defects(covs[:128], floor=floor)
    skipped = np.isnan(above)
    assert 0 < skipped.sum() < 128  # the certificate skips decompositions, and only above the floor
    assert (lam[:128][skipped] > floor).all() and (above[~skipped] == lam[:128][~skipped]).all()
