"""Every stance detector is a model: its defaults in ``__init__`` alone, ``detect`` returns the
detector with its results, and a detector of one's own is selected by its kind from a layout."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from bodyfusion.base.errors import ConfigError
from bodyfusion.nav.stance_detectors import STANCE_DETECTORS, Shoe, StanceDetector, register_stance_detector
from bodyfusion.plugins.foot_ins.config import DETECTOR_PARAMETERS, DetectorConfig
from tests.nav.test_detectors import synthetic

G = 9.81
RATE = 100.0


@pytest.fixture(params=sorted(STANCE_DETECTORS))
def detector_class(request) -> type[StanceDetector]:
    return STANCE_DETECTORS[request.param]


def test_parameters_are_set_in_init_with_their_defaults_and_kept_as_given(detector_class):
    made = detector_class()
    signature = inspect.signature(detector_class.__init__).parameters
    assert made.get_params() == {name: signature[name].default for name in detector_class.parameters()}


def test_detect_returns_the_detector_with_a_stance_flag_per_sample(detector_class):
    acc, gyro, truth = synthetic(seed=7)
    done = detector_class().detect(acc, gyro, RATE, G, labels=truth)
    assert isinstance(done, detector_class)
    assert done.stance.shape == truth.shape and done.stance.dtype == bool
    assert (done.stance == truth).mean() > 0.9  # every built-in detector finds the synthetic rests


def test_the_layout_leaves_every_default_to_the_detector(detector_class):
    """DetectorConfig holds no default of its own: every parameter field is unset by default, and
    every parameter of a built-in detector can be set from the layout."""
    assert all(DetectorConfig.model_fields[name].default is None for name in DETECTOR_PARAMETERS)
    assert set(detector_class.parameters()) <= set(DETECTOR_PARAMETERS)
    cfg = DetectorConfig(kind=detector_class.kind)
    assert cfg.detector().get_params() == detector_class().get_params()


def test_a_parameter_the_detector_does_not_take_is_refused_naming_it():
    with pytest.raises(ValueError, match="the labels detector takes no threshold"):
        DetectorConfig(kind="labels", threshold=1e4)
    with pytest.raises(ValueError, match="unknown stance detector 'nope'"):
        DetectorConfig(kind="nope")
    with pytest.raises(ValueError, match="threshold must be below motion_threshold"):
        DetectorConfig(kind="adaptive", threshold=1e8)


def test_a_kind_is_registered_once():
    class Again(Shoe):
        kind = "shoe"

    with pytest.raises(ValueError, match="taken by Shoe"):
        register_stance_detector(Again)
    with pytest.raises(TypeError):
        register_stance_detector(int)


def test_a_registered_detector_of_ones_own_runs_from_a_layout(tmp_path):
    """A detector that calls stance wherever the angular rate is below a bound, registered by
    kind: a layout selects it and sets its parameter, and the foot INS uses its decisions."""
    from bodyfusion.core.layout import load_layout
    from bodyfusion.runner import run_layout
    from tests.paths import CONFIGS

    class SlowTurn(StanceDetector):
        kind = "slow_turn_test"

        def __init__(self, threshold: float = 0.5) -> None:
            self.threshold = threshold

        def detect(self, acc_b, gyro_b, rate_hz, gravity, labels=None):
            self.stance = np.linalg.norm(gyro_b, axis=1) < self.threshold
            return self

    register_stance_detector(SlowTurn)
    try:
        overrides = ["systems.left_foot.detector={kind: slow_turn_test, threshold: 0.6}", "fuser.method=none",
                     "constraints=[]"]
        loaded = load_layout(CONFIGS / "dual_foot_vicon.yaml", overrides)
        result = run_layout(loaded)
        foot = result.systems["left_foot"]
        expected = np.linalg.norm(foot.stream.gyro_b, axis=1) < 0.6
        np.testing.assert_array_equal(foot.stance_detection.detected, expected)
        with pytest.raises(ConfigError, match="takes no low"):
            load_layout(CONFIGS / "dual_foot_vicon.yaml",
                        ["systems.left_foot.detector={kind: slow_turn_test, low: 1.0}"])
    finally:
        del STANCE_DETECTORS["slow_turn_test"]
