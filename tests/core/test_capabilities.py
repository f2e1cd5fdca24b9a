"""The sensor contract is small, and what a system offers beyond it is discovered, not assumed."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from bodyfusion.base.errors import FusionError
from bodyfusion.core import capabilities
from bodyfusion.core.capabilities import HeadingAlignment, Smoothing, TransitionTracking, offers
from bodyfusion.core.health import CovarianceMonitor
from bodyfusion.core.layout import FuserConfig, HeadingAlignmentConfig
from bodyfusion.core.fuser import Fuser
from bodyfusion.core.heading import align_headings, heading_reference, heading_ties
from bodyfusion.core.progress import FusionProgress
from bodyfusion.core.layout import ConstraintConfig
from bodyfusion.core.system import AidingSource, SensorSystem
from bodyfusion.plugins.foot_ins.system import FootIns
from bodyfusion.plugins.hand_pdr.system import HandPdr
from bodyfusion.plugins.random_walk.system import RandomWalk, RandomWalkConfig
from bodyfusion.testing.inputs import default_context

REQUIRED = 10
"""The most members a plugin author must implement for a navigation system."""


def test_a_navigation_system_needs_at_most_ten_members():
    assert len(SensorSystem.__abstractmethods__) <= REQUIRED, sorted(SensorSystem.__abstractmethods__)


def test_an_aiding_source_needs_at_most_ten_members():
    assert len(AidingSource.__abstractmethods__) <= REQUIRED, sorted(AidingSource.__abstractmethods__)


@pytest.mark.parametrize("cls, offered", [
    (FootIns, {"HeadingAlignment", "BodyPlacement", "TransitionTracking", "Smoothing", "Streaming"}),
    (HandPdr, {"HeadingAlignment", "TransitionTracking", "AbsoluteFixes", "PositionResets", "Streaming"}),
    (RandomWalk, {"TransitionTracking"}),
])
def test_each_built_in_plugin_offers_what_its_sensor_has(cls, offered):
    every = {name for name, c in inspect.getmembers(capabilities, inspect.isclass)
             if c.__module__ == capabilities.__name__}
    assert {name for name in every if issubclass(cls, getattr(capabilities, name))} == offered


def test_the_random_walk_implements_the_ten_and_its_transition_and_no_stub_of_what_it_lacks():
    own = {name for name, member in vars(RandomWalk).items() if callable(member) or isinstance(member, property)}
    assert set(SensorSystem.__abstractmethods__) | set(TransitionTracking.__abstractmethods__) <= own
    lacking = {name for cap in (HeadingAlignment, Smoothing) for name in vars(cap) if not name.startswith("_")}
    assert not own & lacking, own & lacking


def random_walk(name: str) -> RandomWalk:
    return RandomWalk(name, RandomWalkConfig(duration_s=20.0, velocity_mps=[1.0, 0.0, 0.0]), default_context())


def test_a_capability_is_seen_through_the_wrappers_the_fuser_sees_a_system_through():
    walk = random_walk("a")
    tracked = FusionProgress({"a": walk}, lambda done, total: None).track(walk)
    monitored = CovarianceMonitor(tracked)
    assert offers(monitored, TransitionTracking) and not offers(monitored, HeadingAlignment)
    assert not offers(monitored, Smoothing)


def test_systems_without_a_heading_take_no_part_in_heading_alignment():
    systems = {"a": random_walk("a"), "b": random_walk("b")}
    cfg = HeadingAlignmentConfig()
    assert heading_reference(systems, cfg) is None
    assert align_headings(systems, cfg) == {} and heading_ties(systems, cfg) == []
    with pytest.raises(FusionError, match="no heading to align to"):
        heading_reference(systems, HeadingAlignmentConfig(reference="a"))


def test_cross_covariances_ask_every_constrained_system_for_its_transition():
    class Untracked(SensorSystem):  # the ten members, nothing else
        plugin_name, Config = "untracked", RandomWalkConfig
        samples = property(lambda self: self.inner.samples)
        input_report = property(lambda self: self.inner.input_report)
        t_now = property(lambda self: self.inner.t_now)

        def __init__(self, inner):
            super().__init__(inner.name, inner.config, inner.context)
            self.inner = inner

        def advance(self, t): self.inner.advance(t)
        def position_n(self): return self.inner.position_n()
        def covariance(self): return self.inner.covariance()
        def apply_correction(self, dx, P): self.inner.apply_correction(dx, P)
        def sync_times(self): return self.inner.sync_times()
        def sample_times(self): return self.inner.sample_times()
        def trajectory(self): return self.inner.trajectory()

    systems = {"a": random_walk("a"), "b": Untracked(random_walk("b"))}
    assert np.isfinite(systems["b"].position_n()).all()
    constraint = [ConstraintConfig(between=["a", "b"], kind="max", distance_m=1.0)]
    with pytest.raises(FusionError, match="'b' .*cannot track cross-covariances"):
        Fuser(systems, FuserConfig(method="projection", cross_covariance=True), constraint).run()
