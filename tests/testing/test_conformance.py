"""bodyfusion.testing.check_system: every built-in plugin conforms, and the checker catches
seeded defects, each reported under its check's name."""

from __future__ import annotations

from typing import Literal

import numpy as np
import pytest
from pydantic import Field

from bodyfusion.base.sections import StrictModel
from bodyfusion.core.layout_io import read_yaml
from bodyfusion.core.system import SensorSystem
from bodyfusion.base.types import InputReport, Trajectory
from bodyfusion.plugins.foot_ins import FootIns
from bodyfusion.plugins.random_walk import RandomWalk
from bodyfusion.testing import (
    CHECKS,
    ConformanceError,
    JacobianCase,
    check_jacobian,
    check_system,
    default_context,
    strapdown15_jacobian_cases,
    undocumented_fields,
    with_value,
)
from tests.paths import CONFIGS

FOOT = read_yaml(CONFIGS / "dual_foot_vicon.yaml")["systems"]["left_foot"]
WALK = {"duration_s": 10.0, "start_m": [1.3, 2.7, 0.1], "increment_variance_m2": 0.01}


# --------------------------------------------------------------------------- built-ins


def test_foot_ins_conforms():
    report = check_system(
        FootIns, FOOT, name="left_foot", context=default_context(CONFIGS), stochastic=False,
        bad_configs=[
            (with_value(FOOT, "filter.acc_noise_density", -1.0), "filter.acc_noise_density"),
            (with_value(FOOT, "detector.kind", "psychic"), "detector.kind"),
            (with_value(FOOT, "data.stance_column", None), "detector.kind"),  # labels need a stance column
            (with_value(FOOT, "initial.stationary_s", 1e-6), "initial.stationary_s"),  # refused at build
        ])
    assert report.failed == [] and report.skipped == []


def test_random_walk_conforms():
    report = check_system(RandomWalk, WALK, stochastic=True, bad_configs=[
                              (with_value(WALK, "rate_hz", 0), "rate_hz"),
                              (with_value(WALK, "velocity_mps", [1.0, 2.0]), "velocity_mps")])
    assert report.failed == []
    assert report.skipped == ["jacobians"]  # no analytic Jacobians to check


# --------------------------------------------------------------------------- a toy system and its defects


class ToyConfig(StrictModel):
    """A 1-D walker along East."""

    plugin: Literal["toy"] = "toy"
    samples: int = Field(default=50, ge=2, description="Number of samples.")
    noise_m: float = Field(default=0.1, ge=0, description="Step noise (m), drawn from the run seed.")


class Toy(SensorSystem):
    """Position-only system that steps 1 m East per second with seeded noise; correct."""

    plugin_name = "toy"
    Config = ToyConfig

    def __init__(self, name, config, context):
        super().__init__(name, config, context)
        self.t = np.arange(config.samples, dtype=float)
        self.steps = self.draw_steps()
        self.x, self.P, self._i = np.zeros(3), np.eye(3) * 0.01, 0
        self.hist = [(self.x.copy(), np.diag(self.P).copy())]

    def draw_steps(self):
        from bodyfusion.base.seeding import system_seed

        rng = np.random.default_rng(system_seed(self.context.seed, self.name))
        return 1.0 + rng.normal(0, self.config.noise_m, self.t.size)

    def step_covariance(self):
        self.P = self.P + 0.01 * np.eye(3)

    t_start = property(lambda self: float(self.t[0]))
    t_end = property(lambda self: float(self.t[-1]))
    t_now = property(lambda self: float(self.t[self._i]))
    samples = property(lambda self: int(self.t.size))
    input_report = property(lambda self: InputReport())

    def advance(self, t):
        i1 = int(np.searchsorted(self.t, t, side="right"))
        for i in range(self._i + 1, i1):
            self.x = self.x + np.array([self.steps[i], 0.0, 0.0])
            self.step_covariance()
            self.hist.append((self.x.copy(), np.diag(self.P).copy()))
            self._i = i

    def position_n(self):
        return self.x.copy()

    def covariance(self):
        return self.P.copy()

    def apply_correction(self, dx, P):
        self.x = self.x + dx
        self.P = 0.5 * (P + P.T)
        self.hist[-1] = (self.x.copy(), np.diag(self.P).copy())

    def sync_times(self):
        return self.t[5::10]

    def sample_times(self):
        return self.t

    def trajectory(self):
        pos = np.array([h[0] for h in self.hist])
        var = np.array([h[1] for h in self.hist])
        return Trajectory(self.t[: len(self.hist)], pos, np.sqrt(np.maximum(var, 0.0)))


def failures(cls, **kw):
    with pytest.raises(ConformanceError) as info:
        check_system(cls, {}, **kw)
    return info.value


def test_a_correct_toy_passes():
    report = check_system(Toy, {}, stochastic=True, bad_configs=[({"samples": 1}, "samples")])
    assert report.failed == []


