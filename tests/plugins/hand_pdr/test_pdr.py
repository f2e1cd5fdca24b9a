"""The PDR's step-length features: Weinberg's (a_max − a_min)^(1/4) over each step's span."""

from __future__ import annotations

import numpy as np

from bodyfusion.plugins.hand_pdr.config import StepConfig
from bodyfusion.plugins.hand_pdr.pdr import detect_steps, lowpass, weinberg_features


def test_weinberg_features_are_the_range_of_each_steps_span():
    """The vectorised features (maximum/minimum.reduceat) equal the span-by-span loop: step k
    spans the samples from the previous step to it, both included, the first step the same
    span before it."""
    rng = np.random.default_rng(4)
    t = np.arange(6000) / 100.0
    acc = np.column_stack([rng.normal(0, 0.2, t.size), rng.normal(0, 0.2, t.size),
                           9.81 + 2.0 * np.sin(2 * np.pi * 1.8 * t) + rng.normal(0, 0.3, t.size)])
    cfg = StepConfig()
    steps = detect_steps(t, acc, cfg, 9.80665)
    assert len(steps) > 100
    a = lowpass(np.linalg.norm(acc, axis=1), 1.0 / np.median(np.diff(t)), cfg.lowpass_hz)
    bounds = np.concatenate([[max(0, steps[0] - (steps[1] - steps[0]))], steps])
    expected = np.maximum([np.ptp(a[bounds[k]:bounds[k + 1] + 1]) for k in range(len(steps))], 0.0) ** 0.25
    np.testing.assert_array_equal(weinberg_features(t, acc, steps, cfg), expected)


def test_soft_steps_between_detected_ones_are_found():
    """A walk of 1.7 steps/s whose every third step is soft (its peak below the fixed threshold,
    above half of its neighbours'): the watchdog finds each; a phone resting between walks,
    whose ripples are a tenth of the steps', gets none."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 60.0, 0.02)
    step_t = np.arange(1.0, 40.0, 1 / 1.7)
    heights = np.where(np.arange(step_t.size) % 3 == 2, 1.4, 2.2)  # the soft ones: 0.9 m/s^2 after the low-pass
    bump = sum(h * np.exp(-0.5 * ((t - s) / 0.06) ** 2) for s, h in zip(step_t, heights))
    rest = (t > 42.0) * 0.2 * np.sin(2 * np.pi * 1.5 * t)  # standing, fidgeting
    acc = np.column_stack([rng.normal(0, 0.05, t.size), rng.normal(0, 0.05, t.size), 9.81 + bump + rest])
    found = detect_steps(t, acc, StepConfig(), 9.81)
    assert len(found) == step_t.size
    np.testing.assert_allclose(t[found], step_t, atol=0.05)
