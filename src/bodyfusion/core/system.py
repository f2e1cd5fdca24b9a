"""The interface every sensor system (plugin) implements for the fuser.

A system owns its data stream, its nominal navigation state and error-state filter,
its own aiding, and its history. The fuser drives it forward in time with
:meth:`SensorSystem.advance` and, at sync epochs, reads its position and covariance
and hands back a correction with :meth:`SensorSystem.apply_correction`. That, its times, its
trajectory, its sample count and input report are the whole required contract (ten members);
what else a system may offer (heading alignment, a place on the body, cross-covariances, its own
smoother, an absolute sensor) is in :mod:`bodyfusion.core.capabilities`.

An :class:`AidingSource` (a UWB tag) navigates nothing: it gives the fuser scalar
measurements of one or two systems' positions, which the fuser applies to them through
the same interface.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from pydantic import BaseModel

from bodyfusion.base.findings import Finding
from bodyfusion.base.types import InputReport, Trajectory
from bodyfusion.nav.filter_health import CovarianceHealth

if TYPE_CHECKING:  # pandas loads when a table is asked for
    import pandas as pd


@dataclass
class JacobianCase:
    """An analytic Jacobian to compare with central differences (what a plugin's optional
    ``jacobian_cases()`` returns for :func:`bodyfusion.testing.check_system`).

    ``func`` maps a nominal state to an output (a propagated state, a predicted
    measurement...), ``x`` is the linearisation point, ``jacobian`` the analytic (m, n)
    matrix of the output's error with respect to the input's error. ``retract(x, dx)``
    applies an error dx (n,) to a nominal state (default ``x + dx``); ``difference(a, b)``
    is the error of output a relative to b, true minus estimated (default ``a − b``).
    The check passes when max |J_num − J| ≤ ``atol`` + ``rtol`` · max |J|.
    """

    name: str
    func: Callable[[np.ndarray], np.ndarray]
    x: np.ndarray
    jacobian: np.ndarray
    step: float = 1e-6
    atol: float = 1e-7
    rtol: float = 1e-6
    retract: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    difference: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None



class CovarianceHistory:
    """A system's error-state covariance over time as it stores it: ``t`` (N,) s, ``states``
    (the k error states each row and column of a matrix belongs to, in the names of
    :meth:`SensorSystem.states` where the state is one of those: ``east_m``, ``north_m``,
    ``up_m``...), ``matrix`` in the states' units squared, NaN where the system does not store the
    entry, and ``stored`` (what the system keeps, in words). ``matrix`` is the (N, k, k) array, or
    a function that forms the matrices of a slice of the epochs (``epochs`` → (n, k, k)): then a
    long run's whole history of k × k matrices is formed a slice at a time (:meth:`block`,
    :meth:`columns` of ``epochs``) and never held unless asked for (:attr:`matrix`)."""

    def __init__(self, t: np.ndarray, states: tuple[str, ...],
                 matrix: np.ndarray | Callable[[slice], np.ndarray], stored: str) -> None:
        self.t = np.asarray(t)
        self.states = tuple(states)
        self.stored = stored
        self._form = matrix if callable(matrix) else np.asarray(matrix).__getitem__

    def block(self, epochs: slice) -> np.ndarray:
        """(n, k, k): the matrices at ``epochs``."""
        return self._form(epochs)

    def __repr__(self) -> str:
        return f"CovarianceHistory({len(self.t)} epochs, states={self.states}, stored={self.stored!r})"

    @property
    def matrix(self) -> np.ndarray:
        """(N, k, k): every epoch's matrix."""
        return self.block(slice(None))

    def variances(self) -> dict[str, np.ndarray]:
        """State name → (N,) variance."""
        diag = np.diagonal(self.matrix, axis1=1, axis2=2)
        return {name: diag[:, k] for k, name in enumerate(self.states)}

    def columns(self, epochs: slice = slice(None)) -> dict[str, np.ndarray]:
        """``t``, ``var_<state>`` and ``cov_<a>_<b>`` (the upper triangle) at ``epochs``, each (n,)."""
        matrix = self.block(epochs)
        cols: dict[str, np.ndarray] = {"t": self.t[epochs]}
        for a, name in enumerate(self.states):
            cols[f"var_{name}"] = matrix[:, a, a]
        for a, name in enumerate(self.states):
            for b in range(a + 1, len(self.states)):
                cols[f"cov_{name}_{self.states[b]}"] = matrix[:, a, b]
        return cols

    def to_frame(self) -> pd.DataFrame:
        """:meth:`columns` as a DataFrame."""
        import pandas as pd  # pandas loads when a table is asked for

        return pd.DataFrame(self.columns())


