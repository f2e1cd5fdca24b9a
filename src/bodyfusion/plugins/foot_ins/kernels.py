"""Compiled per-sample loop of the foot-mounted INS: strapdown, covariance propagation, ZUPT/ZARU.

The ``ekf`` (:func:`run_foot_ins`) and the ``ckf`` (:func:`run_foot_ins_coloured`) share the
per-sample steps; the ckf replaces the ZUPT at every stance sample whose previous sample was
also updated by the coloured-noise update of :mod:`bodyfusion.plugins.foot_ins.coloured`. The
first stance sample of a stance phase has no previous measurement to difference with and
takes the ordinary ZUPT, with the stationary variance of the AR(1) noise
v_k = α v_{k−1} + ξ_k, R = σ_ξ² / (1 − α²) (:func:`stationary_zupt_params`).

One sample of the ekf is :func:`ekf_step`, the only place its per-sample recursion is written:
the filter (:func:`run_foot_ins`) and the smoothers' passes
(:mod:`bodyfusion.plugins.foot_ins.smoothing_replay`: the covariance rebuild, the backward
navigation) all call it, so a change to the propagation or to the zero-velocity update
changes them all.

For the whole-run RTS the ekf can record, as it runs, what the backward sweep of
:mod:`bodyfusion.plugins.foot_ins.smoothing_mbf` needs (:func:`record_posterior`,
:func:`record_stance`; the arrays of :func:`~bodyfusion.plugins.foot_ins.records.no_record` when it records nothing): the sweep then
needs no replay of the filter.

Every stance update is chi-square gated with bounded influence (``params.zupt_gate``,
0: off; :mod:`bodyfusion.nav.zupt`): a stance sample whose NIS exceeds the gate is counted and
de-weighted, and gets no ZARU (the foot is not at rest there).
"""

from __future__ import annotations

import numba
import numpy as np

from bodyfusion.nav.error_state import (FilterParams, bias_decay, closed_loop_reset, decay_biases,
                                       process_noise_diag, propagate_covariance, transition_left)
from bodyfusion.nav.strapdown import mechanise
from bodyfusion.nav.zupt import ZUPT_COLUMNS, stance_update, stance_velocity_sigma, zero_angular_rate_update
from bodyfusion.plugins.foot_ins.coloured import coloured_zero_velocity_update
from bodyfusion.plugins.foot_ins.records import FilterHistory, FilterState, ImuSamples, RtsRecord, StepScratch

# Layout of the ``counters`` vector: updates, NIS sum (before gating), the
# gated (de-weighted) stance samples, the coloured updates, the ckf's stance updates
# recorded by this call, and the stance samples recorded for the whole-run RTS.
C_ZUPTS, C_ZARUS, C_NIS_SUM, C_COLOURED, C_GATED, C_CALL_RECORDS, C_STANCE_RECORDS = range(7)
COUNTERS_SIZE = 7


@numba.njit(cache=True)
def stationary_zupt_params(params: FilterParams, alpha: float) -> FilterParams:
    """``params`` with the ZUPT σ of the ordinary update under AR(1) noise of colour factor α:
    the stationary σ_ξ / √(1 − α²) of v_k = α v_{k−1} + ξ_k (σ_ξ = ``params.zupt_sigma``)."""
    return FilterParams(params.acc_noise_density, params.gyro_noise_density, params.acc_bias_walk,
                        params.gyro_bias_walk, params.zupt_sigma / np.sqrt(1.0 - alpha * alpha), params.zaru_sigma,
                        params.gravity, params.earth_rate, params.zupt_gate, params.acc_bias_decay,
                        params.gyro_bias_decay, params.zupt_pivot)


