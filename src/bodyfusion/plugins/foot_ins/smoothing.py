"""Smoothing of foot-mounted INS runs: RTS, forward–backward (FB) and FB-RTS.

Runs after the fuser (``smoother.kind`` in the layout, :class:`bodyfusion.core.layout.SmootherConfig`):
the core calls :meth:`bodyfusion.plugins.foot_ins.system.FootIns.smooth`, which hands its
:meth:`~bodyfusion.plugins.foot_ins.system.FootIns.smoothing_record` to :func:`smooth_record`.
The filter keeps no N×15×15 history: the smoother rebuilds the forward filter's
covariances block by block from the recorded nominal states (``hist_x``), the IMU
samples, the stance flags and the few covariances set outside the compiled loop (fuser
constraint corrections, position fixes) — the same functions in the same order, so the
rebuilt covariances are the filter's (``covariance_rebuild_rel_error`` in the
diagnostics checks the last one). Only the current block is held (buffers of
O(longest block) × 15 × 15 floats).

Segments. The run is split at the midpoints of stance runs (runs shorter than
``min_stance_s`` are ignored so a one-sample detector flicker does not cut a stride;
gaps longer than ``max_segment_s`` are cut evenly). Each segment then holds one swing
with half a stance at either end.

Kinds ([Shen2025] §3):

* ``rts``: fixed-interval RTS over the closed-loop error states (:func:`rts_block`),
  over the whole run (``span: whole``, the backward sweep carried across blocks, each
  block's forward covariances rebuilt from a checkpoint) or each segment on its own.
  The filter's error estimate is zero after every injection, so the recursion runs on
  the injected corrections: δx_{k|N} = K_k (δx_{k+1|N} + dx_{k+1}).
* ``fb``: per segment, a forward pass — the filter re-run over the segment
  (:func:`~bodyfusion.plugins.foot_ins.smoothing_kernels.forward_rerun_block`) from the previous segment's
  fused end state (attitude, velocity, position, biases and the 15×15 covariance as
  fused; the first segment from the filter's initial state, so it is the filter) — and a
  backward navigation (mechanisation backward in time: negated angular rates, Earth rate
  and velocity, same specific force) with its own error filter and ZUPTs, started from
  the forward pass's state and covariance at the segment end; the two fused by
  covariance (paper eqs. of §3.3). The fused end state seeds the next segment.
* ``fb-rts``: as ``fb`` with both passes RTS-smoothed over the segment first (the paper's
  scheme).

Choices where the paper is vague (documented here, stated in the report):

* The backward pass starts from the forward pass's state and covariance at the segment
  end (velocity and gyro bias negated). The paper does not say how the backward pass is
  initialised; at a stance midpoint the ZUPTs have pinned the velocity and the level, so
  this costs little and keeps one estimate of heading and position.
* Fusion: the backward pass's p, v, θ are a measurement of the forward pass's (the
  paper fuses attitude, velocity and position); the biases move with their forward
  cross-covariances. The two passes share the data (and the backward pass starts from
  the forward end state), so the fused covariance is optimistic — the paper's scheme
  counts it so too, and it is what seeds the next segment.
* Corrections made outside the filter's compiled loop (fuser constraints, position
  fixes) are carried into the forward re-run: the original filter's correction at that
  sample is injected into the re-run state and its covariance replaced by the one the
  correction left. The record does not hold the other feet or the fixes, so they are
  not recomputed for the re-run state.
* Constraints: the fuser applies them in the forward pass (``fuser.method``); with
  ``smoother.constrain_smoothed`` the core applies them again to the smoothed tracks
  (:func:`bodyfusion.core.smoothing.constrain_trajectories`).

Streaming. FB and FB-RTS run segment by segment in time order and need only the
segment's samples, the previous segment's fused end state and the filter's corrections
made outside its loop: a segment's smoothed output is available as soon as its last
sample has arrived (one stride after its start). The compute time of each segment (the
latency after the segment's last sample) is measured and reported (``latency_ms``: mean,
p95, max; every segment's in :attr:`SmoothingResult.segment_latency_ms`;
``benchmarks/smoothing_latency.py``).

Smoothing never fails a run: a run too short, without stance or where anything
raises, keeps the filter's result and counts a warning (``warnings`` in the system's
``diagnostics()['smoothing']``, hence metrics.json).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from bodyfusion.nav import detectors
from bodyfusion.core.layout import SmootherConfig
from bodyfusion.plugins.foot_ins.smoothing_kernels import (apply_smoothed, backward_block, forward_block, forward_rerun_block, fuse_block,
                                     rts_block)

log = logging.getLogger(__name__)

MIN_SAMPLES = 10
"""Runs with fewer samples are not smoothed (warning)."""


@dataclass
class SmoothingResult:
    """Smoothed nominal states (n, 16) and position variances (n, 3), or None (the filter's
    result stands), with the run's diagnostics; for FB and FB-RTS also the compute time
    of every segment in time order (ms; the diagnostics keep only its summary)."""

    x: np.ndarray | None
    pos_var: np.ndarray | None
    diagnostics: dict = field(default_factory=dict)
    segment_latency_ms: np.ndarray | None = None


def segment_bounds(stance: np.ndarray, rate_hz: float, min_stance_s: float, max_segment_s: float) -> np.ndarray:
    """Segment boundaries (sample indices, increasing, first 0 and last n−1): the
    midpoints of the stance runs at least ``min_stance_s`` long, long gaps cut evenly."""
    n = stance.shape[0]
    starts, ends = detectors.stance_events(stance)
    keep = (ends - starts) >= max(1, int(round(min_stance_s * rate_hz)))
    mids = (starts[keep] + ends[keep] - 1) // 2
    bounds = np.unique(np.concatenate([[0], mids, [n - 1]])).astype(np.int64)
    max_len = max(2, int(round(max_segment_s * rate_hz)))
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


class _Buffers:
    """Block-local buffers (one set per pass)."""

    def __init__(self, size: int) -> None:
        self.Ppost = np.zeros((size, 15, 15))
        self.Pprior = np.zeros((size, 15, 15))
        self.Phi = np.zeros((size, 15, 15))
        self.dx = np.zeros((size, 15))
        self.dxs = np.zeros((size, 15))
        self.Ps = np.zeros((size, 15, 15))
        self.x = np.zeros((size, 16))
        self.xs = np.zeros((size, 16))
        self.var = np.zeros((size, 4))


def _latency(ms: list[float]) -> dict:
    if not ms:
        return {}
    a = np.asarray(ms)
    return {"segments": int(a.size), "mean_ms": float(a.mean()), "p95_ms": float(np.percentile(a, 95)),
            "max_ms": float(a.max())}


def smooth_record(rec: dict, cfg: SmootherConfig) -> SmoothingResult:
    """Smooth one recorded foot-INS run (see ``FootIns.smoothing_record``) per ``cfg``."""
    diag: dict = {"kind": cfg.kind, "warnings": 0, "warning_messages": []}

    def warn(msg: str) -> SmoothingResult:
        diag["warnings"] += 1
        diag["warning_messages"].append(msg)
        log.warning("smoothing: %s; keeping the filter's result", msg)
        return SmoothingResult(None, None, diag)

    hist_x = np.ascontiguousarray(rec["hist_x"], dtype=np.float64)
    n = hist_x.shape[0]
    if n < MIN_SAMPLES:
        return warn(f"run too short to smooth ({n} samples, need {MIN_SAMPLES})")
    stance = np.ascontiguousarray(rec["stance"], dtype=np.bool_)
    if not stance[1:].any():
        return warn("no stance found")
    bounds = segment_bounds(stance, rec["rate_hz"], cfg.min_stance_s, cfg.max_segment_s)
    if bounds.size < 2:
        return warn("no segment to smooth")
    diag["segments"] = int(bounds.size - 1)
    t = np.ascontiguousarray(rec["t"], dtype=np.float64)
    acc = np.ascontiguousarray(rec["acc"], dtype=np.float64)
    gyro = np.ascontiguousarray(rec["gyro"], dtype=np.float64)
    params = np.ascontiguousarray(rec["params"], dtype=np.float64)
    ov_idx, ov_P = rec["override_idx"], rec["override_P"]
    size = int(np.max(np.diff(bounds))) + 1
    fw = _Buffers(size)
    out_x = hist_x.copy()
    out_var = np.zeros((n, 4))
    empty = np.zeros(15)
    gain_failures = 0
    fusion_failures = 0
    P_last = None
    latencies = None
    if cfg.kind == "rts":
        # checkpoints: the filter's posterior covariance at every boundary
        ckpt = np.empty((bounds.size, 15, 15))
        ckpt[0] = rec["P0"]
        for k in range(bounds.size - 1):
            ckpt[k + 1] = forward_block(hist_x, t, acc, gyro, stance, params, int(bounds[k]), int(bounds[k + 1]),
                                        ckpt[k], ov_idx, ov_P, False, fw.Ppost, fw.Pprior, fw.Phi, fw.dx)
        P_last = ckpt[-1]
        carry_dx, carry_P = empty.copy(), None
        for k in range(bounds.size - 2, -1, -1):
            a, b = int(bounds[k]), int(bounds[k + 1])
            L = b - a
            forward_block(hist_x, t, acc, gyro, stance, params, a, b, ckpt[k], ov_idx, ov_P, True,
                          fw.Ppost, fw.Pprior, fw.Phi, fw.dx)
            if cfg.span == "segment" or carry_P is None:
                end_dx, end_P = empty, fw.Ppost[L].copy()
            else:
                end_dx, end_P = carry_dx, carry_P
            gain_failures += rts_block(fw.Ppost, fw.Pprior, fw.Phi, fw.dx, L, end_dx, end_P, fw.dxs, fw.Ps)
            carry_dx, carry_P = fw.dxs[0].copy(), fw.Ps[0].copy()
            apply_smoothed(hist_x, a, L, fw.dxs, fw.Ps, out_x, out_var, a)
        diag["span"] = cfg.span
    else:
        use_rts = cfg.kind == "fb-rts"
        bw = _Buffers(size)
        counters = np.zeros(1)
        latencies = []
        P_a = np.ascontiguousarray(rec["P0"], dtype=np.float64)  # the original filter's, at a
        P_b = np.empty((15, 15))
        x_seed = hist_x[0].copy()  # the forward pass's seed: the filter's initial state, then
        P_seed = P_a.copy()        # the previous segment's fused end state
        P_fused = np.empty((15, 15))
        for k in range(bounds.size - 1):
            a, b = int(bounds[k]), int(bounds[k + 1])
            L = b - a
            t0 = time.perf_counter_ns()
            forward_rerun_block(x_seed, P_seed, hist_x, t, acc, gyro, stance, params, a, b, P_a, ov_idx, ov_P,
                                fw.x, fw.Ppost, fw.Pprior, fw.Phi, fw.dx, P_b)
            backward_block(fw.x[L], fw.Ppost[L], t, acc, gyro, stance, params, a, b, bw.x, bw.Ppost, bw.Pprior,
                           bw.Phi, bw.dx, counters)
            if use_rts:
                gain_failures += rts_block(fw.Ppost, fw.Pprior, fw.Phi, fw.dx, L, empty, fw.Ppost[L], fw.dxs, fw.Ps)
                gain_failures += rts_block(bw.Ppost, bw.Pprior, bw.Phi, bw.dx, L, empty, bw.Ppost[L], bw.dxs, bw.Ps)
                apply_smoothed(fw.x, 0, L, fw.dxs, fw.Ps, fw.xs, fw.var, 0)
                apply_smoothed(bw.x, 0, L, bw.dxs, bw.Ps, bw.xs, bw.var, 0)
                fusion_failures += fuse_block(fw.xs, fw.Ps, bw.xs, bw.Ps, L, a, out_x, out_var, P_fused)
            else:
                fusion_failures += fuse_block(fw.x, fw.Ppost, bw.x, bw.Ppost, L, a, out_x, out_var, P_fused)
            latencies.append((time.perf_counter_ns() - t0) / 1e6)
            x_seed = out_x[b].copy()
            P_seed = P_fused.copy()
            P_a = P_b.copy()
        P_last = P_a
        diag["backward_zupts"] = int(counters[0])
        diag["latency_ms"] = _latency(latencies)
    diag["rts_gain_failures"] = int(gain_failures)
    diag["fusion_failures"] = int(fusion_failures)
    P_end = rec["P_end"]
    diag["covariance_rebuild_rel_error"] = float(np.max(np.abs(P_last - P_end)) / max(np.max(np.abs(P_end)), 1e-300))
    if not np.all(np.isfinite(out_x)) or not np.all(np.isfinite(out_var)):
        return warn("smoother produced non-finite states")
    return SmoothingResult(out_x, out_var, diag, None if latencies is None else np.asarray(latencies))


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
