"""What a sensor system may offer beyond the base contract, discovered by the core.

The base contract (:class:`~bodyfusion.core.system.SensorSystem`) is what the fuser needs of every
system: advance in time, its position and covariance, take a correction, its times and its
trajectory. A system offers more by deriving from one of these classes as well; the core asks
:func:`offers` before it uses one, so a plugin implements only what its sensor has:

- :class:`HeadingAlignment`: its heading is relative (an INS, a PDR) and may be turned, so that
  every worn system navigates in one frame (:mod:`bodyfusion.core.heading`), or it is
  geographic and the others are turned to it; a heading error state lets the fuser tie the
  systems' headings through the run.
- :class:`BodyPlacement`: it knows where on the body it is worn and starts there.
- :class:`TransitionTracking`: it gives its error-state transition Φ between the fuser's syncs,
  for the cross-covariances a constraint creates (``fuser.cross_covariance``).
- :class:`Smoothing`: it smooths its own run once the fuser is done (the layout's ``smoother``).
- :class:`AbsoluteFixes`: it carries an absolute position sensor (a phone's GNSS): its fixes
  alone are what the fused track is scored beside, and what a geographic frame is fitted to.
- :class:`PositionResets`: it may take its position afresh from its absolute sensor when that
  sensor keeps disagreeing with it; the systems held to it then move with it (the fuser).
- :class:`Streaming`: it runs live (:mod:`bodyfusion.live`): its data table grows while it
  runs, and it decides its samples some look-ahead behind the newest.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar, TypeVar

import numpy as np
from pydantic import BaseModel

from bodyfusion.base.errors import FusionError
from bodyfusion.base.findings import Finding

Capability = TypeVar("Capability")


def offers(system: Any, capability: type[Capability]) -> bool:
    """True when ``system`` offers ``capability``; a wrapper the fuser sees a system through (a
    covariance monitor, a progress tracker: whatever passes calls on to its ``monitored``) offers
    what the system inside it offers."""
    while (inner := getattr(system, "monitored", None)) is not None:
        system = inner
    return isinstance(system, capability)


class HeadingAlignment(ABC):
    """A system whose heading the core may align to the other systems' (azimuths clockwise from
    North, rad)."""

    @property
    @abstractmethod
    def heading_is_auto(self) -> bool:
        """True if the layout asks for the heading to be aligned to the other systems."""

    @property
    def heading_is_absolute(self) -> bool:
        """True for a geographic heading (from GNSS or a magnetometer): the reference the other
        systems' headings are aligned to. Default: False."""
        return False

    @abstractmethod
    def initial_travel_azimuth(self, distance_m: float) -> float | None:
        """Azimuth (rad) of the start-to-here vector once the system has travelled ``distance_m``
        horizontally with its current initial heading; None if it never travels that far. Leaves
        the system at its start."""

    @abstractmethod
    def rotate_initial_heading(self, delta_rad: float) -> None:
        """Rotate the initial attitude about Up by ``delta_rad`` (clockwise from North positive,
        as azimuth) and restart from the first sample."""

    def yaw_error_row(self) -> np.ndarray | None:
        """The row h (n,) of the error state with h δx = the rotation about Up (rad,
        counter-clockwise positive) that turns the estimated attitude into the true one
        (:class:`bodyfusion.core.heading.HeadingTie` keeps systems worn together in one frame
        through it); None (the default): no heading error state."""
        return None


class BodyPlacement(ABC):
    """A system that knows where on the body it is worn, placed there at the start when the
    layout gives no initial position."""

    @property
    @abstractmethod
    def wants_body_place(self) -> bool:
        """True when the initial position is not given: :meth:`place_on_body` sets it."""

    @property
    @abstractmethod
    def lateral_offset_m(self) -> float:
        """Metres to the right of the body's centreline (a left foot about −0.1, a right foot
        +0.1; 0 on it or unknown)."""

    @abstractmethod
    def place_on_body(self, walking_azimuth_rad: float) -> None:
        """Set the initial position (and its σ) where the system is worn, the body at the origin
        facing ``walking_azimuth_rad`` (clockwise from North), and restart."""


class TransitionTracking(ABC):
    """A system that gives its error-state transition between the fuser's syncs, so that the
    fuser can carry the cross-covariances its constraints create."""

    @abstractmethod
    def track_transition(self) -> None:
        """Start accumulating the error-state transition Φ (a system that can do so only in
        some configurations raises :class:`~bodyfusion.base.errors.FusionError` naming the key)."""

    @abstractmethod
    def transition_since_sync(self) -> np.ndarray:
        """Φ (n, n) that maps the error state at the previous call to now (propagation and own
        updates, x_now = Φ x_then + independent terms); restarts the accumulation."""


