"""The simulator's tables in memory hold exactly what its files hold: :func:`printed` rounds as
printf prints and the readers parse back."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.sim.files import printed


@pytest.mark.parametrize("fmt", ["%.10g", "%.11f", "%.4f", "%.3f", "%.6g", "%d"])
def test_printed_values_are_the_parsed_printed_decimals(fmt):
    rng = np.random.default_rng(7)
    n = 20_000
    x = np.concatenate([rng.standard_normal(n) * 10.0 ** rng.integers(-15, 16, n),
                        np.arange(0.0, 50.0, 0.0005),  # sample times: many ties in the last printed digit
                        [0.0, -0.0, 0.5, 1.5, 2.5, -2.5, 999.99999995, 9.9999999995, 1e22, 1e-22, np.nan, np.inf]])
    expected = np.array([float(fmt % v) if np.isfinite(v) else v for v in x])
    got = printed(x, fmt)
    same = (got == expected) & (np.signbit(got) == np.signbit(expected))
    assert np.all(same | (np.isnan(got) & np.isnan(expected)))
