"""One frame for systems worn together (bodyfusion.core.heading): the reference, the alignment of
auto headings by default, the feet placed on the body, and the relative-heading tie that keeps
drifting feet in one frame through the run."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.core.capabilities import HeadingAlignment
from bodyfusion.core.heading import HeadingTie, heading_reference
from bodyfusion.core.layout import HeadingAlignmentConfig, load_layout
from bodyfusion.runner import run_layout
from bodyfusion.sim import simulate
from tests.paths import ROOT


def rotate(p: np.ndarray, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return p @ np.array([[c, -s], [s, c]]).T


def walk(turns: float, n: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Centreline (n, 2) of a walk of 12 m that turns by ``turns`` rad along it, and its unit
    right-hand normals."""
    s = np.linspace(0.0, 12.0, n)
    heading = turns * s / 12.0  # counter-clockwise from +x
    step = np.column_stack([np.cos(heading), np.sin(heading)]) * (s[1] - s[0])
    centre = np.vstack([[0.0, 0.0], np.cumsum(step, axis=0)[:-1]])
    right = np.column_stack([np.sin(heading), -np.cos(heading)])
    return centre, right


@settings(max_examples=30, deadline=None)
@given(error=st.floats(-0.3, 0.3), turns=st.sampled_from([0.0, 1.5, np.pi, -2.0]))
def test_a_tie_measures_the_relative_heading_of_a_left_and_a_right_foot(error, turns):
    """The right foot's track is the left's rotated by its heading error (about its start), the
    feet 0.2 m apart across the path: the tie measures the error, turns or not."""
    centre, right = walk(turns)
    left = centre - 0.1 * right
    other = rotate(centre + 0.1 * right, -error)  # estimate = truth turned back by the error
    tie = HeadingTie("left_foot", "right_foot", window_m=10.0, lateral_sd_m=0.1, offsets_m=(-0.1, 0.1))
    got = None
    for a, b in zip(left, other):
        tie.add(np.r_[a, 0.0], np.r_[b, 0.0])
        got = got or tie.measure(0.1, 0.1)
    z, r_var = got
    assert z == pytest.approx(error, abs=0.01)
    assert 0.0 < np.sqrt(r_var) < 0.1


def test_a_tie_waits_for_both_to_travel_its_window():
    tie = HeadingTie("a", "b", window_m=10.0, lateral_sd_m=0.1)
    for x in np.linspace(0.0, 9.0, 10):
        tie.add(np.array([x, 0.0, 0.0]), np.array([x, 0.2, 0.0]))
        assert tie.measure(0.1, 0.1) is None
    tie.add(np.array([11.0, 0.0, 0.0]), np.array([11.0, 0.2, 0.0]))
    z, _ = tie.measure(0.1, 0.1)
    assert z == pytest.approx(0.0, abs=1e-12)
    assert len(tie.points) == 1 and tie.travelled.max() == 0.0  # the next stretch starts here


def test_the_reference_is_the_geographic_heading_then_a_given_one():
    class System(HeadingAlignment):
        def __init__(self, auto: bool, absolute: bool = False) -> None:
            self.auto, self.absolute = auto, absolute

        heading_is_auto = property(lambda self: self.auto)
        heading_is_absolute = property(lambda self: self.absolute)
        initial_travel_azimuth = rotate_initial_heading = None

    cfg = HeadingAlignmentConfig()
    assert heading_reference({"l": System(True), "r": System(True)}, cfg) == "l"
    assert heading_reference({"l": System(True), "r": System(False)}, cfg) == "r"
    assert heading_reference({"l": System(False), "r": System(True), "phone": System(False, True)}, cfg) == "phone"
    assert heading_reference({"l": System(True), "r": System(True)}, HeadingAlignmentConfig(reference="r")) == "r"


@pytest.fixture(scope="module")
def mounted_apart(tmp_path_factory):
    """The consumer-grade walk (240 m, gyro bias instability 100 °/h), the right IMU pointing 150°
    away from the left: a layout that gives nothing but each foot's data columns."""
    out = tmp_path_factory.mktemp("apart")
    sim = simulate(ROOT / "configs" / "sim_dual_foot_consumer_walk.yaml", out, seed=3, overrides=[
        "systems.right_foot.mount_yaw_deg=150", "layout={}"])
    return sim.config_path


def _defaults_only(config, *settings: str):
    overrides = [f"systems.{foot}.initial={{}}" for foot in ("left_foot", "right_foot")]
    overrides += [f"systems.{foot}.detector={{}}" for foot in ("left_foot", "right_foot")]
    overrides += [f"systems.{foot}.filter={{}}" for foot in ("left_foot", "right_foot")]
    return run_layout(load_layout(config, [*overrides, "truth.alignment=first_3m", *settings]))


@pytest.mark.slow
def test_feet_mounted_150_degrees_apart_share_one_frame_with_defaults(mounted_apart):
    """No heading given: the right foot is aligned to the left (150° turned back), both start
    a stance apart, and through the run the tie holds their drifting headings together."""
    tied = _defaults_only(mounted_apart)
    assert abs(np.degrees(tied.heading_rotations_rad["right_foot"]) - 150.0) < 5.0
    start = {n: tied.systems[n].hist_x[0, :2] for n in ("left_foot", "right_foot")}
    assert np.hypot(*(start["left_foot"] - start["right_foot"])) == pytest.approx(0.2)
    alone = _defaults_only(mounted_apart, "heading_alignment.continuous=false")
    rmse = {name: {k: r.scores[k].metrics["horizontal_error_m"]["rmse"] for k in r.scores}
            for name, r in (("tied", tied), ("alone", alone))}
    (tie,) = tied.fuser.heading_ties
    assert tie.summary()["accepted"] >= 5
    assert max(rmse["tied"].values()) < 0.7 * max(rmse["alone"].values()), rmse  # measured 0.65 against 1.95 m


def test_a_lone_foot_keeps_the_origin_and_its_heading(tmp_path):
    sim = simulate(ROOT / "configs" / "sim_perfect_walk.yaml", tmp_path, seed=0, overrides=[
        "systems={left_foot: {kind: foot_imu, foot: left}}", "layout={}"])
    result = run_layout(load_layout(sim.config_path, ["systems.left_foot.initial={}"]))
    assert result.heading_rotations_rad == {} and result.fuser.heading_ties == []
    np.testing.assert_array_equal(result.systems["left_foot"].hist_x[0, :3], np.zeros(3))


@pytest.mark.slow
def test_a_foot_with_no_heading_is_turned_onto_the_phones_gnss_fixes(tmp_path):
    """Foot + phone with GNSS, the foot's heading and position not given: the phone (its heading
    geographic) is the reference, and the foot is turned by the rotation that lays its whole
    track onto the phone's fixes (the truth's frame: the simulated foot needs 0°)."""
    sim = simulate(ROOT / "configs" / "foot_hand_gnss_outage.yaml", tmp_path, seed=1)
    result = run_layout(load_layout(sim.config_path, ["systems.left_foot.initial.heading_deg=auto",
                                                      "systems.left_foot.initial.position_m=null"]))
    assert abs(np.degrees(result.heading_rotations_rad["left_foot"])) < 1.0
    (tie,) = result.fuser.heading_ties
    assert tie.reference == "hand_phone"
    assert result.scores["left_foot"].metrics["horizontal_error_m"]["rmse"] < 0.5
