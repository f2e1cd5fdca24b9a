"""The missed-stance watchdog (bodyfusion.plugins.foot_ins.stance): a stretch without stance longer
than two strides gets one loose update per stride at its stillest instant, counted, timed and
reported; a ZUPT lockout is found; a detector that finds every stance is left alone."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout
from bodyfusion.plugins.foot_ins.stance import StanceDetection, _watch, stance_findings
from bodyfusion.sim import simulate
from tests.paths import ROOT

RATE = 100.0


def _gait(strides: int, period_s: float = 1.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A statistic with one valley per stride (its least value at a known sample), the stance
    flags of a detector that found them all, and the valleys' samples."""
    n_stride = int(period_s * RATE)
    phase = np.arange(strides * n_stride) % n_stride
    statistic = 1e7 * (1.0 - np.cos(2 * np.pi * phase / n_stride)) + 1e3 + phase  # least at phase 0
    valleys = np.arange(strides) * n_stride
    stance = np.zeros(statistic.size, dtype=bool)
    for v in valleys:
        stance[max(0, v - 5):v + 15] = True
    return statistic, stance, valleys


def test_a_detector_that_finds_every_stance_is_left_alone():
    statistic, stance, _ = _gait(20)
    found = StanceDetection(stance, stance, np.full(stance.size, 1.1), np.zeros_like(stance))
    _watch(found, statistic, 3, RATE)
    assert found.missed == [] and not found.fallback.any() and found.stance is stance


def test_each_missed_stride_gets_one_fallback_at_its_stillest_instant():
    statistic, stance, valleys = _gait(20)
    detected = stance.copy()
    detected[5 * 110:15 * 110 - 20] = False  # the detector misses the stances of strides 5..14
    found = StanceDetection(detected, detected, np.full(stance.size, 1.1), np.zeros_like(stance))
    _watch(found, statistic, 3, RATE)
    (a, b, n), = found.missed
    assert a == 5 * 110 and 8 <= n <= 10
    marked = np.flatnonzero(np.diff(np.concatenate(([0], found.fallback.astype(int)))) == 1)
    assert np.all(np.min(np.abs(marked[:, None] - valleys[None, :]), axis=1) <= 2)  # at the valleys
    assert found.stance[marked].all() and found.missed_stances == n


def test_a_foot_moving_without_a_gait_is_restless_not_missing_stances():
    """No stride repeats in the stretch (the period is unknown there: turning on the spot): the
    fallbacks are made all the same, but it is said as a restless foot, for information."""
    statistic, stance, _ = _gait(20)
    detected = stance.copy()
    detected[5 * 110:15 * 110 - 20] = False
    period = np.full(stance.size, 1.1)
    period[5 * 110:15 * 110] = np.nan
    found = StanceDetection(detected, detected, period, np.zeros_like(stance))
    _watch(found, statistic, 3, RATE)
    assert found.missed == [] and len(found.restless) == 1 and found.fallback.any()
    (finding,) = stance_findings("left_foot", found, np.arange(stance.size) / RATE, np.full(stance.size, -1.0), 16.27)
    assert finding.kind == "restless_foot" and finding.severity == "info"


def test_missed_stances_and_lockouts_are_findings():
    statistic, stance, _ = _gait(20)
    detected = stance.copy()
    detected[3 * 110:12 * 110] = False
    found = StanceDetection(detected, detected, np.full(stance.size, 1.1), np.zeros_like(stance))
    _watch(found, statistic, 3, RATE)
    t = np.arange(stance.size) / RATE
    nis = np.where(found.stance, 1.0, -1.0)
    nis[13 * 110 - 5:19 * 110][found.stance[13 * 110 - 5:19 * 110]] = 1e3  # every update beyond the gate
    kinds = {f.kind: f for f in stance_findings("left_foot", found, t, nis, 16.27)}
    assert set(kinds) == {"missed_stances", "zupt_lockout"}
    missed = kinds["missed_stances"]
    assert missed.system == "left_foot" and missed.severity == "warning" and missed.t_start == pytest.approx(3.3)
    assert "stances missed" in missed.message and missed.cause and missed.advice
    assert kinds["zupt_lockout"].t_start == pytest.approx(14.25)  # the first stance run of stride 13


@pytest.mark.slow
def test_a_detector_that_misses_most_stances_is_caught_and_the_walk_kept(tmp_path):
    """A fixed SHOE threshold far too low for the walk: most stances are missed; the watchdog's
    loose updates keep the track within metres of the truth instead of kilometres, and say so."""
    cfg = simulate(ROOT / "configs" / "sim_dual_foot_square.yaml", tmp_path / "walk", seed=3).config_path
    result = run_layout(load_layout(cfg, ["systems.left_foot.detector={kind: shoe, threshold: 1}",
                                          "systems.right_foot.detector={kind: adaptive}", "fuser.method=none"]))
    left = result.systems["left_foot"]
    assert left.diagnostics()["missed_stances"] > 10
    assert left.diagnostics()["fallback_updates"] > 0
    assert result.scores["left_foot"].metrics["horizontal_error_m"]["rmse"] < 0.5  # measured 0.048 (0.051 detected)
    assert any(f.kind == "missed_stances" and f.system == "left_foot" for f in result.findings)
    assert not any(f.kind == "missed_stances" and f.system == "right_foot" for f in result.findings)


@pytest.mark.slow
def test_a_zupt_lockout_is_broken_and_reported(tmp_path, monkeypatch):
    """Two corrupt gyroscope samples (50 rad/s) in a swing turn the foot's attitude by a radian;
    every update of the next stance is beyond the gate. The filter re-inflates its velocity and
    level covariance after that stance, the next one pulls it back, and the run says so: the
    track stays within metres (the heading the spike turned is not observable) where without the
    recovery it runs away; the whole-run RTS smooths through the recovery."""
    import pandas as pd

    from bodyfusion.plugins.foot_ins import system

    sim = simulate(ROOT / "configs" / "sim_perfect_walk.yaml", tmp_path, seed=0,
                   overrides=["systems={left_foot: {kind: foot_imu, foot: left, imu: {preset: icm20948}}}", "layout={}"])
    imu = pd.read_csv(tmp_path / "left_foot_imu.csv")
    swing = int(np.flatnonzero((imu.stance.to_numpy()[:-1] == 1) & (imu.stance.to_numpy()[1:] == 0))[10]) + 10
    imu.loc[swing:swing + 1, "gyro_x"] = 50.0
    imu.to_csv(tmp_path / "left_foot_imu.csv", index=False)
    adaptive = ["systems.left_foot.detector={kind: adaptive}"]
    result = run_layout(load_layout(sim.config_path, adaptive))
    left = result.systems["left_foot"]
    assert left.diagnostics()["zupt_recoveries"] >= 1
    assert any(f.kind == "zupt_lockout" and "re-inflated" in f.message for f in result.findings)
    rmse = result.scores["left_foot"].metrics["horizontal_error_m"]["rmse"]
    smoothed = run_layout(load_layout(sim.config_path, [*adaptive, "smoother.kind=rts"]))
    assert smoothed.systems["left_foot"].diagnostics()["smoothing"]["warnings"] == 0
    assert smoothed.scores["left_foot"].metrics["horizontal_error_m"]["rmse"] <= 1.05 * rmse
    monkeypatch.setattr(system, "MIN_LOCKOUT_SAMPLES", 10**9)  # no recovery
    locked = run_layout(load_layout(sim.config_path, adaptive)).scores["left_foot"].metrics["horizontal_error_m"]
    assert rmse < 0.5 * locked["rmse"], (rmse, locked["rmse"])