def position_covariance(t: np.ndarray, var_enu: np.ndarray, cov_en: np.ndarray | None,
                        stored: str) -> CovarianceHistory:
    """The (N, 3, 3) east, north, up covariance of variances ``var_enu`` (N, 3) m² and the
    east–north covariance ``cov_en`` (N,) m² (None: not stored); the east–up and north–up
    covariances are not stored (NaN)."""

    def block(epochs: slice) -> np.ndarray:
        var = var_enu[epochs]
        matrix = np.full((len(var), 3, 3), np.nan)
        matrix[:, [0, 1, 2], [0, 1, 2]] = var
        if cov_en is not None:
            matrix[:, 0, 1] = matrix[:, 1, 0] = cov_en[epochs]
        return matrix

    return CovarianceHistory(t, ("east_m", "north_m", "up_m"), block, stored)


@dataclass(frozen=True)
class LayoutContext:
    """Layout-wide facts a system needs: gravity (m/s^2), latitude (deg), config folder,
    run seed, the geodetic origin of the ENU frame (lat deg, lon deg, height m; None:
    not set), the GNSS outage windows per system ((start s, duration s), ...) and, on a first
    run (numba's cache was empty as it started and forking is safe:
    :mod:`bodyfusion.core.compile_ahead`), ``compiling_ahead``: the forked processes
    (:class:`~bodyfusion.base.forking.Forked`) compiling kernels the run needs later, by a name
    the systems that share one agree on; a system's constructor may add one while the run
    compiles others, and the run waits for all of them once the systems are built
    (:func:`~bodyfusion.core.compile_ahead.finish_compiling_ahead`), before anything advances.
    None on any other run."""

    gravity_mps2: float
    latitude_deg: float
    base_dir: Path
    seed: int = 0
    geodetic_origin: tuple[float, float, float] | None = None
    outages: dict[str, tuple[tuple[float, float], ...]] = field(default_factory=dict)
    compiling_ahead: dict[str, Any] | None = None
    growing: bool = False
    """The recordings are the first part of a live run's (:mod:`bodyfusion.live`): a system may
    refuse to start on them yet (:class:`~bodyfusion.base.errors.NotReady`)."""


class Plugin(ABC):
    """What every layout entry's class has: ``plugin_name`` (the layout's
    ``systems.<name>.plugin``), ``Config`` (pydantic model of its section), its name,
    validated config and the layout context, and what its readers used and dropped."""

    plugin_name: ClassVar[str]
    Config: ClassVar[type[BaseModel]]
    navigates: ClassVar[bool]
    """True for a navigation system (it has a position and a trajectory), False for an aiding
    source that only measures the navigation systems."""
    body_part: ClassVar[str | None] = None
    """Where on the body the system is worn (``foot``, ``hand``...; :mod:`bodyfusion.core.body`
    knows the distances between them); None: unknown."""
    data_section: ClassVar[str | None] = None
    """The section of the plugin's config (a :class:`~bodyfusion.base.sections.TableSection`, by
    its key within the system's section) that a table given in memory for the whole system feeds
    (``bodyfusion.run(layout, data={"left_foot": imu_frame})``); None: the plugin reads no data.
    Tables for other sections are given by their keys (``data={"hand": {"gnss": fixes}}``)."""

    def __init__(self, name: str, config: BaseModel, context: LayoutContext) -> None:
        self.name = name
        self.config = config
        self.context = context

    @property
    @abstractmethod
    def samples(self) -> int:
        """Number of input samples (or measurements) used."""

    @property
    @abstractmethod
    def input_report(self) -> InputReport:
        """What the readers dropped or reordered."""

    def decided_until(self) -> float:
        """The time (s) up to which the plugin's samples, sync events and measurements are final:
        the fuser takes no event after it. A plugin that read its whole recording has decided
        everything (∞, the default); a live one decides its data some look-ahead behind the newest
        sample (:mod:`bodyfusion.live`)."""
        return math.inf

    def diagnostics(self) -> dict:
        """Plugin-specific figures for metrics.json (stance fraction, updates, rejections...)."""
        return {}

    def health(self) -> dict:
        """Consistency figures of the filter for metrics.json ``systems.<name>.health`` (an aiding
        source's: ``aiding.<name>.health``), in the forms of :mod:`bodyfusion.evaluation.consistency`:

        - ``covariance``: :class:`~bodyfusion.nav.filter_health.CovarianceHealth` of the
          error-state covariance (a navigation system's default, see :meth:`SensorSystem.health`);
        - ``nis``: {aiding type: :class:`~bodyfusion.nav.filter_health.NisTally` dict} for
          every aiding type the plugin applies (ZUPT, GNSS position, ranges...), its expected
          value the measurement dimension;
        - ``quaternion_norm_max_deviation``: max |‖q‖ − 1| over the run, for a quaternion state;
        - ``covariance_history``: the checks of every covariance the plugin recorded, with the
          ``block`` they cover.

        The core adds ``trajectory_covariance`` and, where truth exists, ``nees`` (the
        horizontal NEES, :meth:`bodyfusion.results.run_result.RunResult.health`). Default here: nothing."""
        return {}

    def findings(self) -> list[Finding]:
        """What went wrong in this system's run, as health findings a person can act on
        (:class:`~bodyfusion.base.findings.Finding`: missed stances, saturation, rejected
        updates...). Called after the run (and any smoothing). Default: none."""
        return []

    def innovations(self) -> dict[str, np.ndarray]:
        """Every update the plugin applied or refused, in time order, as equal-length columns:
        ``t`` (s), ``aiding`` (the aiding type, as in :meth:`health`'s ``nis``: ``zupt``,
        ``position_fix``, ``gnss_position``, ``gnss_course``, ``magnetometer``,
        ``anchor_range``, ``peer_range``...), ``nis`` (before any gate), ``dof``, ``accepted``
        (within the gate); a plugin may add columns (a range's ``end``). Default: none."""
        return {}


