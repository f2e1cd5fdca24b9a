"""The chi-square gate of the zero-velocity update: bounded influence of a false stance, no
change to consistent updates, and a filter with a wrong velocity is still pulled back."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.nav.kalman import nis_selected
from bodyfusion.nav.measurements import chi2_gate
from bodyfusion.nav.zupt import gated_noise_variance, zero_velocity_update

GATE = chi2_gate(0.999, 3)


def state(v):
    x = np.zeros(16)
    x[3:6] = v
    x[6] = 1.0
    P = np.diag(np.r_[np.full(3, 1e-4), np.full(3, 4e-4), np.full(3, 1e-4), np.full(6, 1e-6)])
    P[3, 7] = P[7, 3] = 1e-5  # velocity correlated with attitude, as after a swing
    return x, P


def test_a_consistent_update_is_the_plain_update():
    x, P = state([0.01, -0.01, 0.005])
    xa, Pa, xb, Pb = x.copy(), P.copy(), x.copy(), P.copy()
    nis_a = zero_velocity_update(xa, Pa, 0.01, GATE, np.empty(15), np.empty((0, 0)), np.empty((15, 15)))
    nis_b = zero_velocity_update(xb, Pb, 0.01, 0.0, np.empty(15), np.empty((0, 0)), np.empty((15, 15)))
    assert nis_a == nis_b < GATE
    np.testing.assert_array_equal(xa, xb)
    np.testing.assert_array_equal(Pa, Pb)


def test_a_false_stance_moves_the_state_by_a_bounded_amount():
    """A foot swinging at 2 m/s flagged as stance: the plain update zeroes its velocity and
    drags attitude along; the gated one moves it by a few per cent, its NIS set to the gate."""
    x, P = state([2.0, 0.5, 0.0])
    x_plain, P_plain = x.copy(), P.copy()
    zero_velocity_update(x_plain, P_plain, 0.01, 0.0, np.empty(15), np.empty((0, 0)), np.empty((15, 15)))
    x_gated, P_gated = x.copy(), P.copy()
    nis = zero_velocity_update(x_gated, P_gated, 0.01, GATE, np.empty(15), np.empty((0, 0)), np.empty((15, 15)))
    assert nis > 100 * GATE
    moved_plain = np.linalg.norm(x_plain[3:6] - x[3:6])
    moved_gated = np.linalg.norm(x_gated[3:6] - x[3:6])
    assert moved_plain > 1.5 and moved_gated < 0.05 * moved_plain
    r = gated_noise_variance(P, 3, -x[3:6], 1e-4, GATE)
    assert nis_selected(P, 3, -x[3:6], r) == pytest.approx(GATE, rel=1e-5)
    assert np.all(np.linalg.eigvalsh(P_gated) > 0) and np.allclose(P_gated, P_gated.T)


def test_a_wrong_velocity_is_still_pulled_back_over_a_stance():
    """The filter's own velocity is wrong (after a gap, a bad start): every stance sample is
    beyond the gate, yet 100 of them (0.5 s at 200 Hz) bring it near zero."""
    x, P = state([0.8, 0.0, 0.0])
    dx = np.empty(15)
    for _ in range(100):
        P[3:6, 3:6] += np.eye(3) * 1e-6  # propagation between samples
        zero_velocity_update(x, P, 0.01, GATE, dx, np.empty((0, 0)), np.empty((15, 15)))
    assert np.linalg.norm(x[3:6]) < 0.05


def test_a_rolling_foot_gets_a_looser_zero_velocity():
    """σ_v² = σ² + (r |ω − b_g|)²: a foot rolling at ω about a heel or ball r from the IMU moves
    it at up to r |ω|; a still foot keeps the configured σ; pivot 0 switches it off."""
    from bodyfusion.nav.error_state import filter_params
    from bodyfusion.nav.zupt import stance_velocity_sigma

    params = filter_params(zupt_sigma=0.01, zupt_pivot=0.1)
    x, _ = state([0.0, 0.0, 0.0])
    x[13:16] = [0.01, 0.0, -0.01]  # gyro bias estimate
    assert stance_velocity_sigma(params, x[13:16].copy(), x) == pytest.approx(0.01)
    rolling = x[13:16] + [0.0, 0.8, 0.0]
    assert stance_velocity_sigma(params, rolling, x) == pytest.approx(np.hypot(0.01, 0.08))
    assert stance_velocity_sigma(params._replace(zupt_pivot=0.0), rolling, x) == pytest.approx(0.01)
