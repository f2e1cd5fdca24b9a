"""Distance limits from the body (bodyfusion.core.body, bodyfusion.core.limits): they hold on every
walk with truth, follow the gait, defend themselves against a fight, and the truth's own breaks
are reported."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.body import FOOT_FLOOR_SHARE, body_limit
from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout
from bodyfusion.sim import simulate
from tests.paths import ROOT, needs_shared

VICON = ROOT / "configs" / "dual_foot_vicon.yaml"
BODY_LIMIT = ["constraints=[{between: [left_foot, right_foot]}]", "fuser.method=projection"]


@settings(max_examples=50, deadline=None)
@given(height=st.floats(1.0, 2.3), stride=st.floats(0.0, 6.0))
def test_body_limits_follow_the_stride_within_the_body(height, stride):
    walking = body_limit("foot", "foot", height)
    gait = body_limit("foot", "hand", height, stride)
    assert body_limit("hand", "foot", height, stride) == gait
    assert FOOT_FLOOR_SHARE * height <= body_limit("foot", "foot", height, stride) <= 1.3 * 1.6 * height
    assert body_limit("foot", "foot", height, stride + 0.5) >= body_limit("foot", "foot", height, stride)
    assert walking == pytest.approx(np.hypot(0.6 * height, 0.11 * height))
    assert body_limit("foot", None, height) is None and body_limit("hand", "hand", height) is None


def test_the_walking_limits_of_an_average_adult():
    assert body_limit("foot", "foot", 1.75) == pytest.approx(1.07, abs=0.005)
    assert body_limit("foot", "hand", 1.75) == pytest.approx(1.49, abs=0.005)  # the PDR/GNSS paper's 1.5 m


def _truth_margin(result) -> float:
    """The least (limit − truth separation) / limit over the fuser's epochs."""
    log, truth = result.fuser.constraint_log, result.truths
    t = log.t[:log.n]
    sep = np.hypot(*[np.interp(t, truth["left_foot"].t, truth["left_foot"].pos_n[:, d])
                     - np.interp(t, truth["right_foot"].t, truth["right_foot"].pos_n[:, d]) for d in range(2)])
    return float(np.min(1.0 - sep / log.limit[:log.n, 0]))


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["sim_dual_foot_square", "sim_running", "sim_stairs",
                                      "sim_dual_foot_consumer_walk"])
def test_the_body_limit_holds_on_every_simulated_gait(scenario, tmp_path):
    """A walk, a run, stairs and a long consumer-grade walk: the truth's feet stay inside the limit
    at every epoch with a margin, and no fight or break is reported."""
    config = simulate(ROOT / "configs" / f"{scenario}.yaml", tmp_path, seed=1).config_path
    result = run_layout(load_layout(config, BODY_LIMIT))
    assert _truth_margin(result) > 0.15, scenario
    assert not [f for f in result.findings if f.kind in ("constraint_fight", "limit_broken_by_truth")]


@needs_shared("dual_foot_vicon_hu2025")
def test_the_body_limit_holds_on_the_vicon_walk_and_pulls_like_the_authors_own():
    """Hu & Hu's walk turns all the time in a 4.6 m × 1.6 m room (feet up to 0.52 m apart): the
    body limit follows its short strides down to about their own 0.6 m, and holds."""
    result = run_layout(load_layout(VICON, BODY_LIMIT))
    assert _truth_margin(result) > 0.05
    assert result.fuser.limits.stride_m() == pytest.approx(0.8, abs=0.1)
    assert result.fuser.constraint_log.limit[5:result.fuser.constraint_log.n, 0].max() <= 0.75  # strides known
    free = run_layout(load_layout(VICON, ["fuser.method=none"]))
    for foot in ("left_foot", "right_foot"):
        rmse = {r: res.scores[foot].metrics["horizontal_error_m"]["rmse"] for r, res in (("body", result), ("free", free))}
        assert rmse["body"] < rmse["free"], (foot, rmse)


@needs_shared("dual_foot_vicon_hu2025")
def test_a_limit_between_feet_in_frames_150_degrees_apart_is_relaxed_and_reported():
    """Headings set by hand 150° apart and no tie: the 0.6 m limit would drag both tracks (it
    fights them); the fuser relaxes it, says so, and both feet end nearer the truth."""
    wrong = ["systems.left_foot.initial.heading_deg=0", "systems.right_foot.initial.heading_deg=150",
             "heading_alignment.continuous=false", "constraints.0.distance_m=0.6"]
    relaxed = run_layout(load_layout(VICON, wrong))
    pulled = run_layout(load_layout(VICON, [*wrong, "fuser.relax_fights=false"]))
    (fight,) = [f for f in relaxed.findings if f.kind == "constraint_fight"]
    assert "relaxed it" in fight.message and fight.cause and fight.advice
    assert relaxed.fuser.limits.summary()["relaxation_m"][0] > 1.0
    assert pulled.fuser.limits.summary()["relaxation_m"][0] == 0.0
    for foot in ("left_foot", "right_foot"):
        assert (relaxed.scores[foot].metrics["horizontal_error_m"]["rmse"]
                < 0.8 * pulled.scores[foot].metrics["horizontal_error_m"]["rmse"]), foot


