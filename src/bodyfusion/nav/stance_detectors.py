"""Zero-velocity (stance) detectors as models: parameters and their defaults in ``__init__``,
:meth:`StanceDetector.detect` on a foot's IMU samples, the results as attributes.

Every detector takes body-frame specific force ``acc_b`` (N, 3) in m/s^2 (about +g along the
up-pointing axis at rest) and angular rate ``gyro_b`` (N, 3) in rad/s, and leaves ``stance``
(N,) bool, True = the foot at rest. The statistics and their compiled kernels are in
:mod:`bodyfusion.nav.detectors`; the defaults are here and nowhere else.

==============  ==========================================================================
kind            detector
==============  ==========================================================================
``adaptive``    :class:`AdaptiveShoe`: SHOE with a threshold that follows the gait (default)
``shoe``        :class:`Shoe`: SHOE / GLRT with OpenShoe's fixed threshold [Skog2010]
``magnitude``   :class:`AccelerationMagnitude`: | ‖f‖ − g | ≤ threshold [Xu2024]
``axes_band``   :class:`AxesSumBand`: low < f_x + f_y + f_z < high [Deng2026]
``labels``      :class:`Labels`: the recording's own stance column
==============  ==========================================================================

A detector of one's own is a :class:`StanceDetector` subclass with a ``kind``, registered with
:func:`register_stance_detector` (a plugin package does so when its entry point is imported);
a layout then selects it by its kind and sets its ``__init__`` parameters.
"""

from __future__ import annotations

import inspect
import math
from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

from bodyfusion.nav import detectors
from bodyfusion.nav.gait import stride_period

SIGMA_ACC_MPS2 = 0.01
"""SHOE accelerometer noise σ_a (m/s^2): OpenShoe's ``setting.m``."""
SIGMA_GYRO_RADPS = 0.1 * math.pi / 180.0
"""SHOE gyroscope noise σ_ω (rad/s): OpenShoe's 0.1 °/s."""
STILL_THRESHOLD = 0.3e5
"""SHOE threshold γ below which a window is stance: OpenShoe's, for the 1/W-scaled statistic at
the σ above (an RMS angular rate below ~0.30 rad/s with a steady specific force)."""
SHOE_WINDOW = 5
"""Samples per window of the fixed-window detectors."""
ADAPTIVE_WINDOW_S = 0.025
"""The adaptive detector's window (s): the test spans the same time at any rate."""


class StanceDetector(ABC):
    """A zero-velocity detector. Parameters are given to ``__init__`` (their defaults are the
    detector's); :meth:`detect` sets ``stance`` (N,) bool and returns the detector."""

    kind: ClassVar[str]
    """The layout's ``detector.kind``."""
    stance: np.ndarray
    """(N,) True where the foot is at rest, after :meth:`detect`."""
    period_s: np.ndarray | None = None
    """(N,) stride period (s; NaN where no gait repeats) when the detector measured it."""
    statistic: np.ndarray | None = None
    """The SHOE statistic per window (N − W + 1,) when the detector computed it, and its window W."""
    statistic_window: int | None = None

    @classmethod
    def parameters(cls) -> tuple[str, ...]:
        """The names ``__init__`` takes."""
        params = inspect.signature(cls.__init__).parameters.values()
        return tuple(p.name for p in params if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD))

    def get_params(self) -> dict[str, object]:
        """The parameters this detector was made with."""
        return {name: getattr(self, name) for name in self.parameters()}

    @abstractmethod
    def detect(self, acc_b: np.ndarray, gyro_b: np.ndarray, rate_hz: float, gravity: float,
               labels: np.ndarray | None = None) -> StanceDetector:
        """Detect stance in the samples (rate Hz, gravity m/s^2; ``labels`` (N,) the recording's
        own stance column, where it has one); sets ``stance`` and returns ``self``."""


STANCE_DETECTORS: dict[str, type[StanceDetector]] = {}
"""Detector classes by kind: the built-in ones and every registered one."""