class SensorSystem(Plugin):
    """Base class of a body-worn navigation system.

    Class attribute ``position_indices``: indices of δp in the error state. Frames:
    positions in the ENU navigation frame, metres.
    """

    navigates = True
    position_indices: ClassVar[slice] = slice(0, 3)
    geodetic_origin: tuple[float, float, float] | None = None
    """Latitude (deg), longitude (deg), height (m) of the ENU origin this system set (e.g. its
    first GNSS fix) when the layout gives none; None: it sets none."""
    error_model: ClassVar[str | None] = None
    """Name of a shared error-state model the system uses (e.g. ``strapdown15``), so that
    :func:`bodyfusion.testing.check_system` can check its Jacobians."""

    def __init__(self, name: str, config: BaseModel, context: LayoutContext) -> None:
        super().__init__(name, config, context)
        self.covariance_health = CovarianceHealth()
        """Checks of the error-state covariance made during the run (see :meth:`health`)."""

    # --- time -----------------------------------------------------------------
    @property
    def t_start(self) -> float:
        """Time of the first state (s): the first sample."""
        return float(self.sample_times()[0])

    @property
    def t_end(self) -> float:
        """Time of the last sample (s)."""
        return float(self.sample_times()[-1])

    @property
    @abstractmethod
    def t_now(self) -> float:
        """Time of the current state (s)."""

    @abstractmethod
    def advance(self, t: float) -> None:
        """Propagate and apply own aiding for every sample with time <= t."""

    # --- fuser interface ----------------------------------------------------------
    @abstractmethod
    def position_n(self) -> np.ndarray:
        """Current position estimate, ENU (m), shape (3,)."""

    @abstractmethod
    def covariance(self) -> np.ndarray:
        """Current error-state covariance, shape (n, n)."""

    @abstractmethod
    def apply_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        """Closed-loop reset: add error-state correction ``dx`` (n,) to the nominal
        state and replace the covariance with ``P`` (n, n)."""

    def apply_relative_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        """A correction derived from other systems' estimates as well as this one's (a
        distance constraint, a measurement of another system spread by the cross-covariances):
        :meth:`apply_correction`. A system that smooths its run afterwards overrides it to keep
        such a correction as the filter made it — its own smoother cannot re-derive it from the
        other systems' smoothed estimates, and would otherwise count it as a measurement of
        its own state (see :mod:`bodyfusion.plugins.foot_ins.smoothing`)."""
        self.apply_correction(dx, P)

    @abstractmethod
    def sync_times(self) -> np.ndarray:
        """Times (s) of events the fuser may sync on (e.g. stance starts)."""

    @abstractmethod
    def sample_times(self) -> np.ndarray:
        """Times (s) of every sample the system processes."""

    # --- results ----------------------------------------------------------------
    @abstractmethod
    def trajectory(self) -> Trajectory:
        """History of positions and their one-sigma uncertainty."""

    def states(self) -> dict[str, np.ndarray]:
        """The estimated states at the epochs of :meth:`trajectory` (smoothed where the system was
        smoothed), as equal-length columns in names every plugin shares: ``t`` (s); ``east_m``,
        ``north_m``, ``up_m`` (ENU); where the system estimates them ``v_east_mps``,
        ``v_north_mps``, ``v_up_mps``; ``qw``, ``qx``, ``qy``, ``qz`` (attitude, body to ENU);
        ``heading_deg`` (azimuth clockwise from North: of the body x axis for an IMU, of the
        walking direction for a PDR), ``pitch_deg``, ``roll_deg`` (ZYX in ENU, as
        :func:`bodyfusion.nav.attitude.quat_from_azimuth_pitch_roll`); then the plugin's own
        states under their own names with their units. Default: the trajectory's positions."""
        traj = self.trajectory()
        return {"t": traj.t, "east_m": traj.pos_n[:, 0], "north_m": traj.pos_n[:, 1], "up_m": traj.pos_n[:, 2]}

    def covariance_history(self) -> CovarianceHistory:
        """The error-state covariance over time as the system stores it (see the plugin's
        docstring). Default: the trajectory's position covariance (variances and, where given,
        the east–north covariance)."""
        traj = self.trajectory()
        return position_covariance(traj.t, traj.pos_sd**2, traj.pos_cov_en,
                                   "position variances" + (", east-north covariance" if traj.pos_cov_en is not None
                                                           else ""))

    def events(self) -> dict[str, np.ndarray]:
        """Gait events the system detected, as equal-length columns: ``event`` (``stance``,
        ``step``...), ``t`` (start, s), ``t_end`` (s; equal to ``t`` for an instant) and, where the
        system has it, ``length_m`` (a step's length). Default: none."""
        return {}

    def strides(self) -> dict[str, np.ndarray]:
        """The gait stride by stride, for a system worn on a foot: equal-length columns ``stride``,
        ``t_start``, ``t_end`` (s), ``length_m``, ``duration_s``, ``speed_mps`` and what else it
        measures (strides.csv). Default: none."""
        return {}

    # --- consistency ----------------------------------------------------------------
    def health(self) -> dict:
        """As :meth:`Plugin.health`; default ``covariance``: the checks in
        :attr:`covariance_health`, which the core makes while the fuser runs
        (:class:`bodyfusion.core.health.CovarianceMonitor`: at every sync epoch, after every
        correction, at least every second of the system's own sync events, and at the end), or
        the current covariance alone when none was made. Plugins add what they know (their NIS,
        quaternion norm, recorded covariances) to this dict."""
        checks = self.covariance_health
        if not checks.checks:
            checks = CovarianceHealth.of(self.covariance()[None], np.array([self.t_now]))
        return {"covariance": checks.to_dict()}


