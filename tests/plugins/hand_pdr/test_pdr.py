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