class Smoothing(ABC):
    """A system that smooths its own run once the fuser is done."""

    smooths_in_a_thread: ClassVar[bool] = False
    """True when :meth:`smooth` may run in a thread beside the other systems' (it touches only
    its own state and its compiled kernels release the GIL)."""

    def plan_smoothing(self, cfg: BaseModel) -> None:
        """Before the run: the layout's ``smoother`` section, for a system that records what its
        smoother needs as it runs instead of replaying itself afterwards. Default: nothing."""

    @abstractmethod
    def smooth(self, cfg: BaseModel) -> dict | None:
        """Smooth the run (the layout's ``smoother`` section); afterwards ``trajectory()`` is the
        smoothed track. Returns the smoother's diagnostics, None when it did not smooth."""

    def live_smoother(self, cfg: BaseModel) -> Any:
        """This run's smoother as its live run goes (the layout's ``smoother`` section): an object
        whose ``advance(final=False)`` gives the samples the data now smooth for good
        (:class:`~bodyfusion.core.epoch_state.SmoothedSamples`, or None; ``final``: the recording
        is complete) and ``diagnostics()`` a dict. Default: it cannot smooth live."""
        raise FusionError("its kind cannot be smoothed live")

    def joint_smoothing_member(self, cfg: BaseModel) -> Any:
        """This run as a member of the joint RTS of the systems the fuser corrected together
        (:class:`bodyfusion.core.joint_smoothing.JointMember`). Default: it cannot be one."""
        raise FusionError("its kind cannot be smoothed jointly")


class AbsoluteFixes(ABC):
    """A system carrying an absolute position sensor (a phone's GNSS)."""

    @abstractmethod
    def absolute_fixes(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The sensor alone: fix times (K,) s and ENU positions (K, 3) m, every fix its user would
        have (outages masked); None when the run has none."""


class PositionResets(ABC):
    """A system that takes its position afresh from its own absolute sensor when that sensor has
    disagreed with it too long (a phone's GNSS after ``reset_after_rejections`` gated-out fixes:
    the fixes jumped and stayed, or the dead reckoning strayed). A move larger than a body limit
    cannot be one system's alone: the fuser moves the systems held to it by the same amount
    (:meth:`~bodyfusion.core.fuser.Fuser.follow_position_resets`), so that the fix is followed,
    not fought by the constraint."""

    @abstractmethod
    def take_position_resets(self) -> list[tuple[float, np.ndarray]]:
        """The resets since the last call (then forgotten): time (s) and the position's move
        (3,) ENU m."""


class Streaming(ABC):
    """A system that runs live: built on the first part of its recording (its data section's
    in-memory table, :mod:`bodyfusion.live`), it takes each longer part as it arrives. What it
    decided about a sample (stance, a gap's increment) is final once the data reach the
    look-ahead beyond it; :meth:`~bodyfusion.core.system.SensorSystem.decided_until` says up to
    when that is, and the fuser takes no event after it."""

    paces_live: ClassVar[bool] = True
    """Its data section's rows pace a live run (it waits for them): a navigation system's. An
    aiding source's measurements are taken as they come (False): a gap in them never holds the
    run up, and one that arrives after the fuser passed its time is not taken (the schedule
    counts it, :meth:`~bodyfusion.core.system.AidingSource.record_late`)."""

    @classmethod
    def streamed_sections(cls, config: BaseModel) -> tuple[str, ...]:
        """The sections of ``config`` whose tables grow live: the system's data section first (its
        rows pace the run, which waits for them), then its aiding sections (a phone's GNSS: their
        rows are taken as they come and never hold the run up). Default: the data section alone.
        A configuration that cannot run live raises :class:`~bodyfusion.base.errors.ConfigError`
        naming its key."""
        return (cls.data_section,)

    @abstractmethod
    def start_streaming(self, lookahead_s: float) -> None:
        """From now on the recording grows: decide samples ``lookahead_s`` (s) behind the newest."""

    @abstractmethod
    def extend(self) -> None:
        """The data section's table has grown (a longer first part of the recording, every earlier
        row unchanged): read it and decide what the look-ahead allows."""

    @abstractmethod
    def close_stream(self) -> None:
        """The recording is complete: read it whole (what it still holds, after
        :meth:`forget_before`) and decide every sample."""

    def forget_before(self, t: float) -> dict[str, int]:
        """Drop the samples before ``t`` (s) and every history row of them, as far as what is still
        to decide allows; each streamed section's table loses as many first rows, and the rows left
        are numbered from 0 again. Returns the rows dropped per section (section → count; a live
        run that keeps a bounded history, :mod:`bodyfusion.live`). Default: forget nothing, so
        that a plugin written before it runs live as it did, holding its whole history."""
        return {}


def forgotten_history_finding(system: str, t_first: float, t0: float, t1: float, forgotten: int) -> Finding:
    """The ``live_window`` finding of a system that forgot ``forgotten`` samples of a live run
    (:meth:`Streaming.forget_before`): the run began at ``t_first`` (s); the system holds
    ``t0``–``t1`` (s)."""
    return Finding(
        "live_window", "info", system, t0, t1,
        f"the live run kept the last {t1 - t0:.0f} s of this system's recording (it forgot the {forgotten} samples "
        f"before t = {t0:.1f} s as it went): its track, scores and findings here cover t = {t0:.1f}–{t1:.1f} s of "
        f"the {t1 - t_first:.0f} s run; the states sent to the sinks cover all of it.",
        "fusion live --keep bounds the history a run holds (and its memory).",
        "read the whole run's errors in metrics.json (systems.NAME.whole_run: every state emitted, scored against "
        "the truth), or run fusion run on the recording for whole-run figures.")