@dataclass(frozen=True)
class ScalarMeasurement:
    """One scalar measurement of the positions of the systems an aiding source measures.

    ``z``: the measured value; ``predicted``: h(p̂) at the current position estimates;
    ``H_p``: (m, 3) ∂h/∂p, one row per measured system (in the order of
    :meth:`AidingSource.measured_systems`), in the unit of z per metre; ``r_var``: noise
    variance (unit of z squared). The fuser forms the innovation y = z − h(p̂).
    """

    z: float
    predicted: float
    H_p: np.ndarray
    r_var: float


class AidingSource(Plugin):
    """Base class of a body-worn sensor that aids navigation systems without navigating
    itself: a UWB tag ranging to anchors and to other tags, for example.

    It owns its data and the measurement model; the fuser owns the update. At each of
    :meth:`measurement_times` the fuser advances the measured systems to that time, asks
    :meth:`measure` for z, h(p̂) and ∂h/∂p at their positions, and applies a gated scalar
    EKF update (Joseph form) on their stacked error states through the generic
    :class:`SensorSystem` interface (``position_n``, ``covariance``, ``position_indices``,
    ``apply_correction``), so any host works. It has no trajectory: its figures go to
    metrics.json ``aiding.<name>`` through :meth:`diagnostics`.

    Frames and units: positions ENU, metres; time s. ``samples`` counts the
    measurements read, ``diagnostics`` goes to metrics.json ``aiding.<name>``.
    """

    navigates = False
    measurements_forgotten = 0
    """Measurements dropped from the front (a bounded live run forgetting those taken): measurement
    k held is the run's k + this, which the fuser's schedule counts in."""

    @classmethod
    @abstractmethod
    def system_references(cls, config: BaseModel) -> list[tuple[str, str]]:
        """(dotted key within the section, system name) of every system the config names;
        the layout checks that each is a navigation system."""

    @abstractmethod
    def measurement_times(self) -> np.ndarray:
        """(K,) times (s) of the measurements, non-decreasing."""

    @abstractmethod
    def measured_systems(self, k: int) -> tuple[str, ...]:
        """Names of the systems measurement k relates (one: a range to an anchor; two: a
        range between two systems)."""

    @abstractmethod
    def measure(self, k: int, positions_n: list[np.ndarray]) -> ScalarMeasurement:
        """Measurement k at the measured systems' current positions (ENU m, each (3,))."""

    @property
    @abstractmethod
    def gate_nis(self) -> float:
        """Normalised innovation squared above which a measurement is rejected."""

    @abstractmethod
    def record(self, k: int, nis: float | None, accepted: bool) -> None:
        """The fuser's verdict on measurement k (nis None: not applied, e.g. outside the
        measured systems' data)."""

    def record_late(self, k: int) -> None:
        """Measurement k arrived after the fuser had passed its time (a live run's rows taken as they
        come): it is not applied. Default: recorded as not applied (:meth:`record`)."""
        self.record(k, None, False)
