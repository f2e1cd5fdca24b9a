"""The arrays the foot INS's compiled kernels work on, grouped by what they are (named tuples of
arrays, which the kernels take as they are and unpack): the IMU samples, the filter's state,
the history it fills, the record it keeps for the whole-run RTS, and a step's scratch.

Units and frames as everywhere in the foot INS: time s, specific force m/s², angular rate
rad/s in the body frame; nominal state (16,) and error state (15,) of
:mod:`bodyfusion.nav.error_state`, ENU navigation frame."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from bodyfusion.nav.error_state import FilterParams

PACKED_SIZE = 120
"""Elements of a symmetric 15×15 matrix stored packed: its upper triangle by rows."""


class ImuSamples(NamedTuple):
    """The samples a kernel steps through: times ``t`` (N,) s, specific force ``acc_b`` (N, 3)
    and angular rate ``gyro_b`` (N, 3), ``stance`` (N,) bool (a zero-velocity update there)."""

    t: np.ndarray
    acc_b: np.ndarray
    gyro_b: np.ndarray
    stance: np.ndarray


class FilterState(NamedTuple):
    """What a filter carries from sample to sample, updated in place: nominal state ``x``
    (16,), covariance ``P`` (15, 15), the mechanisation's memory ``mech_memory`` (6,, the
    previous step's increments) and ``phi`` (15, 15), the error-state transition accumulated
    for the fuser's cross-covariances ((0, 0): off)."""

    x: np.ndarray
    P: np.ndarray
    mech_memory: np.ndarray
    phi: np.ndarray


RECORDED_COVARIANCE = 13
"""Columns of the covariance a filter records per sample (``hist_cov``): 0–2 the position
variances east, north, up and 3 the east–north covariance (m²); 4–6 the velocity variances
east, north, up (m²/s²); 7–12 the attitude error's covariance (δθ, navigation frame, rad²),
packed ``EE, NN, UU, EN, EU, NU``."""
VELOCITY_VARIANCE = slice(4, 7)
ATTITUDE_COVARIANCE = slice(7, 13)


class FilterHistory(NamedTuple):
    """The rows a filter fills per sample: nominal state ``hist_x`` (N, 16), covariance entries
    ``hist_cov`` (N, :data:`RECORDED_COVARIANCE`), the stance update's NIS ``hist_nis`` (N,),
    and ``counters`` (the kernels' ``C_*`` layout)."""

    hist_x: np.ndarray
    hist_cov: np.ndarray
    hist_nis: np.ndarray
    counters: np.ndarray


class RtsRecord(NamedTuple):
    """What the filter records for the whole-run RTS as it runs (empty arrays: nothing,
    :func:`no_record`): per sample the packed posterior covariance ``Pu`` (N, PACKED_SIZE) and
    the step's mean specific force ``f_ns`` (N, 3); per stance sample ``st_v`` (S, 6) and
    ``st_P`` (S, 15, 4); and the nominal state ``x_prior`` (16,) and covariance ``P_prior``
    (15, 15) before the last step of a call."""

    Pu: np.ndarray
    f_ns: np.ndarray
    st_v: np.ndarray
    st_P: np.ndarray
    x_prior: np.ndarray
    P_prior: np.ndarray


def no_record() -> RtsRecord:
    """The record of a run that records nothing."""
    return RtsRecord(np.empty((0, PACKED_SIZE)), np.empty((0, 3)), np.empty((0, 6)), np.empty((0, 15, 4)),
                     np.empty(16), np.empty((0, 0)))


class StepScratch(NamedTuple):
    """A step's working arrays: the process model ``q_diag`` (17,,
    :func:`~bodyfusion.nav.error_state.process_noise_diag`), the step's mean specific force
    ``f_n`` (3,) and C_nb ``C`` (3, 3) as it leaves them, ``work`` (15, 15) and ``dx`` (15,)."""

    q_diag: np.ndarray
    f_n: np.ndarray
    C: np.ndarray
    work: np.ndarray
    dx: np.ndarray


class FilterReplay(NamedTuple):
    """What a replay of the filter repeats of what it did outside its compiled loop: its recorded
    nominal states ``recorded_x`` (N, 16); the override samples ``ov_idx`` (K,, sorted: fuser
    corrections, position fixes, the ckf's coloured updates) with the covariance each left
    ``ov_P`` (K, 15, 15); the kept corrections ``kept_idx`` (J,, sorted) with the nominal state
    before each ``kept_x`` (J, 16); the samples after a gap ``gap_idx`` (G,, sorted) with the
    covariance the gap policy added before the step to each ``gap_dP`` (G, 15, 15)."""

    recorded_x: np.ndarray
    ov_idx: np.ndarray
    ov_P: np.ndarray
    kept_idx: np.ndarray
    kept_x: np.ndarray
    gap_idx: np.ndarray
    gap_dP: np.ndarray


