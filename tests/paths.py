"""Where the tests find the repository's files and the shared recordings."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
"""The repository."""
CONFIGS = ROOT / "configs"
"""The shipped layouts and scenarios."""
EXAMPLE_DATA = ROOT / "examples" / "data"
"""The vendored recordings (always present)."""
SHARED_DATA = ROOT.parent / "shared" / "data"
"""The shared recordings beside the repository (absent on a fresh machine: tests that need
them skip)."""


def needs_shared(*parts: str):
    """Skip a test unless the shared recording ``SHARED_DATA / parts...`` is present."""
    path = SHARED_DATA.joinpath(*parts)
    return pytest.mark.skipif(not path.exists(), reason=f"shared recording {'/'.join(parts)} not present")