@needs_shared("dual_foot_vicon_hu2025")
def test_a_limit_the_truth_breaks_is_reported_in_the_score():
    result = run_layout(load_layout(VICON, ["constraints.0.distance_m=0.45"]))
    (broken,) = [f for f in result.findings if f.kind == "limit_broken_by_truth"]
    assert "0.52 m apart" in broken.message and "0.45 m" in broken.message
    fine = run_layout(load_layout(VICON))
    assert not [f for f in fine.findings if f.kind == "limit_broken_by_truth"]


def test_a_body_limit_needs_two_parts_the_body_knows():
    """A random walk is worn nowhere the body knows: its limit must be given, at validation."""
    config = ROOT / "configs" / "paper_constraint_monte_carlo.yaml"
    with pytest.raises(ConfigError, match=r"constraints\.0\.distance_m.*give distance_m in metres"):
        load_layout(config, ["constraints.0.distance_m=body"])
    with pytest.raises(ConfigError, match=r"constraints\.0\.distance_m"):
        load_layout(VICON, ["constraints=[{between: [left_foot, right_foot], kind: min}]"])


def _jumped_fixes(tables: dict, east_m: float, after_s: float) -> None:
    """The phone's GNSS fixes moved ``east_m`` east from ``after_s`` on, and left there."""
    (key,) = [k for k in tables if "gnss" in k]
    fixes = tables[key]
    lat = np.deg2rad(fixes["lat_deg"][0])
    later = fixes["t"] >= after_s
    fixes["lon_deg"] = np.where(later, fixes["lon_deg"] + np.rad2deg(east_m / (6378137.0 * np.cos(lat))),
                                fixes["lon_deg"])


@pytest.mark.slow
@pytest.mark.parametrize("east_m", [50e3, 1e6])
def test_a_gnss_jump_that_stays_is_followed_by_the_body_not_fought_by_the_constraint(east_m):
    from bodyfusion.core.layout import validate_layout
    from bodyfusion.sim.scenario import simulated

    layout, tables = simulated(ROOT / "configs" / "foot_hand_gnss_outage.yaml", 0).in_memory()
    layout.pop("outages", None)
    _jumped_fixes(tables, east_m, 60.0)
    result = run_layout(validate_layout(layout, None, ROOT / "configs", tables=tables))
    (followed,) = [f for f in result.findings if f.kind == "reset_followed"]
    assert followed.system == "hand_phone" and 60.0 < followed.t_start < 75.0
    assert result.fuser.limits.summary()["resets_followed"] == 1
    assert result.systems["hand_phone"].diagnostics()["gnss"]["position_resets"] == 1
    # the foot moved with the phone: the limit never broken by more than a stride's worth again
    log = result.fuser.constraint_log
    assert result.fuser.max_violation_before_m < 20.0
    after = log.t[:log.n] > followed.t_start
    foot, phone = result.systems["left_foot"].trajectory(), result.systems["hand_phone"].trajectory()
    moved = np.interp(log.t[:log.n][after][-1], foot.t, foot.pos_n[:, 0]) - foot.pos_n[0, 0]
    assert moved > 0.99 * east_m
    assert np.hypot(*(foot.pos_n[-1, :2] - phone.pos_n[-1, :2])) < 1.6


def test_a_reset_within_the_limit_moves_no_other_system():
    from bodyfusion.core.layout import BodyConfig, ConstraintConfig
    from bodyfusion.core.limits import LimitGuard

    guard = LimitGuard([ConstraintConfig(between=["left_foot", "hand_phone"], kind="max", distance_m=1.5)],
                       [False], ["left_foot", "hand_phone"], ["foot", "hand"], {}, BodyConfig())
    assert not guard.beyond_limits("hand_phone", np.array([1.0, 1.0, 5.0]))  # 1.41 m horizontally
    assert guard.beyond_limits("hand_phone", np.array([1.2, 1.0, 0.0]))
    assert not guard.beyond_limits("right_foot", np.array([100.0, 0.0, 0.0]))  # held by no limit
    guard.follow(61.0, "hand_phone", ["left_foot"], np.array([3.0, 4.0, 0.0]))
    (finding,) = guard.findings()
    assert finding.kind == "reset_followed" and "5.0 m" in finding.message and "left_foot" in finding.message
