"""The stride period (bodyfusion.nav.gait) of foot-like signals at any rate and cadence, its
fundamental rather than a multiple, and none where nothing repeats."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.nav.gait import MAX_STRIDE_S, MIN_STRIDE_S, stride_period


def swing_rate(period_s: float, rate_hz: float, seconds: float, rng: np.random.Generator,
               swing_share: float = 0.4) -> np.ndarray:
    """|ω| of a foot: two rate peaks in each swing (toe-off, heel strike), near zero in stance,
    strides jittered by 2 %, sensor noise."""
    out = []
    while len(out) < seconds * rate_hz:
        p = period_s * (1.0 + 0.02 * rng.standard_normal())
        n = int(round(p * rate_hz))
        tau = np.arange(n) / n
        swing = np.clip((tau - (1.0 - swing_share)) / swing_share, 0.0, 1.0)
        out.extend(6.0 * np.sin(np.pi * swing) ** 2 + 3.0 * np.sin(2 * np.pi * swing) ** 2)
    return np.abs(np.asarray(out[: int(seconds * rate_hz)]) + 0.05 * rng.standard_normal(int(seconds * rate_hz)))


@settings(max_examples=25, deadline=None)
@given(period=st.floats(MIN_STRIDE_S + 0.05, MAX_STRIDE_S - 0.1), rate=st.sampled_from([50.0, 100.0, 204.8, 400.0]),
       seed=st.integers(0, 10_000))
def test_the_stride_period_of_a_foot_is_found_at_any_cadence_and_rate(period, rate, seed):
    rng = np.random.default_rng(seed)
    found = stride_period(swing_rate(period, rate, 20.0, rng), rate)
    assert np.all(np.isfinite(found))
    assert np.median(np.abs(found / period - 1.0)) < 0.04


def test_a_change_of_gait_changes_the_period_where_it_happens():
    rng = np.random.default_rng(1)
    walk, run = swing_rate(1.1, 200.0, 20.0, rng), swing_rate(0.68, 200.0, 20.0, rng, swing_share=0.75)
    found = stride_period(np.concatenate([walk, run]), 200.0)
    assert abs(np.median(found[:2000]) - 1.1) < 0.05 and abs(np.median(found[-2000:]) - 0.68) < 0.04


def test_noise_that_repeats_nothing_has_no_period():
    rng = np.random.default_rng(2)
    assert np.isnan(stride_period(np.abs(rng.normal(0, 2.0, 4000)), 200.0)).all()
    assert np.isnan(stride_period(np.zeros(4000), 200.0)).all()  # standing still


def test_a_window_met_again_on_its_grid_gives_the_same_period_from_the_cache():
    """A live pass derives the windows of its context again; on the recording's grid they are the
    windows met before, answered from the cache with the same bits."""
    from bodyfusion.nav import gait

    rate = 100.0
    x = swing_rate(1.1, rate, 60.0, np.random.default_rng(7))
    whole = stride_period(x, rate)
    hop = int(round(gait.PERIOD_HOP_S * rate))
    hits = gait._best_lag_of.cache_info().hits
    a = 20 * hop
    tail = stride_period(x[a:], rate)
    assert gait._best_lag_of.cache_info().hits > hits
    width = int(gait.PERIOD_WINDOW_S * rate)
    inside = slice(width, x.size - a - width)  # between the first and the last window's centres
    np.testing.assert_array_equal(tail[inside], whole[a:][inside])
