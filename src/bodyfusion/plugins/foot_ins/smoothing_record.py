"""What the foot INS's smoothers work from: the filter's run as a record
(:class:`RunRecord`, from ``FootIns.smoothing_record``), the block buffers a replay fills
(:class:`BlockBuffers`), and what the filter records for the whole-run RTS as it runs, or the
covariance checkpoints it keeps instead (:class:`ForwardRecord`)."""

from __future__ import annotations

import numpy as np

from bodyfusion.core.layout import SmootherConfig
from bodyfusion.nav.error_state import FilterParams
from bodyfusion.plugins.foot_ins.kernels import C_STANCE_RECORDS, pack_covariance
from bodyfusion.plugins.foot_ins.records import (PACKED_SIZE, FilterReplay, FilterRun, FilterState, ImuSamples,
                                                 PassBuffers, RtsRecord, SmoothedPass, SweepRecord, no_record)
from bodyfusion.plugins.foot_ins.smoothing_replay import boxminus, filter_pass

STORE_BYTES = 64 * 2**20
"""The largest record of the whole run the filter writes as it runs for the whole-run RTS
(bytes): about 1 kB per sample and 0.5 kB more per stance sample
(:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.record_pass`): a run of up to some
50 000 samples (8 min at 100 Hz) is recorded so (:class:`ForwardRecord`); a longer one keeps
covariance checkpoints instead (:data:`CHECKPOINT_SAMPLES`)."""

CHECKPOINT_SAMPLES = 256
"""Fewest samples between two covariance checkpoints the filter keeps as it runs when its
whole-run RTS record does not fit :data:`STORE_BYTES` (:class:`ForwardRecord`; 120 floats
each): the sweep replays each stretch between two once, a block whose record (about 1.3 kB
a sample, a few hundred kB) stays in the processor's cache."""

_UPPER = np.triu_indices(15)
"""The packed order of a symmetric 15×15 matrix (upper triangle by rows, as
:func:`~bodyfusion.plugins.foot_ins.kernels.record_posterior` writes it)."""


def record_bytes(samples: int, stance: int, general: int = 0) -> int:
    """Bytes the whole-run RTS's record of ``samples`` samples, ``stance`` of them stance
    samples and ``general`` with a general update, takes
    (:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.record_pass`): 8 × (123 per sample, 65
    per stance sample, 242 per general update)."""
    return 8 * (123 * samples + 65 * stance + 242 * general)


NO_PHI = np.empty((0, 0))
"""The transition a replay does not accumulate."""


class BlockBuffers:
    """Block buffers of ``passes`` passes, each array's first index the pass (see
    :mod:`~bodyfusion.plugins.foot_ins.smoothing_replay`); FB holds the forward pass at 0 and
    the backward one at 1."""

    def __init__(self, size: int, passes: int = 1) -> None:
        self.xs = np.zeros((passes, size, 16))
        self.xp = np.zeros((passes, size, 16))
        self.Ppost = np.zeros((passes, size, 15, 15))
        self.Pprior = np.zeros((passes, size, 15, 15))
        self.Phi = np.zeros((passes, size, 15, 15))
        self.dx = np.zeros((passes, size, 15))
        self.jump = np.zeros((passes, size, 3))
        self.yaw_reset = np.zeros((passes, size, 2))
        self.dxs = np.zeros((passes, size, 15))
        self.Ps = np.zeros((passes, size, 15, 15))
        self.smoothed = np.zeros((passes, size, 16))

    def buffers(self, p: int | None = None) -> PassBuffers:
        """The replay buffers of pass p, or of every pass (a leading pass axis)."""
        arrays = (self.xs, self.xp, self.Ppost, self.Pprior, self.Phi, self.dx, self.jump, self.yaw_reset)
        return PassBuffers(*(a if p is None else a[p] for a in arrays))

    def smoothing(self, fused_P: np.ndarray) -> SmoothedPass:
        """The RTS and fusion buffers of every pass, and the fused position block ``fused_P``."""
        return SmoothedPass(self.dxs, self.Ps, self.smoothed, fused_P)