def register_stance_detector(cls: type[StanceDetector]) -> type[StanceDetector]:
    """Make ``cls`` selectable by its ``kind`` (usable as a class decorator); a kind taken by
    another class is refused."""
    if not (isinstance(cls, type) and issubclass(cls, StanceDetector)) or not isinstance(getattr(cls, "kind", None), str):
        raise TypeError(f"{cls!r} is not a StanceDetector subclass with a kind")
    if STANCE_DETECTORS.get(cls.kind, cls) is not cls:
        raise ValueError(f"stance detector kind {cls.kind!r} is taken by {STANCE_DETECTORS[cls.kind].__name__}")
    STANCE_DETECTORS[cls.kind] = cls
    return cls



@register_stance_detector
class Shoe(StanceDetector):
    """SHOE / GLRT (Skog et al., IEEE TBME 2010): the statistic of
    :func:`~bodyfusion.nav.detectors.shoe_statistic` over ``window`` samples and, as OpenShoe's
    ``zero_velocity_detector.m``, every sample of each window with T_k < ``threshold`` is stance.

    ``window`` W (samples), ``sigma_acc`` σ_a (m/s^2), ``sigma_gyro`` σ_ω (rad/s), ``threshold``
    γ (dimensionless). Since the σ only scale T, the decision depends on γ σ²; at the defaults
    stance means mean ‖ω‖² + (σ_ω/σ_a)² mean ‖f − g u‖² < 0.091 (rad/s)²: an RMS angular rate
    below ~0.30 rad/s (17 °/s) with a steady specific force (γ = 3e5 lets ~1 rad/s through). On
    the shared 60 Hz Vicon walk ([Hu2025]) the defaults agree with the authors' stance labels on
    92.8 % (left) and 88.3 % (right) of the samples (γ = 3e5: 84.0 % / 78.1 %)."""

    kind = "shoe"

    def __init__(self, window: int = SHOE_WINDOW, sigma_acc: float = SIGMA_ACC_MPS2,
                 sigma_gyro: float = SIGMA_GYRO_RADPS, threshold: float = STILL_THRESHOLD) -> None:
        self.window = window
        self.sigma_acc = sigma_acc
        self.sigma_gyro = sigma_gyro
        self.threshold = threshold

    def detect(self, acc_b: np.ndarray, gyro_b: np.ndarray, rate_hz: float, gravity: float,
               labels: np.ndarray | None = None) -> Shoe:
        self.statistic = detectors.shoe_statistic(acc_b, gyro_b, window=self.window, sigma_acc=self.sigma_acc,
                                                  sigma_gyro=self.sigma_gyro, gravity=gravity)
        self.statistic_window = int(self.window)
        self.stance = detectors.spread_windows(self.statistic < self.threshold, int(self.window),
                                               np.asarray(acc_b).shape[0])
        return self