@numba.njit(inline="always")
def _propagate_sample(state: FilterState, imu: ImuSamples, i: int, params: FilterParams, scratch: StepScratch) -> None:
    """Mechanise sample i (from t[i-1] to t[i]), decay the bias estimates and propagate P
    (and Φ when tracked); C_nb (3, 3) of the step is left in ``scratch.C``, f_n (3,) in ``scratch.f_n``."""
    x, P, mech_memory, phi = state
    t, acc_b, gyro_b, _ = imu
    q_diag, f_n, C, _, _ = scratch
    dt = t[i] - t[i - 1]
    mechanise(x, acc_b[i], gyro_b[i], dt, params.gravity, params.earth_rate, f_n, mech_memory, C)
    decay_biases(x, q_diag, dt)
    if phi.shape[0] > 0:
        da, dg = bias_decay(q_diag, dt)
        transition_left(phi, C, f_n, dt, da, dg, np.bool_(False))  # not a literal: one signature
    propagate_covariance(P, C, f_n, dt, q_diag)


@numba.njit(cache=True)
def transition(C: np.ndarray, f_n: np.ndarray, dt: float, q_diag: np.ndarray, Phi: np.ndarray) -> None:
    """Phi (15, 15) = I + A dt, the first-order error-state transition of one step (C_nb and
    f_n as :func:`bodyfusion.nav.strapdown.mechanise` returns them, dt s, the bias decay of the
    process model ``q_diag``, :func:`bodyfusion.nav.error_state.process_noise_diag`): Φ I by
    :func:`bodyfusion.nav.error_state.transition_left`."""
    for r in range(15):
        for c in range(15):
            Phi[r, c] = 1.0 if r == c else 0.0
    da, dg = bias_decay(q_diag, dt)
    transition_left(Phi, C, f_n, dt, da, dg, np.bool_(False))


NO_STANCE = -1.0
"""What :func:`ekf_step` returns at a swing sample (a NIS is never negative)."""


@numba.njit(inline="always")
def ekf_step(state: FilterState, imu: ImuSamples, i: int, params: FilterParams, scratch: StepScratch,
             x_prior: np.ndarray | None, P_prior: np.ndarray | None, Phi: np.ndarray | None) -> float:
    """One sample i of the ekf: mechanise from t[i-1] to t[i], propagate P, and at a stance
    sample the gated ZUPT (and ZARU) of :func:`bodyfusion.nav.zupt.stance_update`.

    The ``state`` is updated in place; of the ``scratch``, ``f_n`` (3,) receives the step's mean
    specific force in the navigation frame (m/s²) and ``C`` (3, 3) its C_nb. For the smoothers, the step also
    writes its prior nominal state ``x_prior`` (16,) and covariance ``P_prior`` (15, 15) when
    ``P_prior`` is not empty, and its transition ``Phi`` (15, 15, :func:`transition`) when
    ``Phi`` is not empty; an empty (0, 0) array skips them, None (the filter) leaves them out of
    the compiled step. Returns the ZUPT's NIS before gating, or :data:`NO_STANCE`."""
    x, P, _, phi = state
    t, _, gyro_b, stance = imu
    q_diag, f_n, C, work, dx = scratch
    _propagate_sample(state, imu, i, params, scratch)
    if P_prior is not None:  # pruned at compile time when None
        if P_prior.shape[0] > 0:
            for r in range(15):
                for c in range(15):
                    P_prior[r, c] = P[r, c]
            for k in range(16):
                x_prior[k] = x[k]
    if Phi is not None:
        if Phi.shape[0] > 0:
            transition(C, f_n, t[i] - t[i - 1], q_diag, Phi)
    if stance[i]:
        return stance_update(x, P, gyro_b[i], params, dx, phi, work)
    return NO_STANCE


@numba.njit(inline="always")
def _count(params: FilterParams, nis: float, counters: np.ndarray) -> None:
    """Count a stance sample's updates: ZUPT, its NIS, gated or ZARU."""
    counters[C_ZUPTS] += 1
    counters[C_NIS_SUM] += nis
    if params.zupt_gate > 0.0 and nis > params.zupt_gate:
        counters[C_GATED] += 1
    elif params.zaru_sigma > 0:
        counters[C_ZARUS] += 1


