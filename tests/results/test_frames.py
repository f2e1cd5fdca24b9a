"""A run's tables (results/frames.py and the plugins' states, covariance histories, events and
innovations): one set of column names for every plugin, values that are the run's own."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout
from bodyfusion.nav.attitude import quat_from_azimuth_pitch_roll
from bodyfusion.plugins.foot_ins.results import attitude_columns
from tests.paths import CONFIGS
from tests.plugins.uwb.test_uwb import ANCHORS, anchor_ranges, walkers_layout


@pytest.fixture(scope="module")
def vicon():
    return run_layout(load_layout(CONFIGS / "dual_foot_vicon_position_fixes.yaml"))


def test_attitude_columns_invert_the_azimuth_pitch_roll_quaternion():
    angles = np.array([[10.0, 5.0, -3.0], [200.0, -20.0, 40.0], [359.0, 0.5, 0.0]])
    q = np.array([quat_from_azimuth_pitch_roll(*np.radians(a)) for a in angles])
    cols = attitude_columns(q)
    np.testing.assert_allclose(np.column_stack([cols["heading_deg"], cols["pitch_deg"], cols["roll_deg"]]), angles,
                               atol=1e-9)


def test_foot_states_are_the_trajectory_epochs_with_velocity_attitude_and_biases(vicon):
    states = vicon.states("left_foot")
    traj = vicon.trajectories["left_foot"]
    np.testing.assert_array_equal(states["t"], traj.t)
    np.testing.assert_array_equal(states[["east_m", "north_m", "up_m"]].to_numpy(), traj.pos_n)
    for column in ("v_east_mps", "qw", "heading_deg", "pitch_deg", "roll_deg", "acc_bias_x_mps2",
                   "gyro_bias_z_radps"):
        assert np.all(np.isfinite(states[column]))
    frame = vicon.to_frame()
    np.testing.assert_array_equal(frame.loc[frame.system == "left_foot", "v_north_mps"], states["v_north_mps"])


def test_foot_covariance_history_holds_the_blocks_it_records(vicon):
    """Position (variances and the east–north covariance), velocity variances and the attitude
    block, after every sample; what is not recorded NaN."""
    cov = vicon.covariances("left_foot")
    traj = vicon.trajectories["left_foot"]
    assert cov.states[:3] == ("east_m", "north_m", "up_m") and cov.matrix.shape == (len(traj.t), 9, 9)
    np.testing.assert_allclose(np.sqrt(np.diagonal(cov.matrix, axis1=1, axis2=2)[:, :3]), traj.pos_sd)
    np.testing.assert_array_equal(cov.matrix[:, 0, 1], traj.pos_cov_en)
    np.testing.assert_array_equal(np.diagonal(cov.matrix, axis1=1, axis2=2)[:, 3:6], traj.motion_cov[:, :3])
    attitude = cov.matrix[:, 6:, 6:]
    np.testing.assert_array_equal(attitude, np.swapaxes(attitude, 1, 2))
    assert np.all(np.linalg.eigvalsh(attitude[::500]) > 0)  # a covariance: positive definite
    assert np.isnan(cov.matrix[:, 0, 2]).all() and np.isnan(cov.matrix[:, 0, 3]).all() and "east-north" in cov.stored
    assert list(cov.to_frame().columns[:4]) == ["t", "var_east_m", "var_north_m", "var_up_m"]
    with pytest.raises(KeyError, match="no system 'nose'"):
        vicon.covariances("nose")


def test_stance_phases_are_the_detectors_runs(vicon):
    events = vicon.events()
    left = events[events.system == "left_foot"]
    stance = vicon.systems["left_foot"].stance
    assert len(left) == int(np.sum(np.diff(stance.astype(int)) == 1) + stance[0])
    assert (left.event == "stance").all() and (left.duration_s >= 0).all()


def test_every_position_fix_has_its_nis_in_the_innovations(vicon):
    rows = vicon.innovations()
    fixes = rows[(rows.system == "left_foot") & (rows.aiding == "position_fix")]
    counts = vicon.systems["left_foot"].fix_counts
    assert len(fixes) == counts.accepted + counts.rejected
    assert (fixes.dof == 3).all() and fixes.t.is_monotonic_increasing
    assert fixes.accepted.sum() == counts.accepted
    tally = vicon.systems["left_foot"].health()["nis"]["position_fix"]
    assert tally["mean"] == pytest.approx(fixes.nis.mean())


def test_constraint_events_hold_every_constraint_at_every_epoch(vicon):
    rows = vicon.constraint_events()
    assert len(rows) == vicon.fuser.epochs * len(vicon.loaded.layout.constraints)
    assert rows.active.sum() == vicon.fuser.activations
    active, idle = rows[rows.active], rows[~rows.active]
    assert (active.distance_before_m > active.limit_m).all()
    assert (active.distance_after_m < active.distance_before_m).all()
    untouched, tails = idle[~idle.tail_truncated], idle[idle.tail_truncated]
    np.testing.assert_array_equal(untouched.distance_after_m, untouched.distance_before_m)
    assert len(tails) > 0 and (tails.distance_before_m <= tails.limit_m).all()
    assert (tails.distance_after_m < tails.distance_before_m).all()  # the cut tail pulls the mean inside
    assert not (rows.active & rows.tail_truncated).any()
    assert (active.multiplier > 0).all() and (idle.multiplier == 0).all()
    np.testing.assert_allclose(sorted(active.multiplier), sorted(vicon.fuser.multipliers))


def test_a_projected_constraint_ends_at_its_limit():
    res = run_layout(load_layout(CONFIGS / "dual_foot_vicon.yaml", ["fuser.inequality=projection"]))
    active = res.constraint_events().query("active")
    assert len(active) > 0
    np.testing.assert_allclose(active.distance_after_m, active.limit_m, atol=1e-6)


def test_a_random_walk_stores_its_whole_covariance(tmp_path):
    res = run_layout(load_layout(walkers_layout(tmp_path, {})))
    cov = res.covariances("w1")
    assert not np.isnan(cov.matrix).any()
    np.testing.assert_array_equal(cov.matrix, res.systems["w1"].hist_cov)
    assert set(res.states("w1").columns) == {"t", "east_m", "north_m", "up_m"}
    assert res.events().empty and res.innovations().empty


def test_every_applied_range_has_its_nis_and_end(tmp_path):
    anchor_ranges(tmp_path, outlier_every=7)
    tag = {"plugin": "uwb", "host": "w1", "anchors": ANCHORS, "sigma_m": 0.1,
           "ranges": {"path": "ranges.csv", "nlos_column": "nlos"}}
    res = run_layout(load_layout(walkers_layout(tmp_path, {"tag": tag})))
    rows = res.innovations()
    src = res.aiding["tag"]
    assert (rows.system == "tag").all() and (rows.aiding == "anchor_range").all()
    assert rows.accepted.sum() == src.diagnostics()["anchor_ranges"]["accepted"]
    assert len(rows) == src.diagnostics()["anchor_ranges"]["accepted"] + src.diagnostics()["anchor_ranges"][
        "rejected_by_gate"]
    assert set(rows.end) <= set(ANCHORS) and np.isfinite(rows.nis).all()


def test_every_stance_update_has_its_nis_in_the_innovations(vicon):
    rows = vicon.innovations()
    zupt = rows[(rows.system == "right_foot") & (rows.aiding == "zupt")]
    diag = vicon.systems["right_foot"].diagnostics()
    assert len(zupt) == diag["zupt_updates"] and (zupt.dof == 3).all()
    assert (~zupt.accepted).sum() == diag["zupt_gated"]
    assert zupt.nis.mean() == pytest.approx(diag["zupt_mean_nis"], rel=1e-9)
    assert zupt.t.is_monotonic_increasing


def test_a_system_exports_to_an_xarray_dataset_with_its_states_named_and_its_units(vicon):
    pytest.importorskip("xarray")
    import json

    ds = vicon.to_xarray("left_foot")
    traj, score, history = vicon.trajectories["left_foot"], vicon.scores["left_foot"], vicon.covariances("left_foot")
    np.testing.assert_array_equal(ds["t"], traj.t)
    np.testing.assert_array_equal(ds["north_m"], traj.pos_n[:, 1])
    np.testing.assert_array_equal(ds["sd_up_m"], traj.pos_sd[:, 2])
    np.testing.assert_array_equal(ds["heading_deg"], vicon.states("left_foot")["heading_deg"])
    np.testing.assert_array_equal(ds["horizontal_error_m"], score.horizontal_error_m)
    np.testing.assert_array_equal(ds["t_truth"], score.t)
    # the covariance by the states' names, as the system stores it
    np.testing.assert_array_equal(ds["covariance"].sel(state="east_m", state_other="north_m"), history.matrix[:, 0, 1])
    assert list(ds["state"].values) == list(history.states)
    assert ds["east_m"].attrs["units"] == "m" and ds["t"].attrs["units"] == "s"
    assert ds["v_up_mps"].attrs["units"] == "m/s"
    assert json.loads(ds.attrs["frame"]) == vicon.frame.to_dict() and ds.attrs["system"] == "left_foot"
    with pytest.raises(KeyError, match="no system"):
        vicon.to_xarray("hand")


def test_a_hand_dataset_has_its_whole_error_state_covariance_on_its_records():
    pytest.importorskip("xarray")
    from bodyfusion.core.layout import validate_layout
    from bodyfusion.sim.scenario import simulated

    layout, tables = simulated(CONFIGS / "foot_hand_gnss_outage.yaml", 0).in_memory()
    result = run_layout(validate_layout(layout, None, CONFIGS, tables=tables))
    ds = result.to_xarray("hand_phone")
    history = result.covariances("hand_phone")
    assert ds.sizes["t"] == len(result.trajectories["hand_phone"].t)
    np.testing.assert_array_equal(ds["t_covariance"], history.t)  # each step and update
    assert ds.sizes["state"] == len(history.states) >= 8
    assert np.all(np.isfinite(ds["covariance"].values))