class FilterRun(NamedTuple):
    """A filter's run as the smoothers take it: its ``samples`` (:class:`ImuSamples`), its
    ``params`` (:class:`~bodyfusion.nav.error_state.FilterParams`), what it did outside its loop
    (:class:`FilterReplay`) and its initial covariance ``P0`` (15, 15)."""

    samples: ImuSamples
    params: FilterParams
    replay: FilterReplay
    P0: np.ndarray


class PassBuffers(NamedTuple):
    """A replayed pass over a block, per step j (L + 1 rows): posterior nominal state ``xs``
    (·, 16) and the prior ``xp`` (·, 16), posterior and prior covariance ``Ppost``, ``Pprior``
    (·, 15, 15), the step's transition ``Phi`` (·, 15, 15), the correction injected ``dx``
    (·, 15), the position an override moved ``jump`` (·, 3, m) and the heading reset's east and
    north velocity rows ``yaw_reset`` (·, 2). The FB smoothers hold two passes: a leading axis."""

    xs: np.ndarray
    xp: np.ndarray
    Ppost: np.ndarray
    Pprior: np.ndarray
    Phi: np.ndarray
    dx: np.ndarray
    jump: np.ndarray
    yaw_reset: np.ndarray


class SmoothedPass(NamedTuple):
    """A pass's RTS and fusion buffers: smoothed error ``dxs`` (·, 15) and covariance ``Ps``
    (·, 15, 15), smoothed nominal state ``smoothed`` (·, 16) (a leading pass axis for FB), and
    the fused position block ``fused_P`` (·, m, m; m = 0: none formed)."""

    dxs: np.ndarray
    Ps: np.ndarray
    smoothed: np.ndarray
    fused_P: np.ndarray


class SweepRecord(NamedTuple):
    """What the whole-run RTS in Bryson–Frazier form steps back through
    (:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.mbf_sweep`): per sample the packed
    posterior covariance ``Pu`` (·, PACKED_SIZE) and mean specific force ``f_ns`` (·, 3); per
    stance sample ``st_v`` (·, 6) and ``st_P`` (·, 15, 4); per general update (a correction
    outside the filter's loop, or the ZARU) the prior covariance ``gen_P`` (·, 15, 15), the
    correction ``gen_dx`` (·, 15), the heading reset's a ``gen_a`` (·, 2) and whether it was
    kept ``gen_kept`` (·,); per kept correction the covariance before it ``kept_P`` (·, 15, 15)."""

    Pu: np.ndarray
    f_ns: np.ndarray
    st_v: np.ndarray
    st_P: np.ndarray
    gen_P: np.ndarray
    gen_dx: np.ndarray
    gen_a: np.ndarray
    gen_kept: np.ndarray
    kept_P: np.ndarray


class SmoothedOutput(NamedTuple):
    """Where a smoother writes its result: nominal states ``out_x`` (N, 16) and position
    covariance ``out_var`` (N, 4: variances east, north, up and the east–north covariance, m²)."""

    out_x: np.ndarray
    out_var: np.ndarray


class CrossTerms(NamedTuple):
    """What a foot's sweep needs of the other systems it is smoothed with jointly
    (:mod:`~bodyfusion.plugins.foot_ins.smoothing_joint`; m = the others' stacked error states,
    0 alone): the adjoint's cross block ``X`` (15, m) between this foot and the others, carried
    back with this foot's steps; the filter's cross-covariance ``Zs`` (L + 1, 15, m) between
    this foot at each sample of the sweep and the others where they stand; the others' adjoint
    ``lam_o`` (m,) and its block ``Lam_oo`` (m, m), fixed while this foot is swept."""

    X: np.ndarray
    Zs: np.ndarray
    lam_o: np.ndarray
    Lam_oo: np.ndarray


def no_cross() -> CrossTerms:
    """The cross terms of a foot smoothed on its own."""
    return CrossTerms(np.zeros((15, 0)), np.zeros((1, 15, 0)), np.zeros(0), np.zeros((0, 0)))
