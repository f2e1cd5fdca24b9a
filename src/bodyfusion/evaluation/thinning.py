"""Thinning long series for drawing: at most :data:`MAX_POINTS` points per line, evenly spaced
in index, first and last sample kept (shared by the figures and the HTML report)."""

from __future__ import annotations

import numpy as np

MAX_POINTS = 20000
"""Most points drawn per line (longer series are thinned evenly)."""


def thin_index(n: int, limit: int = MAX_POINTS) -> np.ndarray:
    """Indices of at most ``limit`` (≥ 2) of ``n`` samples, evenly spaced, the first and the last
    included (all of them when ``n <= limit``)."""
    if n <= limit:
        return np.arange(n)
    step = -(-n // (limit - 1))  # ceil: the last one is added after
    idx = np.arange(0, n, step)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)
