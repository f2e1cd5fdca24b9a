"""The gait table (bodyfusion.plugins.foot_ins.strides): strides from stance to stance, checked
against the truth's, and the motion of each on walking, running and stair gaits; strides.csv."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run, run_layout
from bodyfusion.plugins.foot_ins.strides import classify, stride_table
from bodyfusion.sim import simulate
from tests.paths import ROOT, needs_shared


def test_a_stride_runs_from_stance_middle_to_stance_middle():
    t = np.arange(0.0, 4.0, 0.01)
    stance = (np.mod(t, 1.0) < 0.4)  # stances at 0-0.4, 1-1.4, ...: middles at 0.195, 1.195, ...
    pos = np.column_stack([1.2 * np.floor(t) + 1.2 * np.clip((np.mod(t, 1.0) - 0.4) / 0.6, 0, 1),
                           np.zeros_like(t), 0.1 * np.sin(np.pi * np.clip((np.mod(t, 1.0) - 0.4) / 0.6, 0, 1))])
    table = stride_table(t, pos, stance)
    assert table["stride"].tolist() == [0, 1, 2]
    np.testing.assert_allclose(table["length_m"], 1.2)
    np.testing.assert_allclose(table["duration_s"], 1.0, atol=0.011)  # the middle sample of 40
    np.testing.assert_allclose(table["clearance_m"], 0.1, atol=1e-3)
    assert list(table["motion"]) == ["walk"] * 3


def test_motions_by_length_speed_and_climb():
    motion = classify(np.array([1.4, 2.4, 0.6, 0.6, 0.1, 1.6]), np.array([1.1, 0.7, 1.3, 1.3, 1.0, 0.8]),
                      np.array([0.0, 0.0, 0.34, -0.34, 0.0, 0.0]))
    assert list(motion) == ["walk", "run", "stairs_up", "stairs_down", "shuffle", "run"]


@pytest.mark.slow
@pytest.mark.parametrize("scenario,expected", [("sim_dual_foot_square", {"walk"}), ("sim_running", {"run"}),
                                               ("sim_stairs", {"stairs_up", "stairs_down", "walk"})])
def test_the_stride_table_of_simulated_gaits_matches_their_truth(scenario, expected, tmp_path):
    sim = simulate(ROOT / "configs" / f"{scenario}.yaml", tmp_path, seed=1)
    result = run_layout(load_layout(sim.config_path))
    strides = result.strides()
    left = strides[strides.system == "left_foot"]
    truth = result.truths["left_foot"]
    ends = np.column_stack([np.interp(left[c], truth.t, truth.pos_n[:, 0]) for c in ("t_start", "t_end")])
    ends_n = np.column_stack([np.interp(left[c], truth.t, truth.pos_n[:, 1]) for c in ("t_start", "t_end")])
    true_length = np.hypot(ends[:, 1] - ends[:, 0], ends_n[:, 1] - ends_n[:, 0])
    moving = true_length > 0.3
    assert np.median(np.abs(left.length_m.to_numpy()[moving] / true_length[moving] - 1.0)) < 0.02
    main = left.motion[moving].value_counts()
    assert set(main.index[main > 0.1 * moving.sum()]) == expected, main


@needs_shared("dual_foot_vicon_hu2025")
def test_the_vicon_walks_strides_are_the_truths_within_five_percent(tmp_path):
    result, out = run(ROOT / "configs" / "dual_foot_vicon.yaml", out_dir=tmp_path)
    rows = list(csv.DictReader((out / "strides.csv").open()))
    assert {r["system"] for r in rows} == {"left_foot", "right_foot"}
    assert list(rows[0]) == ["system", "stride", "t_start", "t_end", "length_m", "duration_s", "speed_mps", "climb_m",
                             "clearance_m", "motion"]
    for foot in ("left_foot", "right_foot"):
        s = result.strides()
        s = s[s.system == foot]
        truth = result.truths[foot]
        a = np.column_stack([np.interp(s.t_start, truth.t, truth.pos_n[:, k]) for k in range(2)])
        b = np.column_stack([np.interp(s.t_end, truth.t, truth.pos_n[:, k]) for k in range(2)])
        true_length = np.hypot(*(b - a).T)
        assert np.median(np.abs(s.length_m.to_numpy() / true_length - 1.0)) < 0.05, foot


def test_the_mounting_is_found_from_the_walk(tmp_path):
    """The square walk's right IMU points 7° clockwise of its foot (mount_yaw_deg: the walk is 7°
    counter-clockwise of its x axis), the left straight along: the diagnostics find both."""
    sim = simulate(ROOT / "configs" / "sim_dual_foot_square.yaml", tmp_path, seed=1)
    result = run_layout(load_layout(sim.config_path))
    angles = {n: result.systems[n].diagnostics()["mounting"]["forward_from_x_deg"] for n in ("left_foot", "right_foot")}
    assert angles["left_foot"] == pytest.approx(0.0, abs=0.5) and angles["right_foot"] == pytest.approx(7.0, abs=0.5)
    up = result.systems["left_foot"].diagnostics()["mounting"]["up_b"]
    assert up[2] > 0.999
