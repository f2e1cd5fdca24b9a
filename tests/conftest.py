"""Fixtures shared by the tests: writing a layout or scenario dict as a YAML file."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
import yaml


@pytest.fixture()
def write_yaml(tmp_path: Path) -> Callable[[dict, str], Path]:
    """``write_yaml(mapping, name="layout.yaml")`` → the file written in the test's folder,
    so relative data paths in the mapping resolve beside it."""

    def write(mapping: dict, name: str = "layout.yaml") -> Path:
        path = tmp_path / name
        path.write_text(yaml.safe_dump(mapping, sort_keys=False))
        return path

    return write
