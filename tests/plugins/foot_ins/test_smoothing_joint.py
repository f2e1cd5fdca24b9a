"""The joint RTS of two feet the fuser corrected together (``smoother.joint`` with
``fuser.cross_covariance``), on the embedded dual-foot Vicon walk held by a 0.4 m limit (tighter
than the walk's 0.52 m, so that it acts)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bodyfusion.core.joint_smoothing import JointCorrections, smooth_jointly
from bodyfusion.core.layout import load_layout
from bodyfusion.runner.batch import finish_fusion, prepare_fusion, run_layout

VICON = Path(__file__).resolve().parents[3] / "configs" / "dual_foot_vicon.yaml"
TRACKED = ["fuser.cross_covariance=true", "constraints.0.distance_m=0.4", "output.plots=false"]


def rmse(result, name: str) -> float:
    return result.scores[name].metrics["horizontal_error_m"]["rmse"]


@pytest.fixture(scope="module")
def joint_fusion():
    """The joint RTS's run: the layout, the fusion (its fuser's log) and the result."""
    loaded = load_layout(VICON, TRACKED + ["smoother.kind=rts"])
    fusion = prepare_fusion(loaded)
    return loaded, fusion, finish_fusion(fusion)


@pytest.fixture(scope="module")
def runs(joint_fusion):
    """The constrained filter, its joint RTS and each foot's own RTS."""
    return {"joint": joint_fusion[2]} | {kind: run_layout(load_layout(VICON, TRACKED + extra)) for kind, extra in (
        ("filter", []), ("alone", ["smoother.kind=rts", "smoother.joint=false"]))}


def test_joint_rts_carries_the_cross_covariances_the_fuser_kept(runs):
    """Carried forward through each foot's own steps from one joint correction, the
    cross-covariance reaches the fuser's at the next, to rounding."""
    joint = runs["joint"].systems["left_foot"].diagnostics()["smoothing"]["joint"]
    assert joint["members"] == ["left_foot", "right_foot"]
    assert joint["events"] > 50
    assert joint["correction_failures"] == 0
    assert joint["cross_rebuild_rel_error"] < 1e-9


def test_joint_rts_is_not_worse_than_the_constrained_filter_on_either_foot(runs):
    for name in ("left_foot", "right_foot"):
        assert rmse(runs["joint"], name) <= rmse(runs["filter"], name)
    assert "joint" not in runs["alone"].systems["left_foot"].diagnostics()["smoothing"]


def test_joint_rts_without_a_joint_correction_is_each_foots_own_rts():
    """A limit the feet never reach: no correction joins them, and the joint sweep is each foot's
    own RTS, bit for bit (swept in chunks, the adjoint carried across)."""
    loose = [*TRACKED[:1], "constraints.0.distance_m=5", "output.plots=false", "smoother.kind=rts",
             "heading_alignment.continuous=false"]
    joint, alone = (run_layout(load_layout(VICON, loose + extra)) for extra in ([], ["smoother.joint=false"]))
    assert joint.systems["left_foot"].diagnostics()["smoothing"]["joint"]["corrections"] == 0
    for name in ("left_foot", "right_foot"):
        np.testing.assert_array_equal(joint.systems[name].smoothed_x, alone.systems[name].smoothed_x)
        np.testing.assert_array_equal(joint.systems[name].smoothed_pos_cov, alone.systems[name].smoothed_pos_cov)


def test_the_order_the_feet_are_swept_in_moves_the_tracks_by_a_centimetre_at_most(joint_fusion):
    """Each foot's own ZUPT does not correct the other (the fuser's tracked filter): it is not a
    Kalman update of the stacked state, and the sweep takes it back as the foot's own, an
    approximation the order of the sweep exposes: sweeping the right foot first instead of the
    left moves the smoothed tracks by 10 mm at most with this 0.4 m limit (1.6 mm at the
    layout's own)."""
    loaded, fusion, _ = joint_fusion
    log = fusion.fuser.joint.corrections
    left_first = {n: fusion.systems[n].smoothed_x[:, 0:3].copy() for n in log.names}
    idx = np.r_[15:30, 0:15]
    swapped = JointCorrections(log.names[::-1], [15, 15], log.t, [P[np.ix_(idx, idx)] for P in log.P_prior],
                               [P[np.ix_(idx, idx)] for P in log.P_post], [dx[idx] for dx in log.dx])
    smooth_jointly({n: fusion.systems[n].joint_smoothing_member(loaded.layout.smoother) for n in swapped.names},
                   swapped)
    for name, track in left_first.items():
        assert 0.0 < np.max(np.abs(fusion.systems[name].smoothed_x[:, 0:3] - track)) < 0.015


def test_a_batch_run_logs_every_joint_correction_for_the_joint_smoother_only(joint_fusion):
    _, fusion, result = joint_fusion
    ties = sum(int(np.sum([row[4] for row in tie.log])) for tie in result.fuser.heading_ties)
    assert len(fusion.fuser.joint.corrections.t) == result.fuser.activations + result.fuser.tail_truncations + ties
    assert prepare_fusion(load_layout(VICON, ["smoother.kind=rts", "output.plots=false"])).fuser.joint.corrections is None
