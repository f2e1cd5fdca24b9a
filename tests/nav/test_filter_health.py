"""A filter's health as it runs: covariance checks, NIS tallies, the quaternion norm."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.nav.filter_health import CovarianceHealth, NisTally, covariance_defects, nis, quaternion_norm_deviation


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
