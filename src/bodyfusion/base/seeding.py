"""Deterministic random streams: same seed, same bits, in every process.

Each system draws from ``SeedSequence([seed, stable_hash(name)])``, so adding a system
to a layout does not change the others' random numbers.
"""

from __future__ import annotations

import hashlib

import numpy as np


def stable_hash(name: str) -> int:
    """A 64-bit integer from ``name`` that is the same in every process (unlike ``hash``)."""
    return int.from_bytes(hashlib.sha256(name.encode("utf-8")).digest()[:8], "little")


def system_seed(seed: int, name: str) -> np.random.SeedSequence:
    """The seed sequence of system ``name`` under the run seed ``seed`` (≥ 0)."""
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    return np.random.SeedSequence([int(seed), stable_hash(name)])
