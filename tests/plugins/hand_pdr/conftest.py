"""The simulated walk the hand's live and re-anchoring tests share."""

from __future__ import annotations

import pytest

from bodyfusion.sim.scenario import simulate
from tests.paths import CONFIGS


@pytest.fixture(scope="package")
def dual_foot_hand_walk(tmp_path_factory):
    """Both feet and the phone (IMU, GNSS with a 45 s outage) on the 166 s loop of
    configs/dual_foot_hand_gnss.yaml (seed 0): its layout file."""
    out = tmp_path_factory.mktemp("hand_walk")
    simulate(CONFIGS / "dual_foot_hand_gnss.yaml", out)
    return out / "config.yaml"
