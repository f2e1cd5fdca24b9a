"""Clipped readings (bodyfusion.nav.saturation): a rail is found where the flanks keep climbing,
never on an unclipped signal whose peaks repeat exactly, and the repair restores most of what
the sensor could not report."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.nav.saturation import MIN_CLIPPED_RUNS, find_clipping

RATE = 200.0


def swings(peak: float, strides: int, rng: np.random.Generator, jitter: float = 0.05, noise: float = 0.01) -> np.ndarray:
    """(N, 3) angular rate of a foot: a pitch-rate pulse per stride on y (peak ± jitter), small
    rates on x and z, sensor noise."""
    rows = []
    for _ in range(strides):
        tau = np.linspace(0.0, 1.0, 220)
        pulse = -peak * (1.0 + jitter * rng.standard_normal()) * np.sin(np.pi * np.clip(tau / 0.35, 0, 1)) ** 2
        rows.append(np.column_stack([0.3 * np.sin(2 * np.pi * tau), pulse, 0.2 * np.cos(2 * np.pi * tau)]))
    x = np.vstack(rows)
    return x + noise * rng.standard_normal(x.shape)


@settings(max_examples=20, deadline=None)
@given(peak=st.floats(6.0, 16.0), over=st.floats(1.15, 1.8), seed=st.integers(0, 10_000))
def test_a_gyroscope_clipped_in_every_swing_is_found_and_repaired(peak, over, seed):
    rng = np.random.default_rng(seed)
    truth = swings(peak, 20, rng)
    limit = peak / over
    clipped = np.clip(truth, -limit, limit)
    found = find_clipping(clipped, 1.0 / RATE)
    assert found.rail[1, 0] == pytest.approx(limit) and np.isnan(found.rail[[0, 2]]).all()
    assert len(found.runs) >= 15
    repaired = found.repaired(clipped)
    lost = np.abs(truth - clipped).sum()
    assert np.abs(truth - repaired).sum() < 0.35 * lost
    assert np.all(np.abs(repaired[:, 1]) >= np.abs(clipped[:, 1]) - 1e-12)  # never inside the rail


def test_peaks_that_repeat_exactly_are_not_a_rail():
    """A simulated gait repeats its peaks to the last digit: the top samples of each peak are
    on one level, but the flanks fall away from them (a natural peak), so nothing is clipped."""
    x = swings(9.0, 20, np.random.default_rng(0), jitter=0.0, noise=0.0)
    assert not find_clipping(x, 1.0 / RATE).runs


def test_a_rail_needs_several_clipped_runs():
    rng = np.random.default_rng(3)
    truth = swings(10.0, 20, rng)
    top = np.argsort(np.abs(truth[:, 1]))[::-1]
    limit = 0.8 * np.abs(truth[top[0], 1])
    once = truth.copy()
    stride = int(top[0]) // 220
    once[stride * 220:(stride + 1) * 220, 1] = np.clip(once[stride * 220:(stride + 1) * 220, 1], -limit, limit)
    found = find_clipping(once, 1.0 / RATE)
    assert len(found.runs) < MIN_CLIPPED_RUNS and np.isnan(found.rail).all()


def test_the_runs_of_a_recordings_tail_are_repaired_as_in_the_whole_from_the_cache():
    """A live pass finds the clipped runs of its context again: where the rail is the whole
    recording's, each run's repair is the whole's, bit for bit, its flank fit from the cache."""
    from bodyfusion.nav import saturation

    rng = np.random.default_rng(4)
    clipped = np.clip(swings(10.0, 20, rng), -7.0, 7.0)
    whole = find_clipping(clipped, 1.0 / RATE)
    a = 220 * 8  # a tail from the 9th stride on
    hits = saturation._cubic_through.cache_info().hits
    tail = find_clipping(clipped[a:], 1.0 / RATE)
    assert saturation._cubic_through.cache_info().hits > hits
    assert tail.rail[1, 0] == whole.rail[1, 0]
    later = [r for r in whole.runs if r.start >= a]
    assert [(r.start - a, r.stop - a, r.excess_integral) for r in later] == \
        [(r.start, r.stop, r.excess_integral) for r in tail.runs]
    for r, s in zip(later, tail.runs):
        np.testing.assert_array_equal(r.values, s.values)


@settings(max_examples=30, deadline=None)
@given(sides=st.lists(st.booleans(), min_size=6, max_size=6), seed=st.integers(0, 10_000))
def test_each_side_of_each_axis_is_judged_on_its_own(sides, seed):
    """Swings on every axis, each of the six sides (axis, sign) clipped or not on its own: the
    rails found are those of the sides clipped, at their limits, and every run is on one of them."""
    rng = np.random.default_rng(seed)
    pulses = [swings(peak, 20, rng)[:, 1] for peak in (8.0, 10.0, 12.0)]  # negative ones, a stride apart
    x = np.column_stack([p - 0.7 * np.roll(p, 110) for p in pulses])  # and positive ones between them
    limits = np.empty((3, 2))
    for axis in range(3):
        for side, sign in enumerate((-1.0, 1.0)):
            extreme = float((sign * x[:, axis]).max())
            limits[axis, side] = 0.8 * extreme if sides[2 * axis + side] else np.inf
    clipped = np.clip(x, -limits[:, 0], limits[:, 1])
    found = find_clipping(clipped, 1.0 / RATE)
    for axis in range(3):
        for side in range(2):
            if sides[2 * axis + side]:
                assert found.rail[axis, side] == pytest.approx(limits[axis, side])
            else:
                assert np.isnan(found.rail[axis, side])
    for run in found.runs:
        side = 1 if clipped[run.start, run.axis] > 0 else 0
        assert sides[2 * run.axis + side]
