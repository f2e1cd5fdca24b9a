"""Sensor and truth frames are declared, not guessed: an IMU file in other axes and a truth file
in NED (or with two columns) give the same run once declared."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout
from bodyfusion.nav.frames import apply_axis_map
from tests.paths import ROOT

VICON_CFG = ROOT / "configs" / "dual_foot_vicon.yaml"
VICON_DATA = ROOT / "examples" / "data" / "dual_foot_vicon_hu2025"
ONE_FOOT = ["fuser.method=none", "systems.right_foot.initial.heading_deg=0", "smoother.kind=none"]


def test_axis_maps_permute_and_flip_columns():
    v = np.array([[1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(apply_axis_map(("x", "-y", "-z"), v), [[1.0, -2.0, -3.0]])
    np.testing.assert_array_equal(apply_axis_map(("y", "x", "-z"), v), [[2.0, 1.0, -3.0]])
    horizontal = np.array([[1.0, 2.0, np.nan]])  # no height: stays NaN only where used
    np.testing.assert_array_equal(apply_axis_map(("y", "x", "-z"), horizontal)[0, :2], [2.0, 1.0])


def _flipped_imu(tmp_path: Path) -> Path:
    """The left IMU written in a frame turned 180° about x (y and z negated)."""
    lines = (VICON_DATA / "imuMeasLeft.csv").read_text().splitlines()
    header = lines[0].split(",")
    data = np.loadtxt(VICON_DATA / "imuMeasLeft.csv", delimiter=",", skiprows=1)
    for name in ("acc_y", "acc_z", "gyro_y", "gyro_z"):
        data[:, header.index(name)] *= -1.0
    fmt = ["%d" if h in ("time_index", "is_zero_vel") else "%.17g" for h in header]
    out = tmp_path / "imuMeasLeft_flipped.csv"
    np.savetxt(out, data, delimiter=",", header=",".join(header), comments="", fmt=fmt)
    return out


def test_an_imu_declared_in_its_own_axes_navigates_as_the_original(tmp_path):
    plain = run_layout(load_layout(VICON_CFG, ONE_FOOT))
    flipped = run_layout(load_layout(VICON_CFG, [*ONE_FOOT, f"systems.left_foot.data.path={_flipped_imu(tmp_path)}",
                                                 "systems.left_foot.data.axes=[x, -y, -z]"]))
    np.testing.assert_allclose(flipped.trajectories["left_foot"].pos_n, plain.trajectories["left_foot"].pos_n,
                               atol=1e-9)


def test_truth_in_ned_with_two_columns_scores_like_the_enu_truth(tmp_path):
    """The Vicon truth (z down) rewritten as x = north, y = east with no height column, as the
    PyShoe trials store it, declared ``frame: ned``: the same horizontal scores, no vertical."""
    truth = np.genfromtxt(VICON_DATA / "positionGt.csv", delimiter=",", names=True)
    east, north = truth["pos_left_x"], -truth["pos_left_y"]
    ned = tmp_path / "truth_ned.csv"
    np.savetxt(ned, np.column_stack([truth["time_index"], north, east]), delimiter=",",
               header="time_index,n,e", comments="", fmt=["%d", "%.9g", "%.9g"])
    enu = run_layout(load_layout(VICON_CFG, [*ONE_FOOT, "truth.systems={left_foot: [pos_left_x, pos_left_y, pos_left_z]}"]))
    declared = run_layout(load_layout(VICON_CFG, [
        *ONE_FOOT, f"truth.path={ned}", "truth.systems={left_foot: [n, e]}", "truth.frame=ned"]))
    h_enu = enu.scores["left_foot"].metrics["horizontal_error_m"]
    h_ned = declared.scores["left_foot"].metrics["horizontal_error_m"]
    assert h_ned["rmse"] == pytest.approx(h_enu["rmse"], abs=1e-6)
    assert "vertical_error_m" not in declared.scores["left_foot"].metrics


def test_frame_and_the_older_axis_signs_are_one_declaration():
    a = load_layout(VICON_CFG).layout.truth
    b = load_layout(VICON_CFG, ["truth.frame=enu", "truth.axis_signs=[1, -1, -1]"]).layout.truth
    assert a.axes == b.axes == ("x", "-y", "-z")
    with pytest.raises(ConfigError) as err:
        load_layout(VICON_CFG, ["truth.axis_signs=[1, -1, -1]"])
    assert err.value.key == "truth.axis_signs"


def _signed_permutations() -> list[tuple[str, str, str]]:
    import itertools

    return [tuple(s + a for s, a in zip(signs, order)) for order in itertools.permutations("xyz")
            for signs in itertools.product(("", "-"), repeat=3)]


@pytest.mark.parametrize("axes", _signed_permutations(), ids=lambda a: ",".join(a))
def test_an_imu_axis_map_that_mirrors_is_refused_and_one_that_rotates_is_taken(axes):
    from bodyfusion.nav.frames import apply_axis_map, axis_map_determinant

    matrix = apply_axis_map(axes, np.eye(3)).T  # the map as a matrix: body = M @ file
    assert axis_map_determinant(axes) == round(np.linalg.det(matrix))
    override = f"systems.left_foot.data.axes=[{', '.join(axes)}]"
    if np.linalg.det(matrix) > 0:
        assert load_layout(VICON_CFG, [override]).system_configs["left_foot"].data.axes == axes
    else:
        with pytest.raises(ConfigError, match="mirrors the sensor's frame") as err:
            load_layout(VICON_CFG, [override])
        assert err.value.key == "systems.left_foot.data.axes"