class RunRecord:
    """The filter's record as the compiled passes take it."""

    def __init__(self, rec: dict) -> None:
        f64 = np.float64
        self.hist_x = np.ascontiguousarray(rec["hist_x"], dtype=f64)
        self.t = np.ascontiguousarray(rec["t"], dtype=f64)
        self.acc = np.ascontiguousarray(rec["acc"], dtype=f64)
        self.gyro = np.ascontiguousarray(rec["gyro"], dtype=f64)
        self.stance = np.ascontiguousarray(rec["stance"], dtype=np.bool_)
        self.params = rec["params"]
        self.P0 = np.ascontiguousarray(rec["P0"], dtype=f64)
        self.P_end = np.asarray(rec["P_end"], dtype=f64)
        self.ov_idx = np.ascontiguousarray(rec["override_idx"], dtype=np.int64)
        self.ov_P = np.ascontiguousarray(rec["override_P"], dtype=f64)
        self.kept_idx = np.ascontiguousarray(rec.get("kept_idx", np.empty(0)), dtype=np.int64)
        self.kept_x = np.ascontiguousarray(rec.get("kept_x", np.empty((0, 16))), dtype=f64)
        self.gap_idx = np.ascontiguousarray(rec.get("gap_idx", np.empty(0)), dtype=np.int64)
        self.gap_dP = np.ascontiguousarray(rec.get("gap_dP", np.empty((0, 15, 15))), dtype=f64)
        self.rate_hz = float(rec["rate_hz"])
        self.run = FilterRun(ImuSamples(self.t, self.acc, self.gyro, self.stance), self.params,
                             FilterReplay(self.hist_x, self.ov_idx, self.ov_P, self.kept_idx, self.kept_x, self.gap_idx,
                                          self.gap_dP), self.P0)
        """The run as the compiled smoothers take it."""
        self.forward_record: ForwardRecord = rec.get("forward_record") or ForwardRecord()
        self.n = self.hist_x.shape[0]
        self.state_error = 0.0
        """Largest |replayed − recorded| nominal state element over the stored forward passes."""

    def general_updates(self) -> np.ndarray:
        """(n,) bool: the samples whose update is more than the ekf's ZUPT (a correction outside
        the filter's loop, or the ZARU after the ZUPT), which the whole-run smoother steps back
        through in general form (:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.mbf_sweep`)."""
        out = self.stance.copy() if self.params.zaru_sigma > 0 else np.zeros(self.n, dtype=np.bool_)
        out[self.ov_idx] = True
        return out

    def start(self, a: int, P_a: np.ndarray) -> FilterState:
        """The filter at sample a as a replay starts from it: its recorded state, the covariance
        P_a and its mechanisation memory there."""
        return FilterState(self.hist_x[a], P_a, self.memory([a])[0], NO_PHI)

    def memory(self, a: np.ndarray) -> np.ndarray:
        """(K, 6): the filter's mechanisation memory before the step to each a + 1 (sample
        indices a (K,)): the bias-corrected increments of sample a with the biases the filter
        held then (after sample a − 1)."""
        a = np.asarray(a, dtype=np.int64)
        m = np.zeros((a.size, 6))
        later = a >= 1
        b = a[later]
        dt = (self.t[b] - self.t[b - 1])[:, None]
        m[later, 0:3] = (self.gyro[b] - self.hist_x[b - 1, 13:16]) * dt
        m[later, 3:6] = (self.acc[b] - self.hist_x[b - 1, 10:13]) * dt
        return m

    def forward(self, a: int, b: int, P_a: np.ndarray, store: bool, buf: BlockBuffers) -> np.ndarray:
        """The filter over a < i ≤ b from its recorded state at a and the covariance P_a, with
        ``store`` into the first pass of ``buf`` (and :attr:`state_error` updated); returns the
        covariance at b."""
        P_b = filter_pass(self.start(a, P_a), self.run.samples, self.params, a, b, self.run.replay, store,
                          buf.buffers(0))
        if store:
            self.state_error = max(self.state_error,
                                   float(np.max(np.abs(buf.xs[0, :b - a + 1] - self.hist_x[a:b + 1]))))
        return P_b


