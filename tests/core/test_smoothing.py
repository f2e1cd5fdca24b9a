"""The core's smoothing step: systems that smooth in a thread are smoothed at the same time."""

from __future__ import annotations

import threading

from bodyfusion.core.capabilities import Smoothing
from bodyfusion.core.layout import SmootherConfig
from bodyfusion.core.smoothing import smooth_systems


class Smoother(Smoothing):
    """A system's smoothing hook that records the thread it ran in; ``barrier``: it waits there
    for the other threaded systems (a deadlock, timed out, unless they run at the same time)."""

    def __init__(self, threaded: bool, barrier: threading.Barrier | None = None, smooths: bool = True) -> None:
        self.smooths_in_a_thread = threaded
        self.barrier, self.smooths, self.thread = barrier, smooths, None

    def smooth(self, cfg: SmootherConfig) -> dict | None:
        self.thread = threading.current_thread()
        if self.barrier is not None:
            self.barrier.wait(timeout=10.0)
        return {"kind": cfg.kind} if self.smooths else None


def test_systems_that_smooth_in_a_thread_are_smoothed_at_the_same_time_and_reported_in_order():
    barrier = threading.Barrier(3)
    systems = {"hand": Smoother(False, smooths=False), "left": Smoother(True, barrier), "uwb": Smoother(False),
               "right": Smoother(True, barrier), "third": Smoother(True, barrier)}
    systems["tag"] = object()  # no smoother at all: not asked
    done = smooth_systems(systems, SmootherConfig(kind="rts"))
    assert list(done) == ["left", "uwb", "right", "third"]  # the layout's order, the unsmoothed left out
    assert systems["hand"].thread is systems["uwb"].thread is systems["left"].thread is threading.main_thread()
    assert len({systems[name].thread for name in ("left", "right", "third")}) == 3