@register_stance_detector
class AdaptiveShoe(StanceDetector):
    """SHOE with a threshold that follows the gait (the default): per window
    γ_k = clip(10^(f_k + ``margin_decades``), ``threshold``, ``motion_threshold``), f_k the floor
    of log₁₀ T over the gait cycle around it, the stride period measured from the angular rate
    (:func:`~bodyfusion.nav.detectors.adaptive_shoe_threshold`,
    :func:`~bodyfusion.nav.gait.stride_period`). Walking, running and stair stances at any rate.

    ``window`` W (samples; None: :data:`ADAPTIVE_WINDOW_S` at the rate, at least 3), σ_a (m/s^2),
    σ_ω (rad/s) as :class:`Shoe`; ``threshold``: what is still at it is always stance;
    ``motion_threshold``: nothing above it ever is (1e7: an RMS angular rate of ~5.5 rad/s at the
    default σ_ω); ``margin_decades``: how far above its cycle's floor stance reaches;
    ``prominence_decades``: how far a cycle's swing must rise above its floor for the cycle to be
    a gait (below it only ``threshold`` applies: standing, fidgeting). Results besides
    ``stance``: ``statistic``, ``gamma`` (the threshold per window) and ``period_s``."""

    kind = "adaptive"

    def __init__(self, window: int | None = None, sigma_acc: float = SIGMA_ACC_MPS2,
                 sigma_gyro: float = SIGMA_GYRO_RADPS, threshold: float = STILL_THRESHOLD,
                 motion_threshold: float = 1e7, margin_decades: float = 0.5, prominence_decades: float = 1.0) -> None:
        if not threshold < motion_threshold:
            raise ValueError(f"threshold must be below motion_threshold ({motion_threshold:g})")
        self.window = window
        self.sigma_acc = sigma_acc
        self.sigma_gyro = sigma_gyro
        self.threshold = threshold
        self.motion_threshold = motion_threshold
        self.margin_decades = margin_decades
        self.prominence_decades = prominence_decades

    def detect(self, acc_b: np.ndarray, gyro_b: np.ndarray, rate_hz: float, gravity: float,
               labels: np.ndarray | None = None) -> AdaptiveShoe:
        w = self.window if self.window is not None else max(3, int(round(ADAPTIVE_WINDOW_S * rate_hz)))
        self.statistic = detectors.shoe_statistic(acc_b, gyro_b, window=w, sigma_acc=self.sigma_acc,
                                                  sigma_gyro=self.sigma_gyro, gravity=gravity)
        self.statistic_window = w
        self.period_s = stride_period(np.linalg.norm(np.asarray(gyro_b, dtype=float), axis=1), rate_hz)
        self.gamma = detectors.adaptive_shoe_threshold(
            self.statistic, self.period_s[w // 2:w // 2 + self.statistic.size], rate_hz,
            gamma_still=self.threshold, gamma_motion=self.motion_threshold, margin_decades=self.margin_decades,
            prominence_decades=self.prominence_decades)
        self.stance = detectors.spread_windows(self.statistic < self.gamma, w, np.asarray(acc_b).shape[0])
        return self


@register_stance_detector
class AccelerationMagnitude(StanceDetector):
    """Acceleration magnitude [Xu2024]: stance where | mean_window ‖f‖ − g | ≤ ``threshold``
    (m/s^2), over a centred ``window`` (samples) (:func:`~bodyfusion.nav.detectors.acceleration_magnitude`)."""

    kind = "magnitude"

    def __init__(self, threshold: float = 0.5, window: int = SHOE_WINDOW) -> None:
        self.threshold = threshold
        self.window = window

    def detect(self, acc_b: np.ndarray, gyro_b: np.ndarray, rate_hz: float, gravity: float,
               labels: np.ndarray | None = None) -> AccelerationMagnitude:
        self.stance = detectors.acceleration_magnitude(acc_b, threshold=self.threshold, gravity=gravity,
                                                       window=self.window)
        return self


@register_stance_detector
class AxesSumBand(StanceDetector):
    """Axes-sum band [Deng2026]: stance where ``low`` < f_x + f_y + f_z < ``high`` (m/s^2; None:
    g − 1 and g + 1, for a sensor with one axis up), over a centred ``window`` (samples)
    (:func:`~bodyfusion.nav.detectors.axes_sum_band`)."""

    kind = "axes_band"

    def __init__(self, low: float | None = None, high: float | None = None, window: int = SHOE_WINDOW) -> None:
        if low is not None and high is not None and not low < high:
            raise ValueError(f"need low < high, got {low} and {high}")
        self.low = low
        self.high = high
        self.window = window

    def detect(self, acc_b: np.ndarray, gyro_b: np.ndarray, rate_hz: float, gravity: float,
               labels: np.ndarray | None = None) -> AxesSumBand:
        low = self.low if self.low is not None else gravity - 1.0
        high = self.high if self.high is not None else gravity + 1.0
        if not low < high:
            raise ValueError(f"need low < high, got {low} and {high}")
        self.stance = detectors.axes_sum_band(acc_b, low=low, high=high, window=self.window)
        return self


@register_stance_detector
class Labels(StanceDetector):
    """The recording's own stance column (a motion-capture or pressure-insole label)."""

    kind = "labels"

    def detect(self, acc_b: np.ndarray, gyro_b: np.ndarray, rate_hz: float, gravity: float,
               labels: np.ndarray | None = None) -> Labels:
        if labels is None:
            raise ValueError("the labels detector needs the recording's stance column")
        self.stance = np.asarray(labels, dtype=bool).copy()
        return self
