"""The PDR's low-pass filter and peak picking: scipy.signal's results, bit for bit, without scipy.signal."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from bodyfusion.plugins.hand_pdr.pdr import butterworth_sos, find_peaks, lowpass


def test_the_section_is_scipys_butterworth():
    from scipy.signal import butter

    for wn in np.random.default_rng(0).uniform(1e-4, 0.99, 2000):
        assert np.array_equal(butterworth_sos(float(wn)), butter(2, float(wn), output="sos")[0])


@pytest.mark.parametrize("rate_hz, cutoff_hz", [(100.0, 3.0), (100.0, 0.3), (50.0, 3.0), (10.0, 8.0)])
@pytest.mark.parametrize("shape", [(2000, 3), (2000,), (10,)])
def test_lowpass_is_scipys_sosfiltfilt(rate_hz, cutoff_hz, shape):
    from scipy.signal import butter, sosfiltfilt

    x = np.random.default_rng(1).normal(size=shape).cumsum(axis=0)
    expected = sosfiltfilt(butter(2, min(cutoff_hz / (0.5 * rate_hz), 0.99), output="sos"), x, axis=0)
    assert np.array_equal(lowpass(x, rate_hz, cutoff_hz), expected)


def test_lowpass_of_too_few_samples_is_refused():
    with pytest.raises(ValueError, match="greater than padlen"):
        lowpass(np.zeros(9), 100.0, 3.0)


def test_peaks_are_scipys_find_peaks():
    from scipy.signal import find_peaks as scipy_find_peaks

    rng = np.random.default_rng(2)
    for trial in range(1000):
        n = int(rng.integers(0, 300))
        a = rng.normal(size=n) if trial % 3 == 0 else np.round(rng.normal(size=n).cumsum() * rng.choice([1, 3]))
        height, distance = float(rng.uniform(-3.0, 3.0)), int(rng.integers(1, 30))  # rounded: plateaus, equal peaks
        expected = scipy_find_peaks(a, height=height, distance=distance)[0] if n else np.zeros(0, dtype=int)
        assert np.array_equal(find_peaks(a, height, distance), expected)


def test_step_detection_does_not_import_scipy_signal():
    code = ("import sys, numpy as np\n"
            "from bodyfusion.plugins.hand_pdr.config import StepConfig\n"
            "from bodyfusion.plugins.hand_pdr.pdr import detect_steps, step_lengths, up_in_body\n"
            "t = np.arange(3000) / 100.0\n"
            "acc = np.column_stack([np.zeros_like(t), np.zeros_like(t), 9.81 + 2 * np.sin(2 * np.pi * 1.8 * t)])\n"
            "steps = detect_steps(t, acc, StepConfig(), 9.80665)\n"
            "step_lengths(t, acc, steps, StepConfig()), up_in_body(t, acc)\n"
            "assert len(steps) > 40, len(steps)\n"
            "print('scipy.signal' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False"]
