"""The core's smoothing step: systems that smooth in a thread are smoothed at the same time; a joint
state is smoothed jointly only where it can be, else each system alone, saying why."""

from __future__ import annotations

import threading

import numpy as np

from bodyfusion.core.capabilities import Smoothing
from bodyfusion.core.joint_smoothing import JointCorrections
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


def test_a_joint_state_that_cannot_be_smoothed_jointly_is_smoothed_one_system_at_a_time_and_says_why():
    systems = {"left": Smoother(False), "right": Smoother(False)}
    done = smooth_systems(systems, SmootherConfig(kind="rts"), JointCorrections(["hand", "left"], [3, 15]))
    assert done["left"]["joint_skipped"] == "hand cannot be smoothed"
    done = smooth_systems(systems, SmootherConfig(kind="rts"), JointCorrections(["left", "right"], [15, 15]))
    assert done["right"]["joint_skipped"] == "left: its kind cannot be smoothed jointly"


class JointMemberOf(Smoother):
    """A system whose joint member is never asked to sweep (the log refuses first)."""

    def joint_smoothing_member(self, cfg: SmootherConfig) -> object:
        return object()


def test_a_joint_state_a_measurement_of_one_system_moved_is_not_smoothed_jointly():
    log = JointCorrections(["left", "right"], [15, 15])
    log.record(1.0, np.eye(30), np.eye(30), np.zeros(30), own=True)
    done = smooth_systems({"left": JointMemberOf(False), "right": JointMemberOf(False)}, SmootherConfig(kind="rts"),
                          log)
    assert "aiding source" in done["left"]["joint_skipped"]
