"""examples/estimator_variants.py: one seed of its consumer-IMU walk, and its paired statistics."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest

from tests.paths import ROOT

EXAMPLE = ROOT / "examples" / "estimator_variants.py"


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location("estimator_variants", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


def test_one_seed_of_the_consumer_walk(example):
    runs = example.simulation_seed(0, plan={"ekf": ("none", "dc", "fixed")})
    none, dc, mdc = runs["ekf", "none"], runs["ekf", "dc"], runs["ekf", "fixed"]
    assert none["epochs"] == none["activations"] == 0
    independent = example.both_feet({k: np.array([v]) for k, v in none.items()})[0]
    constrained = example.both_feet({k: np.array([v]) for k, v in dc.items()})[0]
    # the scenario's independent feet drift metres; the limit acts on a tenth of the epochs or more
    assert 0.5 < independent < 15.0
    assert 2.0 < max(none["end_left_foot"], none["end_right_foot"]) < 15.0
    assert dc["epochs"] > 300 and dc["activations"] / dc["epochs"] >= 0.10
    assert constrained < independent
    # the literal equality at the step width is wrong at every stance start
    assert mdc["activations"] == mdc["epochs"]
    assert min(mdc["rmse_left_foot"], mdc["rmse_right_foot"]) > 10 * independent


def test_paired_statistics(example):
    b = np.array([2.0, 4.0, 6.0, 8.0])
    a = 0.5 * b
    d, se, rel, se_rel, lower = example.paired(a, b)
    assert d == pytest.approx(-2.5) and rel == pytest.approx(-0.5)
    assert se == pytest.approx(np.std(a - b, ddof=1) / 2) and se_rel == pytest.approx(0.0, abs=1e-12)
    assert lower == 4
    assert example.verdict(-1.0, 0.1).startswith("lower") and example.verdict(0.1, 0.1).startswith("within")