class ForwardRecord:
    """The whole-run RTS's record written by the ekf as it runs
    (:func:`~bodyfusion.plugins.foot_ins.kernels.run_foot_ins`): per sample the packed posterior
    covariance ``Pu`` and the specific force ``f_ns``, per stance sample ``st_v`` and ``st_P``,
    and the nominal state ``x_prior`` and covariance ``P_prior`` before the kernel's last step.
    A system holds one and reuses its arrays across restarts; inactive (no arrays) unless
    :meth:`plan` asks for it.

    A correction made outside the compiled loop (fuser, position fix) comes after the kernel's
    last step: :meth:`capture` keeps what that step left (prior state and covariance,
    posterior covariance). :meth:`sweep_arrays` then completes the record as
    :func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.record_pass` writes it from the replay:
    the same numbers, as the replay reproduces the filter.

    A whole-run RTS whose record does not fit keeps checkpoints instead (``checkpointing``):
    :meth:`capture` packs the covariance the kernel left, at least :data:`CHECKPOINT_SAMPLES`
    after the last one kept, and the sweep replays each stretch between two once
    (:meth:`checkpoints`)."""

    def __init__(self) -> None:
        self.active = False
        self.checkpointing = False
        self.captured: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.kept = 0

    def plan(self, cfg: SmootherConfig, filter_kind: str, params: FilterParams, stance: np.ndarray) -> bool:
        """Active for the RTS (``kind: rts``, either span, or ``fixed-lag``) of an ``ekf`` without the ZARU (whose
        every stance update the sweep takes in general form) whose record of the run with these
        ``stance`` flags fits :data:`STORE_BYTES`; checkpointing for any other whole-run RTS.
        True when either changed."""
        samples, n_stance = stance.size, int(np.count_nonzero(stance[1:]))
        whole = cfg.kind == "rts" and not cfg.segmented
        active = (cfg.rts_sweep and filter_kind == "ekf" and params.zaru_sigma == 0.0
                  and record_bytes(samples, n_stance) <= STORE_BYTES)
        checkpointing = whole and not active
        if (active, checkpointing) == (self.active, self.checkpointing):
            return False
        self.active, self.checkpointing = active, checkpointing
        if active:
            self.Pu = np.empty((samples, PACKED_SIZE))
            self.f_ns = np.empty((samples, 3))
            self.st_v = np.empty((n_stance, 6))
            self.st_P = np.empty((n_stance, 15, 4))
            self.x_prior = np.empty(16)
            self.P_prior = np.empty((15, 15))
        if checkpointing:
            self.ckpt_idx = np.empty(samples // CHECKPOINT_SAMPLES + 1, dtype=np.int64)
            self.ckpt_P = np.empty((self.ckpt_idx.size, PACKED_SIZE))
        return True

    def restart(self, P0: np.ndarray, counters: np.ndarray) -> RtsRecord:
        """A new run from the covariance P0 at sample 0, the kernel counting into ``counters``;
        returns the record :func:`~bodyfusion.plugins.foot_ins.kernels.run_foot_ins` fills."""
        self.captured = {}
        self.kept = 0
        if not self.active:
            return no_record()
        self.Pu[0] = P0[_UPPER]
        self.f_ns[0] = 0.0
        self.counters = counters
        return RtsRecord(self.Pu, self.f_ns, self.st_v, self.st_P, self.x_prior, self.P_prior)

    def capture(self, i: int, P: np.ndarray) -> None:
        """After the kernel's last step, to sample i, whose posterior covariance is P (15, 15):
        keep the step's prior and P, for a correction outside the loop made there; or,
        checkpointing, P packed when it is exactly symmetric and i at least
        :data:`CHECKPOINT_SAMPLES` after the last checkpoint (sample 0 the first)."""
        if self.active:
            self.captured[i] = (self.x_prior.copy(), self.P_prior.copy(), P[:15, :15].copy())
        elif self.checkpointing and i - (self.ckpt_idx[self.kept - 1] if self.kept else 0) >= CHECKPOINT_SAMPLES:
            self.ckpt_idx[self.kept] = i
            if pack_covariance(P, self.ckpt_P[self.kept]):
                self.kept += 1

    def checkpoints(self, r: RunRecord) -> tuple[np.ndarray, np.ndarray]:
        """The block starts of the record ``r``'s whole-run RTS: sample 0 and the checkpoints
        before its last sample (K,), and the filter's covariance (K, 15, 15) at each: the
        initial one, a checkpoint's, or the one the last correction made there left."""
        if not self.checkpointing:
            return np.zeros(1, dtype=np.int64), r.P0[None].copy()
        idx = self.ckpt_idx[:self.kept]
        idx = idx[idx < r.n - 1]
        P = np.empty((idx.size + 1, 15, 15))
        P[0] = r.P0
        packed = self.ckpt_P[:idx.size]
        P[1:, _UPPER[0], _UPPER[1]] = packed
        P[1:, _UPPER[1], _UPPER[0]] = packed
        last = np.searchsorted(r.ov_idx, idx, side="right") - 1
        corrected = last >= 0
        corrected[corrected] = r.ov_idx[last[corrected]] == idx[corrected]
        P[1:][corrected] = r.ov_P[last[corrected]]
        return np.concatenate([[0], idx]), P

    def sweep_arrays(self, r: RunRecord, general: np.ndarray) -> SweepRecord | None:
        """The record of the whole run as :func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.mbf_sweep`
        takes it (``Pu`` … ``kept_P``; ``Pu`` at each corrected sample set to the covariance
        the corrections left), or None when it cannot serve (a stance sample not recorded, a
        correction at sample 0 or one without its capture): the replay does then."""
        n = r.n
        stance = int(np.count_nonzero(r.stance[1:]))
        gen = np.flatnonzero(general)
        if (not self.active or self.Pu.shape[0] < n or int(self.counters[C_STANCE_RECORDS]) != stance
                or (gen.size and gen[0] == 0) or any(int(i) not in self.captured for i in gen)):
            return None
        ordinal = np.cumsum(r.stance) - 1 - r.stance[0]  # the stance entry of each stance sample
        kept = np.zeros(n, dtype=np.bool_)
        kept[r.kept_idx] = True
        gen_P, gen_dx = np.empty((gen.size, 15, 15)), np.empty((gen.size, 15))
        gen_a, kept_P = np.zeros((gen.size, 2)), np.empty((r.kept_idx.size, 15, 15))
        last = np.searchsorted(r.ov_idx, gen, side="right") - 1
        for g, i in enumerate(gen):
            x_prior, P_prior, P_post = self.captured[int(i)]
            gen_P[g] = P_prior
            if r.stance[i]:
                gen_a[g] = self.st_v[ordinal[i], 3:5]
            k = int(np.searchsorted(r.kept_idx, i))
            boxminus(r.kept_x[k] if kept[i] else r.hist_x[i], x_prior, gen_dx[g])
            if kept[i]:
                kept_P[k] = P_post
            self.Pu[i] = r.ov_P[last[g]][_UPPER]
        return SweepRecord(self.Pu[:n], self.f_ns[:n], self.st_v[:stance], self.st_P[:stance], gen_P, gen_dx, gen_a,
                           kept[gen], kept_P)
