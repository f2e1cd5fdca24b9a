"""Smoothers of the foot INS (bodyfusion.plugins.foot_ins.smoothing): RTS, FB, FB-RTS."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import SmootherConfig, load_layout
from bodyfusion.core.run import run_layout
from bodyfusion.nav.strapdown import integrate
from bodyfusion.plugins.foot_ins.smoothing import segment_bounds, smooth_record
from bodyfusion.plugins.foot_ins.smoothing_kernels import (
    backward_block,
    forward_rerun_block,
    rts_block,
)
from bodyfusion.sim import simulate
from tests.paths import ROOT

VICON_CFG = ROOT / "configs" / "dual_foot_vicon.yaml"

WALK = """
name: walk
rate_hz: 100
path: {kind: polyline, waypoints_m: [[0, 0], [0, 12], [8, 12]], turn_radius_m: 0.5}
gait: {start_still_s: 1, end_still_s: 1}
systems:
  foot: {kind: foot_imu, foot: left, imu: {preset: icm20948, acc_bias_mps2: [0.05, -0.03, 0.02]}}
layout:
  systems:
    foot: {detector: {kind: labels}}
"""


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    d = tmp_path_factory.mktemp("walk")
    scn = d / "walk.yaml"
    scn.write_text(WALK)
    sim = simulate(scn, d / "out", seed=3)
    # the filter starts from a foot INS's generic bias priors, not the simulator's: it leaves
    # in-stride errors while its bias estimates settle — the errors smoothing is for
    result = run_layout(load_layout(sim.config_path, ["systems.foot.initial.gyro_bias_sd_radps=1e-3",
                                                      "systems.foot.initial.acc_bias_sd_mps2=0.05"]))
    system = result.systems["foot"]
    truth = result.truths["foot"]
    rec = system.smoothing_record()
    pos = np.column_stack([np.interp(rec["t"], truth.t, truth.pos_n[:, k]) for k in range(3)])
    return sim, rec, pos


def _rmse(x, pos):
    return float(np.sqrt(np.mean(np.sum((x[:, 0:2] - pos[:, 0:2]) ** 2, axis=1))))


# --------------------------------------------------------------------------- RTS kernel


def test_rts_kernel_equals_textbook_rts_on_a_linear_gaussian_toy():
    rng = np.random.default_rng(1)
    n, L = 15, 40
    A = 0.05 * rng.standard_normal((n, n))
    Phi = np.eye(n) + A
    Q = np.diag(rng.uniform(0.01, 0.1, n))
    H = np.zeros((3, n))
    H[0, 0] = H[1, 4] = H[2, 9] = 1.0
    R = 0.2 * np.eye(3)
    xtrue = rng.standard_normal(n)
    x, P = np.zeros(n), np.eye(n)
    xs_f, Ps_f, xp_f, Pp_f = [x.copy()], [P.copy()], [None], [None]
    Phis = np.zeros((L + 1, n, n))
    dx = np.zeros((L + 1, n))
    for j in range(1, L + 1):
        xtrue = Phi @ xtrue + rng.multivariate_normal(np.zeros(n), Q)
        xp, Pp = Phi @ x, Phi @ P @ Phi.T + Q
        z = H @ xtrue + rng.multivariate_normal(np.zeros(3), R)
        K = Pp @ H.T @ np.linalg.inv(H @ Pp @ H.T + R)
        x = xp + K @ (z - H @ xp)
        P = (np.eye(n) - K @ H) @ Pp
        P = 0.5 * (P + P.T)
        xs_f.append(x.copy()); Ps_f.append(P.copy()); xp_f.append(xp); Pp_f.append(Pp)
        Phis[j] = Phi
        dx[j] = x - xp  # the correction a closed-loop filter injects
    # textbook RTS
    xs, Ps = [None] * (L + 1), [None] * (L + 1)
    xs[L], Ps[L] = xs_f[L], Ps_f[L]
    for j in range(L - 1, -1, -1):
        G = Ps_f[j] @ Phi.T @ np.linalg.inv(Pp_f[j + 1])
        xs[j] = xs_f[j] + G @ (xs[j + 1] - xp_f[j + 1])
        Ps[j] = Ps_f[j] + G @ (Ps[j + 1] - Pp_f[j + 1]) @ G.T
    Ppost = np.asarray(Ps_f)
    Pprior = np.asarray([np.eye(n)] + Pp_f[1:])
    dxs = np.zeros((L + 1, n))
    Pss = np.zeros((L + 1, n, n))
    assert rts_block(Ppost, Pprior, Phis, dx, L, np.zeros(n), Ppost[L].copy(), dxs, Pss) == 0
    for j in range(L + 1):
        np.testing.assert_allclose(xs_f[j] + dxs[j], xs[j], atol=1e-9)
        np.testing.assert_allclose(Pss[j], Ps[j], atol=1e-9)


# --------------------------------------------------------------------------- backward mechanisation


def test_backward_mechanisation_retraces_a_forward_trajectory(walk):
    _, rec, _ = walk
    t, acc, gyro = rec["t"], rec["acc"], rec["gyro"]
    a, b = 150, 650  # through a swing
    params = rec["params"].copy()
    x0 = rec["hist_x"][a].copy()
    fwd = integrate(x0, t[a:b + 1], acc[a:b + 1], gyro[a:b + 1], params[6], params[7:10].copy())
    L = b - a
    xb = np.zeros((L + 1, 16))
    bufs = [np.zeros((L + 1, 15, 15)) for _ in range(3)]
    no_stance = np.zeros_like(rec["stance"])
    backward_block(fwd[-1], np.eye(15) * 1e-4, t, acc, gyro, no_stance, params, a, b, xb, bufs[0], bufs[1],
                   bufs[2], np.zeros((L + 1, 15)), np.zeros(1))
    back = xb[::-1]
    assert np.max(np.abs(back[:, 0:3] - fwd[:, 0:3])) < 2e-3  # m, over 5 s of free navigation
    np.testing.assert_allclose(back[:, 3:6], -fwd[:, 3:6], atol=2e-3)  # velocities opposite
    dq = np.abs(np.sum(back[:, 6:10] * fwd[:, 6:10], axis=1))
    assert np.min(dq) > 1 - 1e-8  # same attitude


# --------------------------------------------------------------------------- smoothing a walk


def _stride_error(x, pos, bounds):
    """RMS horizontal error of the track relative to its position at each segment start
    (the error a stride adds; the heading drift that no smoother can observe is left out)."""
    errs = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        d = (x[a:b + 1, 0:2] - x[a, 0:2]) - (pos[a:b + 1, 0:2] - pos[a, 0:2])
        errs.append(np.sum(d**2, axis=1))
    return float(np.sqrt(np.mean(np.concatenate(errs))))


def test_smoothing_reduces_error_on_a_short_simulated_walk(walk):
    _, rec, pos = walk
    bounds = segment_bounds(rec["stance"], rec["rate_hz"], 0.04, 10.0)
    filt = _stride_error(rec["hist_x"], pos, bounds)
    out = {}
    for kind in ("rts", "fb", "fb-rts"):
        res = smooth_record(rec, SmootherConfig(kind=kind))
        assert res.x is not None and res.diagnostics["warnings"] == 0
        assert res.diagnostics["covariance_rebuild_rel_error"] < 1e-9  # same covariances as the filter
        assert res.diagnostics["segments"] >= 10
        out[kind] = _stride_error(res.x, pos, bounds)
    assert out["rts"] < 0.8 * filt, (filt, out)
    # FB / FB-RTS keep the fused position (not re-integrated from velocity) and re-seed
    # each segment: on this short walk they gain less per stride than RTS, but still gain
    assert out["fb"] < filt and out["fb-rts"] < filt, (filt, out)
    seg = smooth_record(rec, SmootherConfig(kind="rts", span="segment"))
    assert seg.x is not None and seg.diagnostics["span"] == "segment"
    lat = smooth_record(rec, SmootherConfig(kind="fb-rts")).diagnostics["latency_ms"]
    assert lat["segments"] >= 10 and lat["mean_ms"] > 0


def test_forward_rerun_from_the_filter_seed_reproduces_the_filter(walk):
    _, rec, _ = walk
    bounds = segment_bounds(rec["stance"], rec["rate_hz"], 0.04, 10.0)
    a, b = 0, int(bounds[2])  # the first two segments, from the filter's initial state
    L = b - a
    xf = np.zeros((L + 1, 16))
    bufs = [np.zeros((L + 1, 15, 15)) for _ in range(3)]
    P_b = np.zeros((15, 15))
    forward_rerun_block(rec["hist_x"][0].copy(), rec["P0"], rec["hist_x"], rec["t"], rec["acc"], rec["gyro"],
                        rec["stance"], rec["params"], a, b, rec["P0"], rec["override_idx"], rec["override_P"], xf,
                        bufs[0], bufs[1], bufs[2], np.zeros((L + 1, 15)), P_b)
    np.testing.assert_allclose(xf, rec["hist_x"][a:b + 1], atol=1e-9)
    np.testing.assert_allclose(bufs[0][L], P_b, atol=1e-12)  # re-run and rebuilt original agree


@pytest.mark.parametrize("kind", ["fb", "fb-rts"])
def test_fb_forward_pass_is_rerun_from_the_fused_seed_not_the_filter_history(walk, kind):
    """Each segment's forward pass starts from the previous segment's fused end state and
    runs the filter itself: the recorded filter states (but the first, and those at
    fuser/fix corrections, none here) do not enter the result."""
    _, rec, _ = walk
    assert rec["override_idx"].size == 0
    ref = smooth_record(rec, SmootherConfig(kind=kind))
    hx = rec["hist_x"].copy()
    hx[1:, 0:3] += [3.0, -2.0, 0.5]
    hx[1:, 3:6] += 0.1
    alt = smooth_record(dict(rec, hist_x=hx), SmootherConfig(kind=kind))
    np.testing.assert_allclose(alt.x, ref.x, atol=1e-9)
    # the per-segment compute times come with the result
    assert ref.segment_latency_ms is not None and ref.segment_latency_ms.size == ref.diagnostics["segments"]


def test_segments_split_at_stance_midpoints():
    stance = np.zeros(100, dtype=bool)
    stance[0:10] = stance[40:50] = stance[80:90] = stance[60] = True  # the lone sample is a flicker
    b = segment_bounds(stance, rate_hz=100.0, min_stance_s=0.04, max_segment_s=10.0)
    np.testing.assert_array_equal(b, [0, 4, 44, 84, 99])
    b = segment_bounds(stance, rate_hz=100.0, min_stance_s=0.04, max_segment_s=0.2)
    assert np.all(np.diff(b) <= 20) and b[0] == 0 and b[-1] == 99


# --------------------------------------------------------------------------- never fail


def test_too_short_or_no_stance_gives_the_filter_result_and_a_counted_warning(walk):
    sim, rec, _ = walk
    short = {k: (v[:5] if isinstance(v, np.ndarray) and v.shape[:1] == rec["t"].shape else v) for k, v in rec.items()}
    res = smooth_record(short, SmootherConfig(kind="fb-rts"))
    assert res.x is None and res.diagnostics["warnings"] == 1
    still = dict(rec, stance=np.zeros_like(rec["stance"]))
    res = smooth_record(still, SmootherConfig(kind="rts"))
    assert res.x is None and res.diagnostics["warnings"] == 1
    assert "no stance" in res.diagnostics["warning_messages"][0]
    # through a run: a detector that finds no stance
    result = run_layout(load_layout(sim.config_path, [
        "smoother.kind=fb-rts", "systems.foot.detector.kind=magnitude", "systems.foot.detector.threshold=1e-9"]))
    foot = result.systems["foot"]
    d = foot.diagnostics()["smoothing"]
    assert d["warnings"] == 1
    np.testing.assert_array_equal(foot.trajectory().pos_n, foot.hist_x[:, 0:3])


# --------------------------------------------------------------------------- config


@pytest.mark.parametrize("kind", ["none", "rts", "fb", "fb-rts"])
def test_smoother_kind_accepted(kind):
    assert load_layout(VICON_CFG, [f"smoother.kind={kind}"]).layout.smoother.kind == kind


@pytest.mark.parametrize("override,key", [("smoother.kind=fbrts", "smoother.kind"),
                                          ("smoother.span=all", "smoother.span"),
                                          ("smoother.colour=red", "smoother.colour")])
def test_bad_smoother_settings_are_refused_with_the_key_path(override, key):
    with pytest.raises(ConfigError) as ei:
        load_layout(VICON_CFG, [override])
    assert key in str(ei.value)
