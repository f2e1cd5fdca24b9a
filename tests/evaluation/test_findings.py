"""What a score says went wrong (bodyfusion.evaluation.findings): an error over 1 m always comes
with its likely cause, the run's own findings first, else the shape of the error; a truth that
drops out is named; a fused track worse than its sensor alone is a warning."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.base.findings import Finding
from bodyfusion.evaluation.findings import large_error_findings, sensor_alone_findings
from bodyfusion.evaluation.metrics import SystemScore, error_stats, sensor_alone_score
from bodyfusion.base.types import TruthTrack


def loop(n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 100.0, n)
    a = 2 * np.pi * t / 50.0
    return t, np.column_stack([10 * np.cos(a) + 0.05 * t, 10 * np.sin(a), np.zeros(n)])


def score_of(t: np.ndarray, est: np.ndarray, truth: np.ndarray) -> SystemScore:
    err = np.hypot(*(est - truth)[:, :2].T)
    return SystemScore(t, est, truth, err, np.zeros_like(err), {"horizontal_error_m": error_stats(err)})


def rotate(p: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.column_stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1], p[:, 2]])


def test_an_error_under_a_metre_says_nothing():
    t, truth = loop()
    assert large_error_findings({"foot": score_of(t, truth + 0.3, truth)}, []) == []


@pytest.mark.parametrize("shape,word", [("scale", "scale error"), ("drift", "heading drift"), ("jump", "a jump")])
def test_an_error_over_a_metre_names_the_shape_of_its_cause(shape, word):
    t, truth = loop()
    if shape == "scale":
        est = truth * [1.15, 1.15, 1.0]
    elif shape == "drift":
        est = rotate(truth, np.radians(20.0) * t / t[-1])
    else:
        est = truth.copy()
        est[300:, 0] += 2.0
    (finding,) = large_error_findings({"foot": score_of(t, est, truth)}, [])
    assert finding.kind == "large_error" and finding.severity == "warning" and finding.system == "foot"
    assert word in finding.cause and finding.advice
    assert "beyond 1 m" in finding.message


def test_an_error_over_a_metre_cites_the_runs_own_findings_first():
    t, truth = loop()
    own = Finding("missed_stances", "warning", "foot", 10.0, 30.0, "m", "c", "a")
    other = Finding("missed_stances", "warning", "hand", 10.0, 30.0, "m", "c", "a")
    (finding,) = large_error_findings({"foot": score_of(t, truth * [1.2, 1.2, 1.0], truth)}, [own, other])
    assert "missed stances at t = 10.0–30.0 s" in finding.cause and "hand" not in finding.cause


def test_a_truth_that_drops_out_takes_the_blame_for_its_spike():
    t, truth = loop()
    est = truth.copy()
    truth = truth.copy()
    truth[200:203, :2] = truth[199, :2]  # a marker lost ...
    truth[203:, :2] += [5.0, 0.0]  # ... found again 5 m off, at once (20 m/s)
    (finding,) = large_error_findings({"foot": score_of(t, est, truth)}, [])
    assert finding.kind == "truth_dropout" and finding.severity == "info"


def test_a_fused_track_worse_than_its_fixes_alone_is_a_warning():
    t, truth = loop()
    fixes = truth + np.array([1.0, 0.0, 0.0])
    alone = sensor_alone_score(t, fixes, TruthTrack(t, truth))
    assert alone["horizontal_error_m"]["p75"] == pytest.approx(1.0)
    worse = score_of(t, truth + np.array([0.0, 2.0, 0.0]), truth)
    better = score_of(t, truth + np.array([0.0, 0.5, 0.0]), truth)
    (finding,) = sensor_alone_findings({"phone": worse}, {"phone": alone})
    assert finding.kind == "worse_than_sensor_alone" and "2.00 m against 1.00 m" in finding.message
    assert sensor_alone_findings({"phone": better}, {"phone": alone}) == []


def test_the_sensor_alone_is_held_from_its_last_fix():
    truth = TruthTrack(np.array([0.5, 1.5, 9.0]), np.zeros((3, 3)))
    alone = sensor_alone_score(np.array([1.0, 2.0]), np.array([[1.0, 0, 0], [2.0, 0, 0]]), truth)
    # before the first fix: the first; after the last: the last
    assert alone["horizontal_error_m"]["max"] == pytest.approx(2.0)
    assert alone["horizontal_error_m"]["p50"] == pytest.approx(1.0)
