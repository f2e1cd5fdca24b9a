"""The phone's GNSS aiding (bodyfusion.plugins.hand_pdr.gnss_aiding, track_heading): the heading
from the shape of the GNSS track, and the re-anchoring of a dead reckoning that strays; on the
shared IPIN 2023 logs the fused track is never worse than the phone's GNSS alone."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout
from bodyfusion.plugins.hand_pdr.gnss_aiding import BIAS_LIMIT
from bodyfusion.plugins.hand_pdr.track_heading import MIN_FIXES, WINDOW_M, TrackHeading
from tests.paths import CONFIGS, SHARED_DATA, needs_shared

IPIN = SHARED_DATA / "handheld_phone_ipin2023"


@settings(max_examples=30, deadline=None)
@given(error_deg=st.floats(-40.0, 40.0), turn=st.floats(-1.5, 1.5), seed=st.integers(0, 1000))
def test_the_track_measures_the_dead_reckonings_heading_error(error_deg, turn, seed):
    """The walk the fixes trace (1 m a second, turning) against the dead reckoning of steps whose
    heading is off by the error: the stretch measures the error (clockwise, true minus
    estimated) within its own σ, whatever the step scale."""
    rng = np.random.default_rng(seed)
    track = TrackHeading(correlated_fraction=0.8)
    heading, position = 0.3, np.zeros(2)
    got = None
    for k in range(40):
        heading += turn / 40
        step = np.array([np.sin(heading), np.cos(heading)])
        position = position + step
        track.step(0.9, heading - np.radians(error_deg))  # a step model 10 % short, a heading off
        track.add(position + rng.normal(0, 0.3, 2) + [5.0, -3.0], 2.0)  # a fix: its bias and its noise
        got = got or track.measure()
    z, r_var = got
    assert abs(np.degrees(z) - error_deg) < max(3 * np.degrees(np.sqrt(r_var)), 0.5)
    assert np.degrees(np.sqrt(r_var)) < 10.0


def test_a_stretch_needs_its_walk_and_its_fixes():
    track = TrackHeading(correlated_fraction=0.8)
    for k in range(MIN_FIXES - 1):
        track.step(WINDOW_M, 0.0)
        track.add(np.array([0.0, WINDOW_M * k]), 3.0)
    assert track.measure() is None
    track.clear()
    assert track.points == [] and track.walked_m == 0.0


@needs_shared("handheld_phone_ipin2023")
@pytest.mark.parametrize("log", sorted(p.name for p in IPIN.glob("IPIN2023_T3_*.txt")) or ["none"])
def test_the_fused_phone_is_never_worse_than_its_gnss_alone(log):
    """Every shared IPIN 2023 log, run with defaults: the 75th percentile of the fused error at the
    surveyed points is at most the GNSS's alone (the last fix at or before each point)."""
    result = run_layout(load_layout(CONFIGS / "ipin2023_trial01.yaml", [f"systems.hand_phone.phone_log={IPIN / log}",
                                                                         f"truth.path={IPIN / log}"]))
    fused = result.scores["hand_phone"].metrics["horizontal_error_m"]["p75"]
    alone = result.sensor_alone["hand_phone"]["horizontal_error_m"]["p75"]
    assert fused <= alone, (fused, alone)
    assert not [f for f in result.findings if f.kind == "worse_than_sensor_alone"]


def test_a_reanchoring_is_reported_and_named_as_the_cause_of_the_error_it_makes(dual_foot_hand_walk):
    """On the simulated loop the fixes of the last seconds carry a slow error of ~11 m (4 times
    their correlated σ): the phone takes its position afresh from the last fix. The run reports
    the re-anchoring, its move and bias, and the large error it makes names it as its cause."""
    result = run_layout(load_layout(dual_foot_hand_walk))
    hand = result.systems["hand_phone"]
    (t, move, bias, _), = hand.reanchors
    assert t == 165.0 and 10.0 < move < 13.0 and bias > BIAS_LIMIT
    kinds = {(f.kind, f.system): f for f in result.findings}
    reanchored = kinds[("gnss_reanchored", "hand_phone")]
    assert reanchored.t_start == 165.0 and f"moved {move:.1f} m" in reanchored.message
    assert "gnss reanchored at t = 165.0" in kinds[("large_error", "hand_phone")].cause
