"""Smoothing of foot-mounted INS runs: RTS, forward–backward (FB) and FB-RTS ([Shen2025] §3).

Runs after the fuser (``smoother`` in the layout, :class:`bodyfusion.core.layout.SmootherConfig`):
the core calls :meth:`bodyfusion.plugins.foot_ins.system.FootIns.smooth`, which hands its
:meth:`~bodyfusion.plugins.foot_ins.system.FootIns.smoothing_record` to :func:`smooth_record`.

The forward pass is the filter itself. The filter keeps no N×15×15 history: its run is
replayed block by block (:func:`~bodyfusion.plugins.foot_ins.smoothing_replay.filter_pass`)
from its recorded state and mechanisation memory at the block start, with the filter's own
compiled step (:func:`bodyfusion.plugins.foot_ins.kernels.ekf_step`), the gap policy's
inflations and the covariances set outside the compiled loop (fuser corrections, position
fixes, the ckf's coloured updates): the same numbers, bit for bit
(``state_rebuild_max_abs_error`` and ``covariance_rebuild_rel_error`` in the diagnostics: the
replayed against the recorded states, and the last covariance). The segmented kinds hold only
the current block (O(longest block) × 15 × 15 floats). The whole-run RTS replays the run once,
block by block from the last, each block into a compact record
(:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.record_pass`, about 1.3 kB per sample) that
holds that block alone, then swept back into the block before it
(:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.block_sweep`). The blocks start at the
covariance checkpoints the filter keeps as it runs (:class:`~bodyfusion.plugins.foot_ins.smoothing_record.ForwardRecord`: 120 floats every
:data:`CHECKPOINT_SAMPLES` samples or more, about 1.4 MB for an hour at 100 Hz); a stretch
without any is cut by a replay without a record (:func:`_blocks`). When the system knows
before its run that it will be smoothed so
(:meth:`~bodyfusion.plugins.foot_ins.system.FootIns.plan_smoothing`) and the record of the
whole run fits :data:`~bodyfusion.plugins.foot_ins.smoothing_record.STORE_BYTES`, the ekf writes that record itself as it runs, and the RTS
(either span) replays nothing: its record is the filter's, not a replay of it.

Segments. The run is split at the midpoints of stance runs (runs shorter than
``min_stance_s`` are ignored so a one-sample detector flicker does not cut a stride; gaps
longer than ``max_segment_s`` are cut evenly). Each segment holds one swing with half a
stance at either end.

Kinds:

* ``rts`` (§3.2): Rauch–Tung–Striebel over the closed-loop error states; ``span: whole`` (the
  default) carries the backward sweep across the blocks — the fixed-interval smoother of the
  whole run, swept in the modified Bryson–Frazier form, which needs no covariance inverse
  (:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.mbf_sweep`; the same smoother, equal
  to the textbook sweep to rounding); ``span: segment`` smooths every segment on its own —
  the paper's segmented RTS, which at a segment's end is the filter: the same sweep of the
  segment's part of the record (the filter's own, or the segment replayed into one) started
  from zero adjoints at its end (:func:`_segmented_rts`).
* ``fb`` (§3.1, §3.3): per segment a–b, the forward pass (the filter) and a backward
  navigation (the filter's step on the time-reversed samples: angular rates, Earth rate,
  velocity and gyro bias negated, the same specific force) with its own error filter and
  ZUPTs, fused by covariance. The passes are independent. The backward pass starts at b
  from the forward nominal state — a linearisation point, not information: its prior
  (:func:`~bodyfusion.plugins.foot_ins.smoothing_fb.backward_prior`) is diffuse on every
  state but the yaw, which it shares with the forward pass (a foot INS cannot observe it; a
  diffuse yaw would only gather the EKF's spurious yaw information), and the fusion removes
  that shared yaw error
  (:func:`~bodyfusion.plugins.foot_ins.smoothing_fb.fuse_block`). At each sample the
  forward posterior is fused with the backward prior (before its update at that sample), so
  no sample is counted twice: the two-filter form of the smoother given the data up to b. At
  b the fused state is the forward one, and the next segment continues from the filter's
  own state and covariance — nothing shrinks at segment boundaries.
* ``fb-rts`` (Fig. 3): as ``fb`` with both passes RTS-smoothed over the segment before the
  fusion. Both smoothed passes hold the segment's samples, so the fusion's own covariance
  would count them twice; the reported covariance is the forward pass's RTS covariance, the
  information the two together hold.

Position (``fb``, ``fb-rts``). The backward pass cannot observe position; the fused position
is recomputed from the fused velocity by the mechanisation's trapezoid (the paper's
re-forward navigation, :func:`~bodyfusion.plugins.foot_ins.smoothing_fb.integrate_position`),
from the fused position at the segment start, plus the position the filter's corrections
outside its loop moved (fuser constraints, position fixes: the backward pass cannot replay
them, so FB keeps them as the filter made them; FB-RTS spreads the foot's own ones through the
forward RTS and keeps the relative ones, below).
Started instead from the previous segment's recomputed end, as the paper chains its
segments, the track would be a pure integral of velocity whose small per-segment
differences from the smoothed position add up over the run. Its covariance is the fused one.

Corrections made outside the filter's compiled loop are part of the filter's record. A
correction of this foot's own (a position fix, the ckf's coloured update) is information: RTS
smooths through it as through any update (the state jumps by the recorded correction, the
covariance becomes the recorded one, and the smoothed track before it moves with it). A
relative correction — one the fuser derived from another system's estimate as well
(:meth:`~bodyfusion.core.system.SensorSystem.apply_relative_correction`: a distance
constraint, a measurement spread by the cross-covariances) — is kept as the filter made it:
a known input that holds no information for this foot's smoother. The whole-run RTS passes
its adjoint through it unchanged (the jump stays where the filter made it, and before it the
smoothed error is taken with the covariance the filter had before it), and so does the
segmented RTS within each segment; FB and FB-RTS step through it with the recorded covariance.
Smoothed as a measurement of this foot it would be counted in each foot's smoother against the
other's *filtered* estimate, and an inequality constraint, recorded only where it acted, would
be spread back over the samples where it held without the information that it held: on a
simulated dual-foot walk (6 seeds) that made the smoothed feet 40–55 % worse than the
constrained filter. The gap policy's inflation is process noise of the step across the gap.
``smoother.constrain_smoothed`` (by default wherever the fuser enforces them) has the core
apply the constraints again to the smoothed tracks
(:func:`bodyfusion.core.smoothing.constrain_trajectories`).

Streaming. FB, FB-RTS and the segmented RTS run segment by segment in time order and need
only the segment's samples and the filter's state and covariance at its start: a segment's
smoothed output is available as soon as its last sample has arrived. The compute time of
each segment (the latency after its last sample) is measured (``latency_ms``: mean, p95,
max; every segment's in :attr:`SmoothingResult.segment_latency_ms`;
``benchmarks/smoothing_latency.py``).

Smoothing never fails a run: a run too short, without stance or where anything raises,
keeps the filter's result and counts a warning (``warnings`` in the system's
``diagnostics()['smoothing']``, hence metrics.json).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from bodyfusion.core.layout import SmootherConfig
from bodyfusion.nav import detectors
from bodyfusion.plugins.foot_ins.records import PACKED_SIZE, SmoothedOutput, SweepRecord, no_cross
from bodyfusion.plugins.foot_ins.smoothing_fb import fb_segment
from bodyfusion.plugins.foot_ins.smoothing_mbf import block_sweep, mbf_sweep, record_pass
from bodyfusion.plugins.foot_ins.smoothing_record import CHECKPOINT_SAMPLES, BlockBuffers, RunRecord

log = logging.getLogger(__name__)

MIN_SAMPLES = 10
"""Runs with fewer samples are not smoothed (warning)."""

MAX_BLOCK_SAMPLES = 4 * CHECKPOINT_SAMPLES
"""Longer stretches without a checkpoint (a run not advanced by the fuser, a record without
checkpoints) are cut into blocks of :data:`CHECKPOINT_SAMPLES`, their start covariances
given by a replay of the filter without a record."""

@dataclass
class SmoothingResult:
    """Smoothed nominal states (n, 16) and position covariances (n, 4: variances east, north,
    up and the east–north covariance, m²), or None (the filter's result stands), with the
    run's diagnostics; for the segmented kinds also the compute time of every segment in
    time order (ms; the diagnostics keep only its summary)."""

    x: np.ndarray | None
    pos_var: np.ndarray | None
    diagnostics: dict = field(default_factory=dict)
    segment_latency_ms: np.ndarray | None = None


def stance_midpoints(stance: np.ndarray, rate_hz: float, min_stance_s: float, ended: bool = False,
                     skip_first: bool = False) -> np.ndarray:
    """The midpoints (sample indices, increasing) of the stance runs at least ``min_stance_s``
    long; ``ended``: only the runs that ended before the last sample (a live record's later
    samples may lengthen the last); ``skip_first``: not a run that starts at sample 0 (a live
    record that starts at the midpoint of that run)."""
    starts, ends = detectors.stance_events(stance)
    keep = (ends - starts) >= max(1, int(round(min_stance_s * rate_hz)))
    if ended:
        keep &= ends < stance.shape[0]
    if skip_first:
        keep &= starts > 0
    return (starts[keep] + ends[keep] - 1) // 2


def cut_long_segments(bounds: np.ndarray, max_len: int) -> np.ndarray:
    """``bounds`` (sample indices, increasing) with every stretch longer than ``max_len`` samples
    cut evenly."""
    out = [int(bounds[0])]
    for b in bounds[1:]:
        a = out[-1]
        gap = int(b) - a
        if gap <= 0:
            continue
        pieces = -(-gap // max_len)
        for k in range(1, pieces):
            out.append(a + (gap * k) // pieces)
        out.append(int(b))
    return np.asarray(out, dtype=np.int64)


def segment_bounds(stance: np.ndarray, rate_hz: float, min_stance_s: float, max_segment_s: float) -> np.ndarray:
    """Segment boundaries (sample indices, increasing, first 0 and last n−1): the
    midpoints of the stance runs at least ``min_stance_s`` long, long gaps cut evenly."""
    n = stance.shape[0]
    mids = stance_midpoints(stance, rate_hz, min_stance_s)
    bounds = np.unique(np.concatenate([[0], mids, [n - 1]])).astype(np.int64)
    return cut_long_segments(bounds, max_segment_samples(max_segment_s, rate_hz))


def max_segment_samples(max_segment_s: float, rate_hz: float) -> int:
    """The longest segment (samples) for ``smoother.max_segment_s``."""
    return max(2, int(round(max_segment_s * rate_hz)))


def _latency(ms: list[float]) -> dict:
    if not ms:
        return {}
    a = np.asarray(ms)
    return {"segments": int(a.size), "mean_ms": float(a.mean()), "p95_ms": float(np.percentile(a, 95)),
            "max_ms": float(a.max())}


def _rebuild_error(replayed: np.ndarray, recorded: np.ndarray) -> float:
    """The largest max |replayed − recorded| / max |recorded| over covariances (…, 15, 15)."""
    scale = np.maximum(np.max(np.abs(recorded), axis=(-2, -1)), 1e-300)
    return float(np.max(np.max(np.abs(replayed - recorded), axis=(-2, -1)) / scale))


def _blocks(r: RunRecord, starts: np.ndarray, P_start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The block starts (K,) and the filter's covariances there (K, 15, 15) with every stretch
    longer than :data:`MAX_BLOCK_SAMPLES` cut into blocks of at most :data:`CHECKPOINT_SAMPLES`,
    the covariances at the new starts replayed (without a record) from the stretch's start."""
    ends = np.append(starts[1:], r.n - 1)
    new_idx, new_P = [starts], [P_start]
    buf = BlockBuffers(1)
    for k in np.flatnonzero(ends - starts > MAX_BLOCK_SAMPLES):
        a, b = int(starts[k]), int(ends[k])
        cuts = np.arange(a + CHECKPOINT_SAMPLES, b, CHECKPOINT_SAMPLES)
        P = np.empty((cuts.size, 15, 15))
        for m, c in enumerate(cuts):
            P[m] = r.forward(int(cuts[m - 1]) if m else a, int(c), P[m - 1] if m else P_start[k], False, buf)
        new_idx.append(cuts)
        new_P.append(P)
    idx = np.concatenate(new_idx)
    order = np.argsort(idx, kind="stable")
    return idx[order], np.concatenate(new_P)[order]


def sweep_store(r: RunRecord, bounds: np.ndarray, general: np.ndarray, ends: np.ndarray | None = None) -> SweepRecord:
    """The record :func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.record_pass` writes
    (``Pu`` … ``kept_P``), sized for the longest stretch ``bounds[k]`` … ``bounds[ends[k]]``
    (``ends``: default k + 1): its samples, stance samples, general updates (``general`` (n,))
    and kept corrections."""
    ends = np.arange(1, bounds.size) if ends is None else ends
    starts = bounds[:ends.size]
    L = int(np.max(bounds[ends] - starts))
    ns, ng = (int(np.max(np.diff(np.r_[0, np.cumsum(f[1:])][bounds][np.c_[np.arange(ends.size), ends]], axis=1)))
              for f in (r.stance, general))
    kept = np.searchsorted(r.kept_idx, bounds, side="right")
    nk = int(np.max(kept[ends] - kept[:ends.size]))
    return SweepRecord(np.empty((L + 1, PACKED_SIZE)), np.empty((L + 1, 3)), np.empty((ns, 6)), np.empty((ns, 15, 4)),
                       np.empty((ng, 15, 15)), np.empty((ng, 15)), np.empty((ng, 2)), np.zeros(ng, dtype=np.bool_),
                       np.empty((nk, 15, 15)))


def lag_windows(t: np.ndarray, bounds: np.ndarray, lag_s: float) -> np.ndarray:
    """For each segment k (``bounds[k]`` … ``bounds[k + 1]``), the index of the first bound at
    least ``lag_s`` after the segment's end (the last bound where the run ends sooner): the
    end of the data the fixed-lag smoother has when it emits that segment."""
    t_bounds = t[bounds]
    ends = np.searchsorted(t_bounds, t_bounds[1:] + lag_s - 1e-9, side="left")
    return np.minimum(np.maximum(ends, np.arange(1, bounds.size)), bounds.size - 1)


def _achieved_lag(t: np.ndarray, bounds: np.ndarray, ends: np.ndarray) -> dict:
    """The future data (s) each sample was smoothed with: least, median and largest before the
    run's last window (``tail_s``: the run's last stretch, smoothed with what was left of it)."""
    seg = np.repeat(np.arange(bounds.size - 1), np.diff(bounds))
    lag = t[bounds[ends]][seg] - t[bounds[0]:bounds[-1]]
    inner = lag[ends[seg] < bounds.size - 1]
    inner = inner if inner.size else lag
    tail = np.flatnonzero(ends == bounds.size - 1)[0]
    return {"min": float(inner.min()), "median": float(np.median(inner)), "max": float(inner.max()),
            "tail_s": float(t[bounds[-1]] - t[bounds[tail]])}


def _segmented_rts(r: RunRecord, bounds: np.ndarray, general: np.ndarray, forward: SweepRecord | None,
                   out_x: np.ndarray, out_var: np.ndarray, diag: dict,
                   ends: np.ndarray | None = None) -> tuple[float, list[float]]:
    """The RTS of each segment k given the data up to bound ``ends[k]`` (default k + 1: the
    segment on its own, ``span: segment``; :func:`lag_windows`: the fixed-lag smoother): the
    window's part of the filter's own record (``forward``,
    :meth:`~bodyfusion.plugins.foot_ins.smoothing_record.ForwardRecord.sweep_arrays`), or,
    without one, the window replayed into the record
    (:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.record_pass`), swept back from zero
    adjoints at its end. Windows go in time order, each writing from its segment's start to
    its end, so that a segment keeps what its own window gave it. Returns as :func:`_rts`."""
    ends = np.arange(1, bounds.size) if ends is None else ends
    failed = 0
    latencies: list[float] = []
    if forward is not None:  # entries per stance sample, general update, kept correction up to each bound
        Pu, f_ns, st_v, st_P, gen_P, gen_dx, gen_a, gen_kept, kept_P = forward
        counts = np.column_stack([np.r_[0, np.cumsum(f[1:])][bounds] for f in (r.stance, general)] +
                                 [np.searchsorted(r.kept_idx, bounds, side="right")])
    else:
        store = sweep_store(r, bounds, general, ends)
        buf = BlockBuffers(1)
    P = r.P0.copy()
    for k in range(bounds.size - 1):
        a, b, w = int(bounds[k]), int(bounds[k + 1]), int(bounds[ends[k]])
        t0 = time.perf_counter_ns()
        if forward is not None:
            (s0, g0, k0), (s1, g1, k1) = counts[k], counts[ends[k]]
            record = SweepRecord(Pu[a:w + 1], f_ns[a:w + 1], st_v[s0:s1], st_P[s0:s1], gen_P[g0:g1], gen_dx[g0:g1],
                                 gen_a[g0:g1], gen_kept[g0:g1], kept_P[k0:k1])
            failed += mbf_sweep(r.run, general, a, w - a, record, np.zeros(15), np.zeros((15, 15)),
                                SmoothedOutput(out_x, out_var), True, no_cross())
        else:
            P, window_failed = window_rts(r, general, (a, b, w), P, store, buf, SmoothedOutput(out_x, out_var))
            failed += window_failed
        latencies.append((time.perf_counter_ns() - t0) / 1e6)
    diag["rts_gain_failures"] = failed
    return (0.0 if forward is not None else _rebuild_error(P, r.P_end)), latencies


def window_rts(r: RunRecord, general: np.ndarray, window: tuple[int, int, int], P_a: np.ndarray, store: SweepRecord,
               buf: BlockBuffers, out: SmoothedOutput) -> tuple[np.ndarray, int]:
    """The RTS of segment a–b given the data up to w (``window`` (a, b, w), sample indices of
    ``r``): the filter replayed from a with its covariance there ``P_a`` into ``store``
    (:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.record_pass`, :func:`sweep_store`), swept
    back from zero adjoints at w into ``out`` (samples a … w). Returns the filter's covariance
    at b (where the next window starts) and the sweep's gain failures."""
    a, b, w = window
    P_w, error, ns, ng, nk = record_pass(r.start(a, P_a), r.run, general, a, w, store)
    P_b = P_w if w == b else r.forward(a, b, P_a, False, buf)
    r.state_error = max(r.state_error, error)
    Pu, f_ns, st_v, st_P, gen_P, gen_dx, gen_a, gen_kept, kept_P = store
    record = SweepRecord(Pu, f_ns, st_v[:ns], st_P[:ns], gen_P[:ng], gen_dx[:ng], gen_a[:ng], gen_kept[:ng],
                         kept_P[:nk])
    return P_b, mbf_sweep(r.run, general, a, w - a, record, np.zeros(15), np.zeros((15, 15)), out, True, no_cross())


def _rts(r: RunRecord, bounds: np.ndarray, whole: bool, out_x: np.ndarray, out_var: np.ndarray,
         diag: dict) -> tuple[float, list[float]]:
    """RTS over the whole run (the sweep carried back across blocks, each replayed once from the
    filter's covariance at its start: :meth:`~bodyfusion.plugins.foot_ins.smoothing_record.ForwardRecord.checkpoints`, :func:`_blocks`,
    :func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.block_sweep`) or per segment. Returns the
    covariance rebuild's relative error (:func:`_rebuild_error`: at the run's end, and the whole
    run's at every block end) and the per-segment latencies (segmented only)."""
    general = r.general_updates()
    forward = r.forward_record.sweep_arrays(r, general)
    if not whole:  # each segment swept back from zero adjoints at its end
        return _segmented_rts(r, bounds, general, forward, out_x, out_var, diag)
    if forward is not None:  # the filter's own record: nothing to replay
        diag["rts_gain_failures"] = mbf_sweep(r.run, general, 0, r.n - 1, forward, np.zeros(15), np.zeros((15, 15)),
                                              SmoothedOutput(out_x, out_var), True, no_cross())
        return 0.0, []
    starts, P_start = _blocks(r, *r.forward_record.checkpoints(r))
    P_replayed = np.empty_like(P_start)
    failed, error = block_sweep(r.run, general, starts, P_start, r.memory(starts),
                                sweep_store(r, np.r_[starts, r.n - 1], general), P_replayed,
                                SmoothedOutput(out_x, out_var))
    r.state_error = max(r.state_error, error)
    diag["rts_gain_failures"] = failed
    return _rebuild_error(P_replayed, np.concatenate([P_start[1:], r.P_end[None]])), []


def _fb(r: RunRecord, bounds: np.ndarray, with_rts: bool, out_x: np.ndarray, out_var: np.ndarray,
        diag: dict) -> tuple[float, list[float]]:
    """FB or FB-RTS segment by segment in time order (see the module docstring), one compiled
    call per segment (:func:`~bodyfusion.plugins.foot_ins.smoothing_fb.fb_segment`). Returns
    the covariance rebuild's relative error at the run's end (:func:`_rebuild_error`) and the
    per-segment latencies."""
    size = int(np.max(np.diff(bounds))) + 1
    buf = BlockBuffers(size, 2)
    fused_P = np.zeros((size, 0, 0) if with_rts else (size, 3, 3))  # the fused position block (FB)
    params_bw = r.params.backward()
    gain_failures = fusion_failures = 0
    latencies: list[float] = []
    P = r.P0.copy()
    for k in range(bounds.size - 1):
        a, b = int(bounds[k]), int(bounds[k + 1])
        t0 = time.perf_counter_ns()
        P, error, gains, fusions = fb_segment(r.run, params_bw, a, b, P, r.memory([a])[0], with_rts, buf.buffers(),
                                              buf.smoothing(fused_P), SmoothedOutput(out_x, out_var))
        latencies.append((time.perf_counter_ns() - t0) / 1e6)
        r.state_error = max(r.state_error, error)
        gain_failures += gains
        fusion_failures += fusions
    diag["rts_gain_failures"] = gain_failures
    diag["fusion_failures"] = fusion_failures
    return _rebuild_error(P, r.P_end), latencies


def smooth_record(rec: dict, cfg: SmootherConfig) -> SmoothingResult:
    """Smooth one recorded foot-INS run (see ``FootIns.smoothing_record``) per ``cfg``."""
    diag: dict = {"kind": cfg.kind, "warnings": 0, "warning_messages": []}

    def warn(msg: str) -> SmoothingResult:
        diag["warnings"] += 1
        diag["warning_messages"].append(msg)
        log.warning("smoothing: %s; keeping the filter's result", msg)
        return SmoothingResult(None, None, diag)

    r = RunRecord(rec)
    if r.n < MIN_SAMPLES:
        return warn(f"run too short to smooth ({r.n} samples, need {MIN_SAMPLES})")
    if not r.stance[1:].any():
        return warn("no stance found")
    bounds = segment_bounds(r.stance, r.rate_hz, cfg.min_stance_s, cfg.max_segment_s)
    if bounds.size < 2:
        return warn("no segment to smooth")
    diag["segments"] = int(bounds.size - 1)
    diag["span"] = "segment" if cfg.segmented else "whole"
    out_x = r.hist_x.copy()
    out_var = np.zeros((r.n, 4))
    if cfg.kind == "rts":
        rebuild_error, latencies = _rts(r, bounds, not cfg.segmented, out_x, out_var, diag)
    elif cfg.kind == "fixed-lag":
        general = r.general_updates()
        ends = lag_windows(r.t, bounds, cfg.lag_s)
        rebuild_error, latencies = _segmented_rts(r, bounds, general, r.forward_record.sweep_arrays(r, general), out_x,
                                                  out_var, diag, ends)
        diag["lag_s"] = _achieved_lag(r.t, bounds, ends)
    else:
        rebuild_error, latencies = _fb(r, bounds, cfg.kind == "fb-rts", out_x, out_var, diag)
    if latencies:
        diag["latency_ms"] = _latency(latencies)
    diag["covariance_rebuild_rel_error"] = rebuild_error
    diag["state_rebuild_max_abs_error"] = r.state_error
    if not np.all(np.isfinite(out_x)) or not np.all(np.isfinite(out_var)):
        return warn("smoother produced non-finite states")
    return SmoothingResult(out_x, out_var, diag, np.asarray(latencies) if latencies else None)


def smooth_system(system, cfg: SmootherConfig) -> SmoothingResult:
    """Smooth one system in place (its ``trajectory()`` then returns the smoothed track)."""
    t0 = time.perf_counter()
    try:
        result = smooth_record(system.smoothing_record(), cfg)
    except Exception as err:  # smoothing must never make a run fail
        log.warning("smoothing %s failed: %s; keeping the filter's result", system.name, err)
        result = SmoothingResult(None, None, {"kind": cfg.kind, "warnings": 1,
                                              "warning_messages": [f"smoother failed: {type(err).__name__}: {err}"]})
    result.diagnostics["wall_s"] = time.perf_counter() - t0
    system.set_smoothed(result.x, result.pos_var, result.diagnostics)
    return result
