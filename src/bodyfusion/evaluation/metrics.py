"""Scoring of estimated trajectories against ground truth (docs/architecture.md, "Evaluation protocol").

Frames and units: every position is in the navigation frame, local East-North-Up (ENU),
metres; time in seconds. "Horizontal" means the east-north plane, "vertical" the up axis.

Errors are computed at the TRUTH epochs: each estimate is interpolated linearly to the
truth times, and truth epochs outside the estimate's time span are skipped. Datasets
without absolute heading are aligned with ONE planar rotation + translation (no scale),
fitted on the first ``alignment_distance_m`` (default 3 m) of travel of all systems
together, so the systems' relative geometry is not adjusted.
"""

from __future__ import annotations

import math

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from bodyfusion.base.errors import FusionError
from bodyfusion.base.types import Trajectory, TruthTrack

PERCENTILES = (50, 75, 90, 95, 99)

ALIGNMENTS = ("first_3m", "none")
"""Accepted values of ``score_systems(alignment=...)``."""

ERROR_EPOCHS = "truth"
"""Where errors are evaluated: at truth epochs, the estimate interpolated to them."""

_STAT_KEYS = ("rmse", "mean", "max") + tuple(f"p{p}" for p in PERCENTILES)


# --------------------------------------------------------------------------- transform


@dataclass
class PlanarTransform:
    """p_truth ≈ R @ p_est[:2] + translation (horizontal); vertical offset dz added to up.

    rotation_rad: rotation about the up axis, counter-clockwise (east towards north), rad.
    translation_m: (2,) east, north translation, m.
    vertical_offset_m: added to the up coordinate, m.
    """

    rotation_rad: float
    translation_m: np.ndarray
    vertical_offset_m: float

    @property
    def matrix(self) -> np.ndarray:
        """(2, 2) horizontal rotation matrix R."""
        c, s = np.cos(self.rotation_rad), np.sin(self.rotation_rad)
        return np.array([[c, -s], [s, c]])

    def apply(self, pos_n: np.ndarray) -> np.ndarray:
        """Map estimate positions (N, 3) ENU m into the truth frame; returns a new (N, 3) array."""
        pos = np.asarray(pos_n, dtype=float)
        out = np.empty(pos.shape, dtype=float)
        out[..., :2] = pos[..., :2] @ self.matrix.T + np.asarray(self.translation_m, dtype=float)
        out[..., 2] = pos[..., 2] + self.vertical_offset_m
        return out

    @classmethod
    def identity(cls) -> "PlanarTransform":
        """No rotation, no translation, no vertical offset."""
        return cls(0.0, np.zeros(2), 0.0)

    def to_dict(self) -> dict[str, float | list[float]]:
        """Plain-JSON form: rotation in degrees and radians, translation and offset in m."""
        return {
            "rotation_rad": float(self.rotation_rad),
            "rotation_deg": float(np.degrees(self.rotation_rad)),
            "translation_m": [float(v) for v in np.asarray(self.translation_m, dtype=float)],
            "vertical_offset_m": float(self.vertical_offset_m),
        }


# --------------------------------------------------------------------------- helpers


