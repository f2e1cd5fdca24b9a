"""Comparing arrays for the conformance checks: the same bits, and the difference in one line."""

from __future__ import annotations

from typing import Any

import numpy as np


def as_bytes(a: Any) -> bytes:
    """The float64 bytes of ``a``, C order."""
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64)).tobytes()


def same_bits(a: Any, b: Any) -> bool:
    """Whether ``a`` and ``b`` have the same shape and the same float64 bits."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and as_bytes(a) == as_bytes(b)


def max_diff(a: Any, b: Any) -> str:
    """How ``a`` and ``b`` differ: their shapes, or the largest absolute difference."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        return f"shapes {a.shape} and {b.shape}"
    with np.errstate(invalid="ignore"):
        d = np.abs(a - b)
    return f"max |difference| {np.nanmax(d) if d.size else 0.0:.3g}"