@numba.njit(inline="always")
def _record_sample(x: np.ndarray, P: np.ndarray, nis: float, i: int, hist_x: np.ndarray, hist_cov: np.ndarray,
                   hist_nis: np.ndarray) -> None:
    hist_nis[i] = nis
    _record_row(x, P, i, hist_x, hist_cov)


@numba.njit(inline="always")
def _record_row(x: np.ndarray, P: np.ndarray, i: int, hist_x: np.ndarray, hist_cov: np.ndarray) -> None:
    """Row i of the history: the state x and P's entries in the
    :data:`~bodyfusion.plugins.foot_ins.records.RECORDED_COVARIANCE` layout."""
    for k in range(16):
        hist_x[i, k] = x[k]
    for k in range(3):
        hist_cov[i, k] = P[k, k]
        hist_cov[i, 4 + k] = P[3 + k, 3 + k]
        hist_cov[i, 7 + k] = P[6 + k, 6 + k]
    hist_cov[i, 3] = P[0, 1]
    hist_cov[i, 10] = P[6, 7]
    hist_cov[i, 11] = P[6, 8]
    hist_cov[i, 12] = P[7, 8]


@numba.njit(inline="always")
def record_posterior(P: np.ndarray, f_n: np.ndarray, j: int, Pu: np.ndarray, f_ns: np.ndarray) -> None:
    """Row j of the whole-run RTS record: ``Pu[j]`` (:data:`~bodyfusion.plugins.foot_ins.records.PACKED_SIZE`,) the posterior
    covariance P (15, 15) packed (upper triangle by rows), ``f_ns[j]`` (3,) the step's mean
    specific force f_n (navigation frame, m/s²; with the state before the step it gives the
    step's transition again, exactly)."""
    _pack(P, Pu[j])
    for k in range(3):
        f_ns[j, k] = f_n[k]


@numba.njit(inline="always")
def _pack(P: np.ndarray, out: np.ndarray) -> None:
    """``out`` (:data:`~bodyfusion.plugins.foot_ins.records.PACKED_SIZE`,) ← the upper triangle of P (15, 15) by rows."""
    q = 0
    for r in range(15):
        for c in range(r, 15):
            out[q] = P[r, c]
            q += 1


@numba.njit(inline="always")
def _pack_symmetric(P: np.ndarray, out: np.ndarray) -> bool:
    """:func:`_pack`; whether P is exactly symmetric (then ``out`` holds all of it; a NaN makes
    it not)."""
    _pack(P, out)
    for r in range(15):
        for c in range(r, 15):
            if P[c, r] != P[r, c]:
                return False
    return True


@numba.njit(cache=True)
def pack_covariance(P: np.ndarray, out: np.ndarray) -> bool:
    """``out`` (:data:`~bodyfusion.plugins.foot_ins.records.PACKED_SIZE`,) ← the upper triangle of P (15, 15) by rows; whether P is
    exactly symmetric (then ``out`` holds all of it; a NaN makes it not)."""
    return _pack_symmetric(P, out)


NO_RESET = (np.empty(0), np.empty((0, 0)))
"""The ``dx``, ``P_new`` of :func:`set_state` for a state already set (no closed-loop reset)."""
NOT_PACKED = np.empty(0)
"""The ``packed`` of :func:`set_state` when the covariance is not kept (no smoother rebuilds it)."""


