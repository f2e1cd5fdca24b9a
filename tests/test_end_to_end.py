"""End to end: ``fusion simulate`` then ``fusion run`` on walks whose truth is known exactly."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout
from bodyfusion.sim import simulate
from tests.paths import CONFIGS


@pytest.fixture(scope="module")
def perfect_walk(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("perfect")
    return simulate(CONFIGS / "sim_perfect_walk.yaml", out, seed=0).config_path


def test_error_free_imus_navigate_to_under_a_centimetre_after_a_minute_of_walking(perfect_walk):
    """A check of mechanisation + ZUPT filter on exact data: > 60 s of walking, < 1 cm (each
    foot on its own: the relative-heading tie between them is checked next)."""
    result = run_layout(load_layout(perfect_walk, ["heading_alignment.continuous=false"]))
    for name, score in result.scores.items():
        assert score.t[-1] - score.t[0] > 60.0
        assert score.metrics["horizontal_error_m"]["max"] < 0.01, name
        assert score.metrics["vertical_error_m"]["max"] < 0.01, name


def test_the_heading_tie_of_error_free_feet_measures_no_drift(perfect_walk):
    """Exact feet have no relative heading drift: the tie's measurements (their paths on the
    body's centreline) stay within half a degree, and the feet within 2 cm after 80 m."""
    result = run_layout(load_layout(perfect_walk))
    (tie,) = result.fuser.heading_ties
    assert tie.summary()["measurements"] >= 5 and tie.summary()["max_abs_deg"] < 0.5
    for name, score in result.scores.items():
        assert score.metrics["horizontal_error_m"]["max"] < 0.02, name


@pytest.mark.slow
def test_run_writes_the_contract_outputs_for_a_simulation(perfect_walk, tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "bodyfusion.cli", "run", str(perfect_walk), "--out", str(out)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["alignment"] == "none"
    assert set(doc["systems"]) == {"left_foot", "right_foot"}
    for block in doc["systems"].values():
        assert set(block["horizontal_error_m"]) == {"rmse", "mean", "max", "p50", "p75", "p90", "p95", "p99"}
        assert block["distance_m"] > 60
    lines = (out / "trajectories.csv").read_text().splitlines()
    assert lines[0].startswith("system,t,east_m,north_m,up_m,sd_east_m,sd_north_m,sd_up_m,v_east_mps,")
    assert len(lines) - 1 == sum(b["samples"] for b in doc["systems"].values())
    for png in ("trajectory.png", "error_vs_time.png", "error_cdf.png"):
        assert (out / png).stat().st_size > 1000


def test_icm20948_walk_stays_within_one_percent_of_distance(tmp_path):
    """Realistic MEMS errors (FB-RTS paper Table 1 preset), SHOE detector, 2 laps of a
    20 m × 10 m rectangle: final error under 1 % of the distance for both feet."""
    config = simulate(CONFIGS / "sim_dual_foot_square.yaml", tmp_path, seed=3).config_path
    result = run_layout(load_layout(config))
    for name, score in result.scores.items():
        assert score.metrics["final_error_pct_distance"] < 1.0, name


def test_same_seed_gives_the_same_trajectory_bits(tmp_path):
    a = simulate(CONFIGS / "sim_dual_foot_square.yaml", tmp_path / "a", seed=5).config_path
    b = simulate(CONFIGS / "sim_dual_foot_square.yaml", tmp_path / "b", seed=5).config_path
    ra, rb = run_layout(load_layout(a)), run_layout(load_layout(b))
    for name in ra.trajectories:
        np.testing.assert_array_equal(ra.trajectories[name].pos_n, rb.trajectories[name].pos_n)
