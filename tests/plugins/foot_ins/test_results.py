"""The foot INS's compact records: the covariances corrections outside the compiled loop leave."""

from __future__ import annotations

import numpy as np

from bodyfusion.plugins.foot_ins.results import CovarianceLog, Rows


def test_the_covariance_log_gives_back_every_covariance_as_it_was_added():
    """Symmetric covariances kept as their upper triangle, an asymmetric one and one with a NaN
    off the diagonal kept whole; across the row blocks, in the order added."""
    rng = np.random.default_rng(0)
    log = CovarianceLog(block=3)  # several blocks for a few rows
    covs = []
    for k in range(8):
        A = rng.normal(size=(15, 15))
        P = A @ A.T
        if k == 2:
            P[4, 1] += 1e-9  # a Joseph update's rounding
        if k == 5:
            P[0, 7] = np.nan
        covs.append(P)
        log.add(10 * k, P)
    idx, back = log.covariances()
    assert idx.tolist() == [10 * k for k in range(8)] and len(log) == 8
    np.testing.assert_array_equal(back, np.stack(covs))
    assert len(log.lower_at) == 2


def test_rows_hand_out_views_to_write_and_keep_them():
    rows = Rows((2,), block=2)
    for k in range(5):
        rows.next_row()[:] = (k, -k)
    rows.append((5, -5))
    np.testing.assert_array_equal(rows.array(), [[k, -k] for k in range(6)])


def test_the_covariance_log_gives_the_covariances_of_the_later_samples_alone():
    """What a live fixed-lag window reads: from a sample on, the same numbers as the whole log's."""
    rng = np.random.default_rng(3)
    log = CovarianceLog(block=3)
    for i in range(11):
        A = rng.normal(size=(15, 15))
        P = A @ A.T
        if i % 3 == 0:
            P[4, 1] += 1e-3  # kept whole: its lower triangle beside the upper
        log.add(i // 2, P)
    idx, P = log.covariances()
    for since in range(7):
        later = idx >= since
        idx_s, P_s = log.covariances(since)
        assert np.array_equal(idx_s, idx[later]) and np.array_equal(P_s, P[later])


def test_rows_copy_from_any_row_across_their_blocks():
    rows = Rows((2,), np.float64, block=4)
    for i in range(11):
        rows.append([i, -i])
    for first in range(13):
        assert np.array_equal(rows.array(first), rows.array()[first:])
