"""The fuser's clock gives a live run the batch run's events: any slicing of the horizon yields
the same events in the same order as one slice."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.core.layout import FuserConfig
from bodyfusion.core.schedule import CONSTRAINT, MEASUREMENT, OUTPUT, TIE, EventSchedule, epoch_times


@dataclass
class Timed:
    """What the schedule reads of a system (or an aiding source)."""

    samples: np.ndarray
    sync: np.ndarray

    @property
    def t_start(self) -> float:
        return float(self.samples[0])

    @property
    def t_end(self) -> float:
        return float(self.samples[-1])

    def sample_times(self) -> np.ndarray:
        return self.samples

    def sync_times(self) -> np.ndarray:
        return self.sync

    def measurement_times(self) -> np.ndarray:
        return self.sync

    measurements_forgotten = 0  # as an aiding source that forgot none


def _system(rng: np.random.Generator, rate: float) -> Timed:
    t0 = rng.uniform(0.0, 2.0)
    samples = t0 + np.arange(int(rng.integers(200, 600))) / rate
    return Timed(samples, np.sort(rng.choice(samples, size=20, replace=False)))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), epochs=st.sampled_from(["events", "interval", "sample"]),
       cuts=st.lists(st.floats(-1.0, 12.0), max_size=12))
def test_any_slicing_of_the_horizon_gives_the_one_slice_events(seed, epochs, cuts):
    rng = np.random.default_rng(seed)
    feet = [_system(rng, 60.0), _system(rng, 100.0)]
    source = _system(rng, 10.0)
    config = FuserConfig(epochs=epochs, interval_s=float(rng.choice([0.05, 0.1, 1 / 3])))
    seen: list[tuple[int, float]] = []

    def schedule(sink):
        return EventSchedule(feet, [source], feet, config, feet, 0.1, lambda i, t: sink.extend((i, x) for x in t))

    whole = schedule([]).until(math.inf)
    sliced_schedule = schedule(seen)
    sliced = []
    for h in sorted(cuts) + [math.inf]:
        sliced += sliced_schedule.until(h)
    assert sliced == whole
    assert sorted(seen) == sorted((i, float(x)) for i, s in enumerate(feet) for x in s.sync)
    kinds = {k for _, k, _, _ in whole}
    assert {MEASUREMENT, TIE, CONSTRAINT, OUTPUT} <= kinds


def test_interval_epochs_are_the_ones_np_arange_makes():
    rng = np.random.default_rng(3)
    feet = [_system(rng, 60.0), _system(rng, 100.0)]
    config = FuserConfig(epochs="interval", interval_s=0.1)
    t0, t1 = max(s.t_start for s in feet), min(s.t_end for s in feet)
    expected = np.arange(t0 + 0.1, t1, 0.1)
    np.testing.assert_array_equal(epoch_times(feet, config), expected[(expected > t0) & (expected <= t1)])
    parts = [epoch_times(feet, config, a, b) for a, b in ((-math.inf, 3.0), (3.0, 4.2), (4.2, math.inf))]
    np.testing.assert_array_equal(np.concatenate(parts), epoch_times(feet, config))
