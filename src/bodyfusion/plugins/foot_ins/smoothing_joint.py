"""A foot INS as a member of a joint RTS (:mod:`bodyfusion.core.joint_smoothing`): the feet the
fuser corrected together, with their cross-covariances tracked (``fuser.cross_covariance``), are
smoothed as one stacked state, so that each correction the fuser derived from both feet is
information for both smoothed tracks, not a known input of each.

The core's sweep moves one member at a time between two joint corrections; this module does a
member's part of it with the foot's own whole-run record (the filter's,
:meth:`~bodyfusion.plugins.foot_ins.smoothing_record.ForwardRecord.sweep_arrays`):

* :func:`cross_forward` carries a cross-covariance Z (15, m) between this foot and the others
  forward through the foot's closed-loop steps, Z ← A_i Z with A_i = G (I − K H) Φ at a stance
  sample (:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.zupt_gain`), Φ at a swing sample,
  P⁺ G⁻ᵀ (P⁻)⁻¹ Φ at a general update: the filter's cross-covariance at each sample, from the
  one the fuser left after a joint correction;
* :meth:`JointRtsMember.sweep` sweeps the foot back over the stretch with
  :func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.mbf_sweep` and those cross-covariances
  (:class:`~bodyfusion.plugins.foot_ins.records.CrossTerms`), in chunks of at most
  :data:`CHUNK_SAMPLES` (the cross-covariance at each chunk start kept from one forward pass,
  each chunk's carried again as it is swept), so that a long stretch holds one chunk.
"""

from __future__ import annotations

import numba
import numpy as np

from bodyfusion.base.errors import FusionError
from bodyfusion.core.layout import SmootherConfig
from bodyfusion.nav.attitude import quat_to_dcm_into
from bodyfusion.nav.error_state import bias_decay, process_noise_diag, transition_left
from bodyfusion.nav.zupt import ZUPT_COLUMNS
from bodyfusion.plugins.foot_ins.records import CrossTerms, FilterRun, SmoothedOutput, SweepRecord
from bodyfusion.plugins.foot_ins.smoothing_mbf import mbf_sweep, zupt_gain
from bodyfusion.plugins.foot_ins.smoothing_record import RunRecord
from bodyfusion.plugins.foot_ins.smoothing_rts import chol_solve

CHUNK_SAMPLES = 2048
"""Longest stretch (samples) a member sweeps with its cross-covariances held for every sample
(15 × m floats each)."""


@numba.njit(cache=True, nogil=True)
def cross_forward(run: FilterRun, general: np.ndarray, record: SweepRecord, i0: int, L: int, Z: np.ndarray,
                  Zs: np.ndarray) -> bool:
    """Z (15, m) in place from the cross-covariance between this foot at sample i0 (after
    everything done there) and the others, to the one at i0 + L before the kept corrections
    there (the others standing still): Z ← A_i Z for i0 < i ≤ i0 + L, A_i the step's
    closed-loop map (module docstring) rebuilt from the ``record`` of samples i0 … i0 + L (as
    :func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.mbf_sweep` takes it). Where ``Zs`` has
    L + 1 rows, Zs[j] receives Z at i0 + j. False when a general update's prior cannot be
    factorised (Z is left as it was there)."""
    (t, _, _, stance), params, replay, _ = run
    hist_x = replay.recorded_x
    Pu, f_ns, st_v, st_P, gen_P, _, gen_a, gen_kept, kept_P = record
    m = Z.shape[1]
    store = Zs.shape[0] > 0
    q_diag = process_noise_diag(params)
    C_nb = np.empty((3, 3))
    Hc, K = np.empty((3, 4)), np.empty((15, 3))
    S3, Si3 = np.empty((3, 3)), np.empty((3, 3))
    P = np.empty((15, 15))
    Y = np.empty((15, m))
    Lw = np.empty((15, 16))
    ok = True
    ns = ng = nk = 0
    if store:
        Zs[0] = Z
    for j in range(1, L + 1):
        i = i0 + j
        dt = t[i] - t[i - 1]
        quat_to_dcm_into(hist_x[i - 1, 6:10], C_nb)
        da, dg = bias_decay(q_diag, dt)
        transition_left(Z, C_nb, f_ns[j], dt, da, dg, np.bool_(False))
        if general[i]:  # Z ← P⁺ G⁻ᵀ (P⁻)⁻¹ Z
            if gen_kept[ng]:
                P[:, :] = kept_P[nk]
                nk += 1
            else:
                q = 0
                for r in range(15):
                    for c in range(r, 15):
                        P[r, c] = Pu[j, q]
                        P[c, r] = Pu[j, q]
                        q += 1
            if chol_solve(gen_P[ng], Z, Y, Lw):
                a0, a1 = gen_a[ng, 0], gen_a[ng, 1]
                for c in range(m):
                    Y[8, c] -= a0 * Y[3, c] + a1 * Y[4, c]
                for r in range(15):
                    for c in range(m):
                        s = 0.0
                        for k in range(15):
                            s += P[r, k] * Y[k, c]
                        Z[r, c] = s
            else:
                ok = False
            ng += 1
            if stance[i]:
                ns += 1
        elif stance[i]:  # Z ← G (I − K H) Z
            zupt_gain(st_v[ns], st_P[ns], params, Hc, K, S3, Si3)
            for c in range(m):
                u0 = u1 = u2 = 0.0
                for n in range(4):
                    z = Z[ZUPT_COLUMNS[n], c]
                    u0 += Hc[0, n] * z
                    u1 += Hc[1, n] * z
                    u2 += Hc[2, n] * z
                for r in range(15):
                    Z[r, c] -= K[r, 0] * u0 + K[r, 1] * u1 + K[r, 2] * u2
                Z[3, c] += st_v[ns, 3] * Z[8, c]
                Z[4, c] += st_v[ns, 4] * Z[8, c]
            ns += 1
        if store:
            Zs[j] = Z
    return ok


