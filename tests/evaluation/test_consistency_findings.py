"""NEES and NIS get verdicts: a consistent run says nothing; one beyond its band gets a finding
naming how far and the likely cause from the course of its NEES over the run."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.core.layout import load_layout
from bodyfusion.evaluation.consistency import NeesTrack
from bodyfusion.evaluation.consistency_findings import CONSISTENT_FACTOR, nees_findings, nis_findings
from bodyfusion.runner import run_layout
from tests.paths import CONFIGS

T = np.linspace(0.0, 100.0, 1001)


def _chi2(scale: np.ndarray | float = 1.0, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).chisquare(2, T.size) * scale


@pytest.mark.parametrize("scale, kind, severity", [
    (np.ones(T.size), None, None),
    (np.full(T.size, 20.0), "nees_overconfident", "warning"),
    (np.full(T.size, 0.05), "nees_pessimistic", "info"),
    (np.where(T < 20.0, 200.0, 1.0), "initial_state_mismatch", "warning"),
    (np.exp(T / 12.0), "nees_drift", "warning"),
])
def test_a_nees_gets_the_verdict_its_course_says(scale, kind, severity):
    found = nees_findings({"foot": NeesTrack(T, _chi2(scale))})
    if kind is None:
        assert found == []
        return
    assert [(f.kind, f.severity, f.system) for f in found] == [(kind, severity, "foot")]
    assert "a consistent filter: 2" in found[0].message and found[0].advice


def test_an_initial_state_mismatch_is_placed_at_the_start():
    found = nees_findings({"foot": NeesTrack(T, _chi2(np.where(T < 20.0, 200.0, 1.0)))})
    assert found[0].t_start == 0.0 and found[0].t_end < 25.0


@pytest.mark.parametrize("mean, kind", [(3.1, None), (3.0 * CONSISTENT_FACTOR * 1.5, "nis_high"),
                                        (3.0 / CONSISTENT_FACTOR / 2.0, "nis_pessimistic")])
def test_a_mean_nis_beyond_its_band_is_named_with_its_cause(mean, kind):
    nis = {"foot": {"zupt": {"dof": 3, "expected": 3.0, "count": 500, "mean": mean, "beyond_gate": 4},
                    "zaru": {"dof": 3, "expected": 3.0, "count": 500, "mean": None, "beyond_gate": 0}}}
    found = nis_findings(nis, {"foot": (0.0, 60.0)})
    assert [f.kind for f in found] == ([] if kind is None else [kind])
    if kind == "nis_high":
        assert "zupt_sigma_mps" in found[0].advice and "4 beyond the gate" in found[0].message


def test_the_flagship_walk_is_consistent_and_says_nothing_about_it():
    result = run_layout(load_layout(CONFIGS / "dual_foot_vicon.yaml", ["output.plots=false"]))
    kinds = {f.kind for f in result.findings}
    assert not kinds & {"nees_overconfident", "nees_drift", "initial_state_mismatch", "nis_high"}
    assert all(1.0 / CONSISTENT_FACTOR < result.nees[n].summary()["mean"] / 2.0 < CONSISTENT_FACTOR
               for n in result.nees)


def test_against_a_fitted_truth_frame_the_verdicts_are_info_and_read_no_initial_mismatch():
    """The first metres fit the truth's frame to the estimate: the start of the NEES measures the
    fit, not the initial state, and the whole NEES is approximate."""
    start_high = NeesTrack(T, _chi2(np.where(T < 20.0, 200.0, 1.0)), alignment="first_3m")
    assert [(f.kind, f.severity) for f in nees_findings({"foot": start_high})] == [("nees_overconfident", "info")]
    drifting = NeesTrack(T, _chi2(np.exp(T / 12.0)), alignment="first_3m")
    assert [(f.kind, f.severity) for f in nees_findings({"foot": drifting})] == [("nees_drift", "info")]