@numba.njit(cache=True)
def set_state(x: np.ndarray, P: np.ndarray, dx: np.ndarray, P_new: np.ndarray, i: int, hist_x: np.ndarray,
              hist_cov: np.ndarray, packed: np.ndarray) -> bool:
    """A state set outside the compiled loop, at sample i, in one call: the closed-loop reset by
    dx (15,) and P_new (n, n) (:func:`bodyfusion.nav.error_state.closed_loop_reset`; both empty,
    :data:`NO_RESET`: none, x (16,) and P (n, n) already set); row i of ``hist_x`` (N, 16) ← x and
    of ``hist_cov`` (N, 13) ← P's entries (:data:`~bodyfusion.plugins.foot_ins.records.RECORDED_COVARIANCE`)
    (m²); unless ``packed`` is empty (:data:`NOT_PACKED`), ``packed`` (:data:`~bodyfusion.plugins.foot_ins.records.PACKED_SIZE`,) ← the
    upper triangle of P (15, 15) by rows. Returns whether P is exactly symmetric (then ``packed``
    holds all of it; a NaN makes it not); True when nothing is packed."""
    if dx.shape[0] > 0:
        closed_loop_reset(x, P, dx, P_new)
    _record_row(x, P, i, hist_x, hist_cov)
    return packed.shape[0] == 0 or _pack_symmetric(P, packed)


@numba.njit(inline="always")
def record_stance(x: np.ndarray, x_prior: np.ndarray, P_prior: np.ndarray, sigma_v: float, n: int,
                  st_v: np.ndarray, st_P: np.ndarray) -> None:
    """Entry n of the whole-run RTS record of the stance samples, from the nominal state x (16,)
    just after the sample's stance update and x_prior (16,), P_prior (15, 15) before it:
    ``st_v[n]`` (6,) the prior velocity v⁻ (m/s), the east and north velocity rows
    a = (−Δv_N, Δv_E) of the update's heading reset G = I + a e_ψᵀ (Δv = v⁺ − v⁻,
    :func:`bodyfusion.nav.error_state.keep_yaw_unobservable`) and the ZUPT's noise variance
    before the gate, σ_v² (m²/s², :func:`bodyfusion.nav.zupt.stance_velocity_sigma`); ``st_P[n]``
    (15, 4) the prior covariance's columns at :data:`~bodyfusion.nav.zupt.ZUPT_COLUMNS`."""
    for k in range(3):
        st_v[n, k] = x_prior[3 + k]
    st_v[n, 3] = -(x[4] - x_prior[4])
    st_v[n, 4] = x[3] - x_prior[3]
    st_v[n, 5] = sigma_v * sigma_v
    for r in range(15):
        for m in range(4):
            st_P[n, r, m] = P_prior[r, ZUPT_COLUMNS[m]]


@numba.njit(cache=True)
def run_foot_ins(state: FilterState, imu: ImuSamples, i0: int, i1: int, params: FilterParams,
                 history: FilterHistory, record: RtsRecord) -> None:
    """The ``ekf``: process samples i0 ≤ i < i1 (i0 ≥ 1): mechanise from t[i-1] to t[i],
    propagate P, and at stance samples apply the gated ZUPT (and the ZARU when its σ > 0).

    The ``state`` (:class:`~bodyfusion.plugins.foot_ins.records.FilterState`: x, P, the
    mechanisation memory of :func:`bodyfusion.nav.strapdown.mechanise`, the transition Φ
    accumulated for the fuser) is updated in place; of the ``history``, row i of ``hist_x`` and
    ``hist_cov`` (N, 13) receives the state and the covariance entries after sample i
    (:data:`~bodyfusion.plugins.foot_ins.records.RECORDED_COVARIANCE`), and ``hist_nis`` (N,) its
    stance update's NIS before gating (:data:`NO_STANCE` at a swing sample); ``counters``
    accumulates (layout ``C_*``).

    Unless ``record.Pu`` is empty (:func:`~bodyfusion.plugins.foot_ins.records.no_record`), the run records for the whole-run RTS: row i of
    ``Pu`` (N, :data:`~bodyfusion.plugins.foot_ins.records.PACKED_SIZE`) and ``f_ns`` (N, 3) (:func:`record_posterior`) and, at the
    n-th stance sample of the run (n = ``counters[C_STANCE_RECORDS]``), entry n of ``st_v``
    (S, 6) and ``st_P`` (S, 15, 4) (:func:`record_stance`); ``x_prior`` (16,) and ``P_prior``
    (15, 15) are left with the nominal state and covariance before the step to i1 − 1 (the
    sample a correction from outside the loop would be made at)."""
    x, P, _, _ = state
    _, _, gyro_b, stance = imu
    hist_x, hist_cov, hist_nis, counters = history
    Pu, f_ns, st_v, st_P, x_prior, P_prior = record
    scratch = StepScratch(process_noise_diag(params), np.empty(3), np.empty((3, 3)), np.empty((15, 15)), np.empty(15))
    f_n = scratch.f_n
    no_prior = np.empty((0, 0))
    recording = Pu.shape[0] > 0
    for i in range(i0, i1):
        keep = recording and (stance[i] or i == i1 - 1)
        nis = ekf_step(state, imu, i, params, scratch, x_prior, P_prior if keep else no_prior, None)
        if nis != NO_STANCE:
            _count(params, nis, counters)
        if recording:
            if nis != NO_STANCE:
                record_stance(x, x_prior, P_prior, stance_velocity_sigma(params, gyro_b[i], x_prior),
                              int(counters[C_STANCE_RECORDS]), st_v, st_P)
                counters[C_STANCE_RECORDS] += 1
            record_posterior(P, f_n, i, Pu, f_ns)
        _record_sample(x, P, nis, i, hist_x, hist_cov, hist_nis)