def _interp_track(t_src: np.ndarray, pos_src: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Linear interpolation of positions (N, 3) given at ``t_src`` (increasing, s) to times ``t``.

    Returns (M, 3); NaN rows for times outside [t_src[0], t_src[-1]].
    """
    t_src = np.asarray(t_src, dtype=float)
    pos_src = np.asarray(pos_src, dtype=float).reshape(len(t_src), -1)
    t = np.asarray(t, dtype=float)
    out = np.full((t.size, pos_src.shape[1]), np.nan)
    if t_src.size == 0 or t.size == 0:
        return out
    if t_src.size == 1:
        out[t == t_src[0]] = pos_src[0]
        return out
    inside = (t >= t_src[0]) & (t <= t_src[-1])
    # one vectorised np.interp per coordinate (3 columns, not a loop over samples)
    out[inside] = np.column_stack([np.interp(t[inside], t_src, col) for col in pos_src.T])
    return out


def _in_span(t: np.ndarray, t_span: np.ndarray) -> np.ndarray:
    """Boolean mask of ``t`` inside [t_span[0], t_span[-1]] (inclusive); all False if span empty."""
    t = np.asarray(t, dtype=float)
    if len(t_span) == 0:
        return np.zeros(t.shape, dtype=bool)
    return (t >= t_span[0]) & (t <= t_span[-1])


def _rows(mask: np.ndarray) -> slice | np.ndarray:
    """The rows ``mask`` (N,) selects: a slice when they are consecutive (as at increasing
    times inside a span), so that indexing by it gives a view, not a copy; else the mask."""
    if not mask.any():
        return mask
    first = int(np.argmax(mask))
    stop = mask.size - int(np.argmax(mask[::-1]))
    return slice(first, stop) if np.count_nonzero(mask) == stop - first else mask


def _cumulative_horizontal(pos_n: np.ndarray) -> np.ndarray:
    """(N,) cumulative horizontal path length from the first row, m (NaN steps count as 0)."""
    pos = np.asarray(pos_n, dtype=float)
    if len(pos) == 0:
        return np.zeros(0)
    steps = np.hypot(*np.diff(pos[:, :2], axis=0).T)
    return np.concatenate(([0.0], np.cumsum(np.nan_to_num(steps, nan=0.0))))


def interpolate_truth(truth: TruthTrack, t: np.ndarray) -> np.ndarray:
    """Truth positions (M, 3) ENU m at times ``t`` (s), linear; NaN outside the truth's time span."""
    return _interp_track(truth.t, truth.pos_n, t)


def path_length_m(pos_n: np.ndarray) -> float:
    """Horizontal (east-north) cumulative path length of positions (N, 3) ENU, m. NaN steps are skipped."""
    cum = _cumulative_horizontal(pos_n)
    return float(cum[-1]) if cum.size else 0.0


def loop_closure_m(traj: Trajectory) -> float:
    """Horizontal distance ‖p_last − p_first‖ of a trajectory, m (first/last finite positions).

    Frame-independent under a planar rigid transform, so no alignment is needed. NaN if the
    trajectory has no finite horizontal position.
    """
    xy = np.asarray(traj.pos_n, dtype=float)[:, :2]
    finite = np.flatnonzero(np.all(np.isfinite(xy), axis=1))
    if finite.size == 0:
        return float("nan")
    return float(np.hypot(*(xy[finite[-1]] - xy[finite[0]])))


def error_stats(err: np.ndarray) -> dict[str, float]:
    """Statistics of absolute errors (m): rmse, mean, max, p50, p75, p90, p95, p99.

    NaN entries are ignored; percentiles use linear interpolation (numpy default).
    All values are plain Python floats; all NaN if no finite error is given.
    """
    e = np.abs(np.asarray(err, dtype=float).ravel())
    e = e[np.isfinite(e)]
    if e.size == 0:
        return {k: float("nan") for k in _STAT_KEYS}
    pct = np.percentile(e, PERCENTILES)
    out = {
        "rmse": float(np.sqrt(np.mean(e**2))),
        "mean": float(np.mean(e)),
        "max": float(np.max(e)),
    }
    out.update({f"p{p}": float(v) for p, v in zip(PERCENTILES, pct)})
    return out


class ErrorSketch:
    """:func:`error_stats` of absolute errors (m) taken a block at a time, in bounded memory: the
    sum, sum of squares and largest exactly, the percentiles from a log-binned histogram
    within ``relative_accuracy`` of their value (DDSketch's bins, C. Masson, J. E. Rim, H. K.
    Lee, VLDB 2019: bin i holds (γ^(i−1), γ^i], γ = (1 + α)/(1 − α), its value 2γ^i/(γ + 1)),
    linearly interpolated between the two ranks as :func:`numpy.percentile` does. Errors below
    ``smallest_m`` count as zero; NaN is ignored. ``count``: errors taken."""

    def __init__(self, relative_accuracy: float = 1e-3, smallest_m: float = 1e-9, largest_m: float = 1e6) -> None:
        self._log_gamma = math.log((1.0 + relative_accuracy) / (1.0 - relative_accuracy))
        self._first = math.floor(math.log(smallest_m) / self._log_gamma)
        self._counts = np.zeros(math.ceil(math.log(largest_m) / self._log_gamma) - self._first + 2, dtype=np.int64)
        self._smallest = smallest_m
        self.count = 0
        self._sum = self._sum_sq = 0.0
        self._max = -math.inf

    def add(self, err: np.ndarray) -> None:
        """Take the errors ``err`` (m; their absolute values; NaN ignored)."""
        e = np.abs(np.asarray(err, dtype=float).ravel())
        e = e[np.isfinite(e)]
        if not e.size:
            return
        self.count += e.size
        self._sum += float(np.sum(e))
        self._sum_sq += float(np.sum(e * e))
        self._max = max(self._max, float(np.max(e)))
        bins = np.zeros(e.size, dtype=np.int64)  # bin 0: below the smallest
        big = e >= self._smallest
        bins[big] = np.clip(np.ceil(np.log(e[big]) / self._log_gamma).astype(np.int64) - self._first, 1,
                            self._counts.size - 1)
        self._counts += np.bincount(bins, minlength=self._counts.size)

    def _value(self, rank: int) -> float:
        """The value of the error of rank ``rank`` (0-based, ascending): its bin's."""
        i = int(np.searchsorted(np.cumsum(self._counts), rank, side="right"))
        return 0.0 if i == 0 else min(2.0 * math.exp((i + self._first) * self._log_gamma) /
                                      (math.exp(self._log_gamma) + 1.0), self._max)

    def stats(self) -> dict[str, float]:
        """The figures :func:`error_stats` gives (all NaN before any error)."""
        if not self.count:
            return {k: float("nan") for k in _STAT_KEYS}
        out = {"rmse": math.sqrt(self._sum_sq / self.count), "mean": self._sum / self.count, "max": self._max}
        for p in PERCENTILES:
            r = p / 100.0 * (self.count - 1)
            lo, hi = math.floor(r), math.ceil(r)
            a, b = self._value(lo), self._value(hi)
            out[f"p{p}"] = a + (b - a) * (r - lo)
        return out


def error_cdf(err: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Empirical CDF of absolute errors: (sorted errors m, cumulative probability in (0, 1]). NaN ignored."""
    e = np.abs(np.asarray(err, dtype=float).ravel())
    e = np.sort(e[np.isfinite(e)])
    return e, np.arange(1, e.size + 1, dtype=float) / max(e.size, 1)


def horizontal_sigma_m(traj: Trajectory, t: np.ndarray) -> np.ndarray:
    """The horizontal σ (DRMS, √(σ_E² + σ_N²), m; unchanged by the evaluation rotation) of
    ``traj``'s position covariance, interpolated linearly to times ``t`` (s); NaN outside its span."""
    sd = np.asarray(traj.pos_sd, dtype=float)
    return np.interp(np.asarray(t, dtype=float), traj.t, np.hypot(sd[:, 0], sd[:, 1]), left=np.nan, right=np.nan)


def outage_errors(est: Trajectory, truth: TruthTrack, transform: PlanarTransform,
                  start_s: float, duration_s: float) -> dict[str, float]:
    """Horizontal error (m) of one system across a GNSS outage ``[start_s, start_s + duration_s)`` (s).

    Evaluated at the ESTIMATE's epochs (truth interpolated to them, estimate mapped by
    ``transform``), so an update at the first fix after the outage does not leak back into
    the error before it:

    - ``end_error_m``: at the estimate's last epoch strictly before ``start_s + duration_s``,
      the error accumulated just before GNSS returns. With ``duration_s`` 0 it is the error
      just before ``start_s`` with GNSS on: the baseline a study compares outages with.
    - ``max_error_m``: the largest error at the epochs in ``[start_s, start_s + duration_s)``
      and at that last epoch.
    - ``end_t_s``: the time of that last epoch, s.

    All NaN when the estimate has no epoch before the outage's end inside the truth's span.
    """
    end = start_s + duration_s
    t = np.asarray(est.t, dtype=float)
    p_truth = _interp_track(truth.t, truth.pos_n, t)
    d = transform.apply(np.asarray(est.pos_n, dtype=float)) - p_truth
    h_err = np.hypot(d[:, 0], d[:, 1])
    usable = np.flatnonzero((t < end) & np.isfinite(h_err))
    if usable.size == 0:
        return {"end_error_m": float("nan"), "max_error_m": float("nan"), "end_t_s": float("nan")}
    last = usable[-1]
    window = usable[t[usable] >= start_s]
    return {"end_error_m": float(h_err[last]),
            "max_error_m": float(max(h_err[last], h_err[window].max(initial=0.0))),
            "end_t_s": float(t[last])}


# --------------------------------------------------------------------------- alignment


def _alignment_pairs(
    est: Trajectory, truth: TruthTrack, distance_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """(estimate, truth) position pairs (K, 3) for the first ``distance_m`` of truth travel.

    Truth epochs are restricted to the estimate's time span; path length is counted from
    the first such epoch, and the epochs kept are those before the truth has travelled
    ``distance_m`` plus the first epoch reaching it (so a sparse truth gives at least two
    points whenever two overlap). Pairs with a non-finite coordinate are dropped.
    """
    t_truth = np.asarray(truth.t, dtype=float)
    inside = _in_span(t_truth, np.asarray(est.t, dtype=float))
    t = t_truth[inside]
    p_truth = np.asarray(truth.pos_n, dtype=float)[inside]
    if t.size == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    cum = _cumulative_horizontal(p_truth)
    n_keep = min(int(np.searchsorted(cum, distance_m, side="left")) + 1, t.size)
    t, p_truth = t[:n_keep], p_truth[:n_keep]
    p_est = _interp_track(est.t, est.pos_n, t)
    ok = np.all(np.isfinite(p_est[:, :2]), axis=1) & np.all(np.isfinite(p_truth[:, :2]), axis=1)
    return p_est[ok], p_truth[ok]


def fit_first_distance_alignment(
    estimates: Mapping[str, Trajectory],
    truths: Mapping[str, TruthTrack],
    distance_m: float = 3.0,
) -> PlanarTransform:
    """One planar rotation + translation (no scale) mapping all estimates onto their truths.

    Closed-form least squares (2-D Kabsch/Umeyama, proper rotation) over the pairs
    (estimate interpolated to truth epoch, truth) of ALL systems present in both mappings,
    each contributing its epochs until its truth has travelled ``distance_m`` horizontally
    (m, cumulative path length from its first epoch inside the estimate's span). The
    vertical offset is mean(truth_up − est_up) over the same pairs that have a height (0 for
    horizontal truth). Fewer than two pairs,
    or pairs with no horizontal spread, give a translation-only fit.

    Raises FusionError if no estimate overlaps its truth in time.
    """
    names = [n for n in estimates if n in truths]
    pairs = [_alignment_pairs(estimates[n], truths[n], distance_m) for n in names]
    a = np.concatenate([p[0] for p in pairs]) if pairs else np.zeros((0, 3))
    b = np.concatenate([p[1] for p in pairs]) if pairs else np.zeros((0, 3))
    if a.shape[0] == 0:
        which = ", ".join(names) if names else "none"
        raise FusionError(
            f"alignment first_{distance_m:g}m: no estimate overlaps its truth in time "
            f"(systems with truth: {which})"
        )
    a_mean, b_mean = a.mean(axis=0), b.mean(axis=0)
    ac, bc = a[:, :2] - a_mean[:2], b[:, :2] - b_mean[:2]
    # Maximise sum b_i . R a_i  ->  theta = atan2(sum a x b, sum a . b)
    cross = float(np.sum(ac[:, 0] * bc[:, 1] - ac[:, 1] * bc[:, 0]))
    dot = float(np.sum(ac[:, 0] * bc[:, 0] + ac[:, 1] * bc[:, 1]))
    scale = float(np.sqrt(np.sum(ac**2) * np.sum(bc**2)))
    if a.shape[0] < 2 or scale <= 1e-12 or np.hypot(cross, dot) <= 1e-12 * max(scale, 1.0):
        theta = 0.0  # rotation not observable: translation only
    else:
        theta = float(np.arctan2(cross, dot))
    c, s = np.cos(theta), np.sin(theta)
    rot = np.array([[c, -s], [s, c]])
    translation = b_mean[:2] - rot @ a_mean[:2]
    dz = b[:, 2] - a[:, 2]
    dz = dz[np.isfinite(dz)]  # horizontal truth has no height
    return PlanarTransform(theta, translation, float(dz.mean()) if dz.size else 0.0)


# --------------------------------------------------------------------------- scoring


@dataclass
class SystemScore:
    """Errors of one system at the truth epochs inside its estimate's time span.

    t: (M,) s.  pos_est_aligned, pos_truth: (M, 3) ENU m (estimate after the evaluation
    transform).  horizontal_error_m: (M,) east-north distance, m.  vertical_error_m: (M,)
    absolute up difference, m.  ``t`` and ``pos_truth`` are read-only, views of the truth's
    arrays where its epochs inside the span are consecutive (always, for increasing truth
    times), not copies.  metrics: the per-system block of metrics.json without
    "samples" (see ``score_systems``).
    """

    t: np.ndarray
    pos_est_aligned: np.ndarray
    pos_truth: np.ndarray
    horizontal_error_m: np.ndarray
    vertical_error_m: np.ndarray
    metrics: dict


def _score_one(
    name: str, est: Trajectory, truth: TruthTrack, transform: PlanarTransform, loop: bool
) -> SystemScore:
    t_truth = np.asarray(truth.t, dtype=float)
    inside = _in_span(t_truth, np.asarray(est.t, dtype=float))
    if not np.any(inside):
        raise FusionError(
            f"scoring {name}: truth ({_span(t_truth)}) does not overlap the estimate "
            f"({_span(np.asarray(est.t, dtype=float))}) in time"
        )
    rows = _rows(inside)
    t, p_truth = t_truth[rows], np.asarray(truth.pos_n, dtype=float)[rows]
    t.flags.writeable = p_truth.flags.writeable = False  # views of the truth's arrays, as a rule
    p_est = transform.apply(_interp_track(est.t, est.pos_n, t))
    d = p_est - p_truth
    h_err = np.hypot(d[:, 0], d[:, 1])
    v_err = np.abs(d[:, 2])

    if truth.sparse:
        # Sparse surveyed points: the straight lines between them underestimate the walk,
        # so the distance is the estimate's own path over the scored time span.
        mid = (est.t > t[0]) & (est.t < t[-1])
        ends = _interp_track(est.t, est.pos_n, t[[0, -1]])
        distance = path_length_m(np.vstack([ends[:1], np.asarray(est.pos_n, dtype=float)[mid], ends[1:]]))
        source = "estimate"
    else:
        distance = path_length_m(p_truth)
        source = "truth"

    finite = np.flatnonzero(np.isfinite(h_err))
    final = float(h_err[finite[-1]]) if finite.size else float("nan")
    metrics: dict = {
        "distance_m": float(distance),
        "horizontal_error_m": error_stats(h_err),
        **({"vertical_error_m": error_stats(v_err)} if np.isfinite(v_err).any() else {}),
        "final_error_pct_distance": 100.0 * final / distance if distance > 0 else float("nan"),
        "scored_epochs": int(finite.size),
        "distance_source": source,
    }
    if loop:
        metrics["loop_closure_m"] = loop_closure_m(est)
    return SystemScore(t, p_est, p_truth, h_err, v_err, metrics)


def _span(t: np.ndarray) -> str:
    return f"{t[0]:g}..{t[-1]:g} s" if t.size else "empty"


def score_systems(
    estimates: Mapping[str, Trajectory],
    truths: Mapping[str, TruthTrack],
    alignment: str = "first_3m",
    loop: bool = False,
    alignment_distance_m: float = 3.0,
) -> tuple[PlanarTransform, dict[str, SystemScore]]:
    """Align (optionally) and score every system that has truth.

    alignment: "first_3m" — one transform for all systems, ``fit_first_distance_alignment``
    over the first ``alignment_distance_m`` m; "none" — identity (simulations know heading).

    Errors are at truth epochs (estimate interpolated linearly to them); truth epochs
    outside the estimate's span are skipped. Systems without truth are absent from the
    result (use ``loop_closure_m`` for them). Per-system ``metrics``:

    - distance_m: horizontal path length over the scored epochs, m — of the TRUTH for dense
      truth, of the ESTIMATE for sparse truth (surveyed points); ``distance_source`` says which.
    - horizontal_error_m, vertical_error_m: ``error_stats`` blocks, m (no vertical block for
      horizontal truth).
    - final_error_pct_distance: 100 × horizontal error at the last scored epoch / distance_m
      (NaN if distance_m is 0).
    - scored_epochs: number of epochs with a finite error.
    - loop_closure_m (only if ``loop``): ``loop_closure_m`` of the whole estimate, m.

    Raises FusionError for an unknown alignment or a system whose truth and estimate do not
    overlap in time.
    """
    if alignment not in ALIGNMENTS:
        raise FusionError(f"alignment: unknown method {alignment!r} (expected one of {', '.join(ALIGNMENTS)})")
    names = [n for n in estimates if n in truths]
    if alignment == "first_3m" and names:
        transform = fit_first_distance_alignment(estimates, truths, alignment_distance_m)
    else:
        transform = PlanarTransform.identity()
    scores = {n: _score_one(n, estimates[n], truths[n], transform, loop) for n in names}
    return transform, scores


def sensor_alone_score(t_fix: np.ndarray, pos_fix: np.ndarray, truth: TruthTrack) -> dict:
    """The error of a system's absolute sensor used alone (a phone's GNSS fixes, ``t_fix`` (K,) s,
    ``pos_fix`` (K, 3) ENU m) at every truth epoch, as its user has it: the last fix at or before
    the epoch (the first fix before any), no alignment. ``horizontal_error_m`` (and, with 3-D
    truth, ``vertical_error_m``) blocks of :func:`error_stats`."""
    t = np.asarray(truth.t, dtype=float)
    k = np.clip(np.searchsorted(t_fix, t, side="right") - 1, 0, len(t_fix) - 1)
    d = np.asarray(pos_fix, dtype=float)[k] - np.asarray(truth.pos_n, dtype=float)
    out = {"horizontal_error_m": error_stats(np.hypot(d[:, 0], d[:, 1]))}
    if np.asarray(truth.pos_n).shape[1] > 2 and np.isfinite(d[:, 2]).any():
        out["vertical_error_m"] = error_stats(np.abs(d[:, 2]))
    return out
