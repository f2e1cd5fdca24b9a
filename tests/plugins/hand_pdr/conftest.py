"""The simulated walks the hand's live and re-anchoring tests share."""

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


@pytest.fixture(scope="package")
def short_hand_walk(tmp_path_factory):
    """The same layout on a 58 s walk of 67 m (GNSS out from 25 to 35 s): its layout file."""
    out = tmp_path_factory.mktemp("short_hand_walk")
    simulate(CONFIGS / "dual_foot_hand_gnss.yaml", out,
             overrides=["path.waypoints_m=[[0, 0], [0, 40], [25, 50]]",
                        "systems.hand_phone.gnss.outages=[{start_s: 25, duration_s: 10}]"])
    return out / "config.yaml"