def test_asymmetric_covariance_is_caught():
    class Asymmetric(Toy):
        def step_covariance(self):
            self.P = self.P + 0.01 * np.eye(3)
            self.P[0, 1] += 1e-3  # one triangle only

    err = failures(Asymmetric, stochastic=True)
    assert "covariance" in err.report.failed
    assert "[covariance] failed" in str(err) and "not symmetric" in str(err)


def test_indefinite_covariance_is_caught():
    class Indefinite(Toy):
        def step_covariance(self):
            self.P = self.P - 0.02 * np.eye(3)

    err = failures(Indefinite, stochastic=True)
    assert "covariance" in err.report.failed and "positive semi-definite" in str(err)


def test_nondeterminism_is_caught():
    class Unseeded(Toy):
        def draw_steps(self):
            return 1.0 + np.random.default_rng().normal(0, self.config.noise_m, self.t.size)  # ignores the seed

    err = failures(Unseeded, stochastic=True)
    assert "seed" in err.report.failed  # (chunked and corrected runs differ from fresh ones too)
    assert "two builds with seed 0 differ" in str(err)


def test_ignoring_the_seed_is_caught_when_stochastic():
    class SeedBlind(Toy):
        def draw_steps(self):
            return 1.0 + np.random.default_rng(7).normal(0, self.config.noise_m, self.t.size)

    assert failures(SeedBlind, stochastic=True).report.failed == ["seed"]
    check_system(SeedBlind, {}, stochastic=False)


def test_undocumented_config_is_caught():
    class BareConfig(StrictModel):
        plugin: Literal["toy"] = "toy"
        samples: int = 50
        noise_m: float = Field(default=0.1, description="Step noise (m).")

    class Undocumented(Toy):
        Config = BareConfig

    err = failures(Undocumented, stochastic=True)
    assert err.report.failed == ["documented"]
    assert "undocumented parameters: samples" in str(err)


def test_documentation_rule():
    class Section(StrictModel):
        """Walk duration (s) and ``rate_hz``; the velocity."""

        plugin: str = "x"
        duration_s: float = 1.0           # named by its stem in the docstring
        rate_hz: float = 1.0              # named in the docstring
        velocity_mps: float = 1.0         # stem "velocity"
        lever_m: float = 0.0
        """Attribute docstring."""
        gain: float = Field(default=1.0, description="Described.")
        secret: float = 0.0

    assert undocumented_fields(Section) == ["secret"]


def test_stale_allow_undocumented_entries_fail():
    report = check_system(Toy, {}, stochastic=True, allow_undocumented=["samples"], checks=["documented"],
                          raise_on_failure=False)
    assert report.failed == ["documented"] and "stale" in report.result("documented").detail


def test_chunk_dependence_is_caught():
    class ChunkDependent(Toy):
        def advance(self, t):
            before = self._i
            super().advance(t)
            if self._i > before:
                self.x = self.x * (1 + 1e-15)  # something per call, not per sample

    err = failures(ChunkDependent, stochastic=True)
    assert "chunking" in err.report.failed


def test_bad_config_accepted_or_misnamed_is_caught():
    err = failures(Toy, stochastic=True, bad_configs=[({"samples": 10}, "samples")])
    assert err.report.failed == ["bad_config"] and "was accepted" in str(err)
    err = failures(Toy, stochastic=True, bad_configs=[({"samples": 1}, "noise_m")])
    assert "refused under key 'systems.system.samples'" in str(err)


def test_ignored_correction_is_caught():
    class Stubborn(Toy):
        def apply_correction(self, dx, P):
            self.P = 0.5 * (P + P.T)

    err = failures(Stubborn, stochastic=True)
    assert err.report.failed == ["correction"] and "moved position_n() by" in str(err)


def test_wrong_analytic_jacobian_is_caught():
    class WrongJacobian(Toy):
        def jacobian_cases(self):
            f = lambda x: np.array([np.sin(x[0]), x[0] * x[1]])  # noqa: E731
            x = np.array([0.3, 2.0])
            good = JacobianCase("good", f, x, np.array([[np.cos(0.3), 0.0], [2.0, 0.3]]))
            bad = JacobianCase("sign slip", f, x, np.array([[np.cos(0.3), 0.0], [-2.0, 0.3]]))
            return [good, bad]

    err = failures(WrongJacobian, stochastic=True)
    assert err.report.failed == ["jacobians"] and "sign slip" in str(err)


def test_strapdown15_check_catches_a_sign_error_in_F():
    acc = np.array([[4.0, -7.0, 15.0]])
    gyro = np.array([[1.5, -3.0, 0.8]])
    case = strapdown15_jacobian_cases(acc, gyro, 0.01, 9.8)[0]
    check_jacobian(case)
    case.jacobian = case.jacobian.copy()
    case.jacobian[3:6, 9:12] *= -1.0  # −C δb_a → +C δb_a
    with pytest.raises(AssertionError, match="strapdown15"):
        check_jacobian(case)


def test_failures_name_every_failing_check_and_skip_dependants():
    class Broken(Toy):
        plugin_name = "Not A Name"

    report = check_system(Broken, {}, raise_on_failure=False)
    assert report.failed == ["interface"]
    assert set(report.skipped) == set(CHECKS) - {"interface"}