class JointRtsMember:
    """A foot INS's part in the joint RTS (:class:`bodyfusion.core.joint_smoothing.JointMember`):
    its whole-run record (the filter's own: the joint sweep replays nothing), the smoothed
    states it writes, and its sample times (s) to find where each joint correction was made.
    Raises :class:`~bodyfusion.base.errors.FusionError` when the filter kept no whole-run
    record (a run too long for it, an estimator with the ZARU)."""

    size = 15

    def __init__(self, system, cfg: SmootherConfig) -> None:
        self.system = system
        self.cfg = cfg
        r = self.r = RunRecord(system.smoothing_record())
        self.general = r.general_updates()
        self.record = r.forward_record.sweep_arrays(r, self.general)
        if self.record is None:
            raise FusionError("its filter kept no whole-run record to smooth jointly (a run longer than it "
                              "records, or the ZARU)")
        self.times = np.asarray(system.sample_times()[:r.n], dtype=float)
        self._counts = np.column_stack([np.r_[0, np.cumsum(f[1:])] for f in (r.stance, self.general)]
                                       + [np.searchsorted(r.kept_idx, np.arange(r.n), side="right")])
        self.out = SmoothedOutput(r.hist_x.copy(), np.zeros((r.n, 4)))
        self.gain_failures = 0
        self.cross_failures = 0

    @property
    def samples(self) -> int:
        return self.r.n

    def sample_at(self, t: float) -> int:
        """The sample the filter stood at when the fuser corrected it at time t (s): the last at or before t."""
        return int(np.searchsorted(self.times, t, side="right")) - 1

    def _slice(self, a: int, b: int) -> SweepRecord:
        """The record of samples a … b."""
        (s0, g0, k0), (s1, g1, k1) = self._counts[a], self._counts[b]
        Pu, f_ns, st_v, st_P, gen_P, gen_dx, gen_a, gen_kept, kept_P = self.record
        return SweepRecord(Pu[a:b + 1], f_ns[a:b + 1], st_v[s0:s1], st_P[s0:s1], gen_P[g0:g1], gen_dx[g0:g1],
                           gen_a[g0:g1], gen_kept[g0:g1], kept_P[k0:k1])

    def _forward(self, a: int, b: int, Z: np.ndarray, Zs: np.ndarray) -> None:
        if not cross_forward(self.r.run, self.general, self._slice(a, b), a, b - a, Z, Zs):
            self.cross_failures += 1

    def transfer(self, a: int, b: int) -> np.ndarray:
        """The closed-loop transition (15, 15) from sample a to b (before the kept corrections at b)."""
        U = np.eye(15)
        self._forward(a, b, U, np.empty((0, 15, 15)))
        return U

    def sweep(self, a: int, b: int, write_last: bool, W: np.ndarray, lam: np.ndarray, Lam: np.ndarray,
              X: np.ndarray, lam_o: np.ndarray, Lam_oo: np.ndarray) -> np.ndarray:
        """Sweep back from sample b (before the kept corrections there) to a (after everything
        done there), the others standing still: (lam, Lam, X) in place; W (15, m) is the
        cross-covariance with the others at a. Writes the smoothed states of a … b − 1, and of b
        with ``write_last``. Returns the cross-covariance at b (from W carried forward)."""
        m = W.shape[1]
        starts = list(range(a, b, CHUNK_SAMPLES)) or [a]
        checkpoints = [W.copy()]
        if len(starts) > 1:  # the cross-covariance at each chunk's start
            Z = W.copy()
            for c0 in starts[:-1]:
                self._forward(c0, c0 + CHUNK_SAMPLES, Z, np.empty((0, 15, m)))
                checkpoints.append(Z.copy())
        Z_end = None
        for c0, Z0 in zip(reversed(starts), reversed(checkpoints)):
            c1 = min(c0 + CHUNK_SAMPLES, b)
            Zs = np.empty((c1 - c0 + 1, 15, m))
            self._forward(c0, c1, Z0, Zs)
            Z_end = Zs[-1].copy() if Z_end is None else Z_end
            self.gain_failures += mbf_sweep(self.r.run, self.general, c0, c1 - c0, self._slice(c0, c1), lam, Lam,
                                            self.out, write_last and c1 == b, CrossTerms(X, Zs, lam_o, Lam_oo))
        return Z_end

    def finish(self, diagnostics: dict) -> dict:
        """Hand the smoothed track to the system, with the joint sweep's ``diagnostics`` (its
        ``smoothing_diagnostics``, returned)."""
        x, var = self.out
        diag = {"kind": self.cfg.kind, "span": "whole", "warnings": 0, "warning_messages": [],
                "rts_gain_failures": self.gain_failures, "cross_failures": self.cross_failures,
                "joint": diagnostics}
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(var))):
            diag["warnings"] = 1
            diag["warning_messages"].append("joint smoother produced non-finite states")
            self.system.set_smoothed(None, None, diag)
        else:
            self.system.set_smoothed(x, var, diag)
        return diag