@numba.njit(cache=True)
def run_foot_ins_coloured(state: FilterState, imu: ImuSamples, i0: int, i1: int, params: FilterParams, alpha: float,
                          history: FilterHistory, post_idx: np.ndarray, post_P: np.ndarray) -> None:
    """The ``ckf`` with colour factor α: as :func:`run_foot_ins`, with the coloured-noise
    update at every stance sample i ≥ 2 whose previous sample was stance too (a separate
    entry point, so that the ekf does not compile it). The other stance samples, and a
    differenced sample whose coloured NIS exceeds the gate, take the gated ordinary ZUPT with
    the stationary σ (:func:`stationary_zupt_params`). Neither is what the smoothers rebuild
    (the ZUPT with σ_ξ), so the index and posterior covariance of every stance update are
    written, in order, to ``post_idx`` (K,) and ``post_P`` (K, 15, 15), K the stance samples
    of the chunk; ``counters[C_CALL_RECORDS]`` says how many were written."""
    x, P, _, phi = state
    t, _, gyro_b, stance = imu
    hist_x, hist_cov, hist_nis, counters = history
    scratch = StepScratch(process_noise_diag(params), np.empty(3), np.empty((3, 3)), np.empty((15, 15)), np.empty(15))
    q_diag, f_n, C, work, dx = scratch
    ordinary = stationary_zupt_params(params, alpha)
    v_prev = np.empty(3)
    gate = params.zupt_gate
    counters[C_CALL_RECORDS] = 0
    for i in range(i0, i1):
        for k in range(3):
            v_prev[k] = x[3 + k]
        _propagate_sample(state, imu, i, params, scratch)
        nis = NO_STANCE
        if stance[i]:
            coloured = False
            if stance[i - 1] and i >= 2:
                nis = coloured_zero_velocity_update(state, v_prev, scratch, t[i] - t[i - 1], alpha,
                                                    stance_velocity_sigma(params, gyro_b[i], x), gate)
                coloured = gate <= 0.0 or nis <= gate
                if coloured and params.zaru_sigma > 0:
                    zero_angular_rate_update(x, P, gyro_b[i], params.zaru_sigma, dx, phi, work)
            if not coloured:
                nis = stance_update(x, P, gyro_b[i], ordinary, dx, phi, work)
            _count(params, nis, counters)
            if coloured:
                counters[C_COLOURED] += 1
            n_post = int(counters[C_CALL_RECORDS])
            post_idx[n_post] = i
            for r in range(15):
                for c in range(15):
                    post_P[n_post, r, c] = P[r, c]
            counters[C_CALL_RECORDS] += 1
        _record_sample(x, P, nis, i, hist_x, hist_cov, hist_nis)
