"""Smoothers of the foot INS (bodyfusion.plugins.foot_ins.smoothing): RTS, FB, FB-RTS ([Shen2025])."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import SmootherConfig, load_layout
from bodyfusion.runner import build_systems, layout_context, run_layout
from bodyfusion.nav.strapdown import integrate
from bodyfusion.plugins.foot_ins.smoothing import lag_windows, segment_bounds, smooth_record
from bodyfusion.plugins.foot_ins.smoothing_record import BlockBuffers, RunRecord
from bodyfusion.plugins.foot_ins.records import (FilterReplay, FilterState, ImuSamples, PassBuffers,
                                                 SmoothedOutput)
from bodyfusion.plugins.foot_ins.smoothing_fb import backward_prior, fb_segment, fuse_block, integrate_position
from bodyfusion.plugins.foot_ins.smoothing_replay import filter_pass
from bodyfusion.plugins.foot_ins.smoothing_rts import apply_smoothed, rts_block, rts_block_after_position
from bodyfusion.sim import simulate
from tests.paths import ROOT

VICON_CFG = ROOT / "configs" / "dual_foot_vicon.yaml"
VICON_DATA = ROOT / "examples" / "data" / "dual_foot_vicon_hu2025"
KINDS = {"rts": SmootherConfig(kind="rts"), "rts-segment": SmootherConfig(kind="rts", span="segment"),
         "fb": SmootherConfig(kind="fb"), "fb-rts": SmootherConfig(kind="fb-rts")}

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

# The filter told the simulated sensor's own error model: biases that random-walk with the
# filter's densities (the preset's Gauss-Markov instability off), a turn-on accelerometer
# bias drawn with the filter's prior sigma, and a foot whose stance velocity is white noise
# of the ZUPT's sigma (0.01 m/s).
MATCHED_WALK = """
name: matched_walk
rate_hz: 100
path: {kind: rectangle, length_m: 10, width_m: 6, laps: 2, clockwise: true, turn_radius_m: 1.0}
gait: {start_still_s: 2, end_still_s: 1}
systems:
  foot:
    kind: foot_imu
    foot: left
    imu: {preset: icm20948, gyro_bias_instability_radps: 0, acc_bias_instability_mps2: 0,
          gyro_bias_random_walk: 2.0e-5, acc_bias_random_walk: 5.0e-4, acc_bias_sd_mps2: 0.05}
    stance_noise: {colour_factor: 0, sigma_mps: 0.01}
layout:
  systems:
    foot: {detector: {kind: labels}}
"""


def _simulate(tmp_path_factory, text: str, seed: int):
    d = tmp_path_factory.mktemp("sim")
    scn = d / "scenario.yaml"
    scn.write_text(text)
    return simulate(scn, d / "out", seed=seed)


def _record_and_truth(result, name="foot"):
    rec = result.systems[name].smoothing_record()
    truth = result.truths[name]
    pos = np.column_stack([np.interp(rec["t"], truth.t, truth.pos_n[:, k]) for k in range(3)])
    return rec, pos


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    sim = _simulate(tmp_path_factory, WALK, 3)
    # the filter starts from a foot INS's generic bias priors, not the simulator's: it leaves
    # in-stride errors while its bias estimates settle — the errors smoothing is for
    result = run_layout(load_layout(sim.config_path, ["systems.foot.initial.gyro_bias_sd_radps=1e-3",
                                                      "systems.foot.initial.acc_bias_sd_mps2=0.05"]))
    rec, pos = _record_and_truth(result)
    return sim, rec, pos


def _rmse(x, pos):
    return float(np.sqrt(np.mean(np.sum((x[:, 0:2] - pos[:, 0:2]) ** 2, axis=1))))


def _stride_error(x, pos, bounds):
    """RMS horizontal error of the track relative to its position at each segment start
    (the error a stride adds; the heading drift that no smoother can observe is left out)."""
    errs = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        d = (x[a:b + 1, 0:2] - x[a, 0:2]) - (pos[a:b + 1, 0:2] - pos[a, 0:2])
        errs.append(np.sum(d**2, axis=1))
    return float(np.sqrt(np.mean(np.concatenate(errs))))


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
    unused = np.zeros((L + 1, 16))
    passes = PassBuffers(unused, unused, Ppost, Pprior, Phis, dx, np.zeros((L + 1, 3)), np.zeros((L + 1, 2)))
    assert rts_block(passes, L, np.zeros(n), Ppost[L].copy(), dxs, Pss) == 0
    for j in range(L + 1):
        np.testing.assert_allclose(xs_f[j] + dxs[j], xs[j], atol=1e-9)
        np.testing.assert_allclose(Pss[j], Ps[j], atol=1e-9)


def _rts(buf: BlockBuffers, L: int, position: bool = True) -> int:
    """The textbook RTS of the first pass's block a … a + L from its end (rts_block; without
    ``position``, the states after it: rts_block_after_position), the states into ``smoothed``."""
    sweep = rts_block if position else rts_block_after_position
    failed = sweep(buf.buffers(0), L, np.zeros(15), buf.Ppost[0, L].copy(), buf.dxs[0], buf.Ps[0])
    apply_smoothed(buf.xs[0], 0, L, buf.dxs[0], buf.smoothed[0], 0)
    return failed


# --------------------------------------------------------------------------- one step: filter = replay


def _replay(rec: dict) -> tuple[BlockBuffers, np.ndarray]:
    r = RunRecord(rec)
    buf = BlockBuffers(r.n)
    return buf, r.forward(0, r.n - 1, r.P0, True, buf)


def test_the_smoothers_replay_is_the_filter_bit_for_bit(walk):
    _, rec, _ = walk
    buf, P_end = _replay(rec)
    assert np.array_equal(buf.xs[0], rec["hist_x"])
    assert np.array_equal(P_end, rec["P_end"])
    for kind, cfg in KINDS.items():
        d = smooth_record(rec, cfg).diagnostics
        assert d["state_rebuild_max_abs_error"] == 0.0 and d["covariance_rebuild_rel_error"] == 0.0, kind


@pytest.fixture(scope="module")
def vicon_cut(tmp_path_factory):
    """The first 30 s of the Vicon walk, both feet within 0.6 m (the fuser corrects both),
    the left IMU with 0.5 s of samples cut out (the gap policy inflates its covariance),
    smoothed by the whole-run RTS."""
    tmp_path = tmp_path_factory.mktemp("vicon_cut")
    left = (VICON_DATA / "imuMeasLeft.csv").read_text().splitlines()
    right = (VICON_DATA / "imuMeasRight.csv").read_text().splitlines()
    (tmp_path / "left.csv").write_text("\n".join(left[:901] + left[931:1801]) + "\n")
    (tmp_path / "right.csv").write_text("\n".join(right[:1801]) + "\n")
    return run_layout(load_layout(VICON_CFG, [f"systems.left_foot.data.path={tmp_path / 'left.csv'}",
                                              f"systems.right_foot.data.path={tmp_path / 'right.csv'}",
                                              "smoother.kind=rts"]))


def test_replay_through_fuser_corrections_and_a_gap_is_the_filter_bit_for_bit(vicon_cut):
    res = vicon_cut
    for foot in ("left_foot", "right_foot"):
        rec = res.systems[foot].smoothing_record()
        assert rec["override_idx"].size > 5
        buf, P_end = _replay(rec)
        assert np.array_equal(buf.xs[0], rec["hist_x"]) and np.array_equal(P_end, rec["P_end"]), foot
        assert res.systems[foot].diagnostics()["smoothing"]["warnings"] == 0
    rec = res.systems["left_foot"].smoothing_record()
    assert rec["gap_idx"].size == 1
    g, dP = int(rec["gap_idx"][0]), rec["gap_dP"][0]
    buf, _ = _replay(rec)
    # the inflation is process noise of the step across the gap, not uncertainty before it
    assert buf.Ppost[0, g - 1, 0, 0] < 0.5 * dP[0, 0] < buf.Pprior[0, g, 0, 0]


@pytest.mark.parametrize("kind", ["rts", "rts-segment"])
def test_the_filters_own_record_smooths_as_its_replay(vicon_cut, kind):
    """Planned for the RTS, the ekf records what the sweep needs as it runs (ForwardRecord,
    completed at the fuser's corrections): the smoothed states and covariances, of the whole run
    or of each segment, equal those smoothed from the replay of the filter, which is not run."""
    for foot in ("left_foot", "right_foot"):
        rec = vicon_cut.systems[foot].smoothing_record()
        assert rec["forward_record"].active and rec["kept_idx"].size > 5, foot
        own = smooth_record(rec, KINDS[kind])
        replayed = smooth_record({**rec, "forward_record": None}, KINDS[kind])
        assert np.array_equal(own.x, replayed.x) and np.array_equal(own.pos_var, replayed.pos_var), foot
        assert own.diagnostics["rts_gain_failures"] == replayed.diagnostics["rts_gain_failures"] == 0


def test_segmented_rts_is_the_textbook_sweep_of_each_segment(walk, vicon_cut):
    """span: segment sweeps each segment's part of the record (the filter's own, or the segment
    replayed) back in the Bryson–Frazier form from zero adjoints at its end: the textbook RTS of
    the segment (rts_block from the filter at its end)
    to rounding. Where the fuser corrected the foot inside a segment the two differ by design
    (the sweep takes the relative correction as a known input, as the whole-run sweep does):
    those segments are left out here."""
    cfg = KINDS["rts-segment"]
    checked = skipped = 0
    for rec in [walk[1]] + [vicon_cut.systems[foot].smoothing_record() for foot in ("left_foot", "right_foot")]:
        res = smooth_record(rec, cfg)
        assert res.diagnostics["rts_gain_failures"] == 0 and res.diagnostics["state_rebuild_max_abs_error"] == 0.0
        r = RunRecord(rec)
        bounds = segment_bounds(r.stance, r.rate_hz, cfg.min_stance_s, cfg.max_segment_s)
        buf = BlockBuffers(int(np.max(np.diff(bounds))) + 1)
        P = r.P0.copy()
        for k in range(bounds.size - 1):
            a, b = int(bounds[k]), int(bounds[k + 1])
            P = r.forward(a, b, P, True, buf)
            if np.any((r.ov_idx > a) & (r.ov_idx <= b)):
                skipped += 1
                continue
            assert _rts(buf, b - a) == 0
            L = b - a - (k + 2 < bounds.size)  # sample b is the next segment's
            Ps = buf.Ps[0, :L + 1]
            sd = np.sqrt(np.einsum("jkk->jk", Ps))
            np.testing.assert_allclose(res.x[a:a + L + 1, 0:6] / sd[:, 0:6], buf.smoothed[0, :L + 1, 0:6] / sd[:, 0:6],
                                       rtol=0, atol=1e-9)
            np.testing.assert_allclose(res.x[a:a + L + 1, 6:10], buf.smoothed[0, :L + 1, 6:10], rtol=0, atol=1e-12)
            var = np.column_stack([Ps[:, 0, 0], Ps[:, 1, 1], Ps[:, 2, 2], Ps[:, 0, 1]])
            scale = sd[:, [0, 1, 2, 0]] * sd[:, [0, 1, 2, 1]]
            np.testing.assert_allclose(res.pos_var[a:a + L + 1] / scale, var / scale, rtol=0, atol=1e-9)
            checked += 1
    assert checked > 20 and skipped > 10, (checked, skipped)


def test_only_the_rts_of_the_ekf_without_zaru_records_as_it_runs(walk):
    for overrides, cfg, records in (([], KINDS["rts"], True), ([], KINDS["rts-segment"], True),
                                    ([], KINDS["fb-rts"], False), ([], SmootherConfig(kind="none"), False),
                                    (["systems.foot.filter.kind=ckf"], KINDS["rts"], False),
                                    (["systems.foot.filter.zaru_sigma_radps=0.01"], KINDS["rts"], False)):
        loaded = load_layout(walk[0].config_path, overrides)
        foot = build_systems(loaded, layout_context(loaded))["foot"]
        foot.plan_smoothing(cfg)
        assert foot.smoothing_record()["forward_record"].active == records, (overrides, cfg)


# --------------------------------------------------------------------------- backward navigation


def _segment(r: RunRecord, a: int, b: int, P_a: np.ndarray, with_rts: bool, buf: BlockBuffers, fused_P: np.ndarray,
             out_x: np.ndarray, out_var: np.ndarray) -> tuple:
    """FB (FB-RTS) of the segment a … b, the passes into ``buf`` (forward [0], backward [1])."""
    params_bw = r.params.backward()
    return fb_segment(r.run, params_bw, a, b, P_a, r.memory([a])[0], with_rts, buf.buffers(), buf.smoothing(fused_P),
                      SmoothedOutput(out_x, out_var))


def test_backward_navigation_retraces_a_forward_trajectory(walk):
    _, rec, _ = walk
    a, b = 150, 650  # through a swing
    r = RunRecord(dict(rec, stance=np.zeros_like(rec["stance"]), hist_x=rec["hist_x"].copy()))  # no update
    params = r.params
    fwd = integrate(r.hist_x[a].copy(), r.t[a:b + 1], r.acc[a:b + 1], r.gyro[a:b + 1], params.gravity, params.earth_rate.copy())
    r.hist_x[b] = fwd[-1]  # the backward pass starts from the forward nominal state at b
    buf = BlockBuffers(b - a + 1, 2)
    _segment(r, a, b, r.P0, False, buf, np.zeros((b - a + 1, 3, 3)), r.hist_x.copy(), np.zeros((r.n, 4)))
    back = buf.xs[1, ::-1]
    back[:, 3:6] *= -1.0  # backward form: velocity negated
    assert np.max(np.abs(back[:, 0:3] - fwd[:, 0:3])) < 2e-3  # m, over 5 s of free navigation
    np.testing.assert_allclose(back[:, 3:6], fwd[:, 3:6], atol=2e-3)
    assert np.min(np.abs(np.sum(back[:, 6:10] * fwd[:, 6:10], axis=1))) > 1 - 1e-8  # same attitude


# --------------------------------------------------------------------------- smoothing a walk


def test_smoothing_reduces_the_in_stride_error_on_a_short_walk(walk):
    _, rec, pos = walk
    bounds = segment_bounds(rec["stance"], rec["rate_hz"], 0.04, 10.0)
    filt = _stride_error(rec["hist_x"], pos, bounds)
    out = {}
    for kind, cfg in KINDS.items():
        res = smooth_record(rec, cfg)
        assert res.x is not None and res.diagnostics["warnings"] == 0
        assert res.diagnostics["segments"] >= 10
        out[kind] = _stride_error(res.x, pos, bounds)
    assert all(v < 0.8 * filt for v in out.values()), (filt, out)
    lat = smooth_record(rec, KINDS["fb-rts"]).diagnostics["latency_ms"]
    assert lat["segments"] >= 10 and lat["mean_ms"] > 0


def test_fb_position_is_recomputed_from_the_fused_velocity(walk):
    _, rec, _ = walk
    x = smooth_record(rec, KINDS["fb"]).x
    bounds = segment_bounds(rec["stance"], rec["rate_hz"], 0.04, 10.0)
    a, b = int(bounds[5]), int(bounds[6])  # sample b belongs to the next segment
    dt = np.diff(rec["t"][a:b])[:, None]
    np.testing.assert_allclose(np.diff(x[a:b, 0:3], axis=0), 0.5 * (x[a:b - 1, 3:6] + x[a + 1:b, 3:6]) * dt,
                               rtol=0, atol=1e-12)


def test_fb_passes_are_independent_nothing_shrinks_at_segment_boundaries(walk):
    """The backward pass starts without information: fused with the forward pass it leaves the
    yaw σ (which neither pass can observe) where the filter has it, the fused state at each
    segment end is the filter's, and every segment starts from the filter's own covariance
    (so the replayed filter ends on its last covariance, bit for bit)."""
    _, rec, _ = walk
    r = RunRecord(rec)
    bounds = segment_bounds(r.stance, r.rate_hz, 0.04, 10.0)
    size = int(np.max(np.diff(bounds))) + 1
    buf = BlockBuffers(size, 2)
    fused_x, fused_P, fused_var = r.hist_x.copy(), np.zeros((size, 15, 15)), np.zeros((r.n, 4))
    P = r.P0.copy()
    for k in range(bounds.size - 1):
        a, b = int(bounds[k]), int(bounds[k + 1])
        L = b - a
        P_b, _, _, failed = _segment(r, a, b, P, False, buf, fused_P, fused_x, fused_var)
        assert failed == 0
        Ppost = buf.Ppost[0]
        yaw_f, yaw_g = np.sqrt(Ppost[:L + 1, 8, 8]), np.sqrt(fused_P[:L + 1, 8, 8])
        assert np.all(yaw_g >= 0.99 * yaw_f)
        assert np.all(yaw_g <= yaw_f * (1 + 1e-12))
        sd = np.sqrt(np.diag(Ppost[L]))
        assert np.max(np.abs(fused_P[L] - Ppost[L]) / np.outer(sd, sd)) < 0.02  # the fused end is the forward one
        P = P_b
    assert np.array_equal(P, r.P_end)
    for kind in ("fb", "fb-rts"):
        assert smooth_record(rec, KINDS[kind]).diagnostics["covariance_rebuild_rel_error"] == 0.0


def test_the_sweep_after_position_is_the_whole_sweeps_on_those_states(walk):
    """No state, ZUPT or heading reset depends on position: where nothing measures it (the
    simulated walk's filter, like every backward pass) the RTS of the other twelve states is the
    whole sweep's on them, to rounding, and leaves position unsmoothed."""
    r = RunRecord(walk[1])
    bounds = segment_bounds(r.stance, r.rate_hz, KINDS["fb-rts"].min_stance_s, KINDS["fb-rts"].max_segment_s)
    whole, reduced = BlockBuffers(int(np.max(np.diff(bounds))) + 1), BlockBuffers(int(np.max(np.diff(bounds))) + 1)
    P = r.P0.copy()
    for k in range(min(bounds.size - 1, 12)):
        a, b = int(bounds[k]), int(bounds[k + 1])
        P_b = r.forward(a, b, P, True, whole)
        r.forward(a, b, P, True, reduced)
        L = b - a
        assert _rts(whole, L) == 0 and _rts(reduced, L, position=False) == 0
        S = slice(3, 15)
        sd = np.sqrt(np.einsum("jkk->jk", whole.Ps[0, :L + 1, S, S]))
        np.testing.assert_allclose(reduced.Ps[0, :L + 1, S, S] / (sd[:, :, None] * sd[:, None, :]),
                                   whole.Ps[0, :L + 1, S, S] / (sd[:, :, None] * sd[:, None, :]), rtol=0, atol=1e-10)
        np.testing.assert_allclose(reduced.dxs[0, :L + 1, S] / sd, whole.dxs[0, :L + 1, S] / sd, rtol=0, atol=1e-10)
        assert not np.any(reduced.dxs[0, :L + 1, 0:3])
        assert not np.allclose(whole.dxs[0, :L, 0:3], 0.0)  # the whole sweep does move position
        P = P_b


def _fb_composed(rec: dict, with_rts: bool) -> tuple[np.ndarray, np.ndarray]:
    """FB (FB-RTS) as the passes composed one kernel at a time: the backward navigation's
    inputs reversed by numpy, both passes smoothed (the backward one's states after position),
    the whole fused covariance formed."""
    cfg = KINDS["fb-rts" if with_rts else "fb"]
    r = RunRecord(rec)
    bounds = segment_bounds(r.stance, r.rate_hz, cfg.min_stance_s, cfg.max_segment_s)
    size = int(np.max(np.diff(bounds))) + 1
    fw, bw, fused_P = BlockBuffers(size), BlockBuffers(size), np.zeros((size, 15, 15))
    out_x, out_var = r.hist_x.copy(), np.zeros((r.n, 4))
    params_bw = r.params.backward()
    sign = np.r_[np.ones(3), -np.ones(3), np.ones(6), -np.ones(3)]
    sign = np.outer(sign, sign)
    P = r.P0.copy()
    for k in range(bounds.size - 1):
        a, b = int(bounds[k]), int(bounds[k + 1])
        L = b - a
        P_b = r.forward(a, b, P, True, fw)
        i = b - np.arange(L + 1)
        src = np.minimum(i + 1, b)
        x0 = r.hist_x[b].copy()
        x0[3:6] *= -1.0
        x0[13:16] *= -1.0
        gaps = (r.gap_idx > a) & (r.gap_idx <= b)
        filter_pass(FilterState(x0, backward_prior(P_b, r.P0) * sign, np.zeros(6), np.empty((0, 0))),
                    ImuSamples(-r.t[i], r.acc[src], -r.gyro[src], np.ascontiguousarray(r.stance[i])), params_bw, 0, L,
                    FilterReplay(r.hist_x, np.empty(0, dtype=np.int64), np.empty((0, 15, 15)),
                                 np.empty(0, dtype=np.int64), np.empty((0, 16)),
                                 np.ascontiguousarray((b - r.gap_idx[gaps] + 1)[::-1]),
                                 np.ascontiguousarray((r.gap_dP[gaps] * sign)[::-1])), True, bw.buffers(0))
        if with_rts:
            _rts(fw, L)
            _rts(bw, L, position=False)
            fuse_block(fw.smoothed[0], fw.Ps[0], bw.smoothed[0], bw.Ps[0], L, out_x, fused_P, a)
            Pp = fw.Ps[0, :L + 1]
        else:
            fuse_block(fw.xs[0], fw.Ppost[0], bw.xp[0], bw.Pprior[0], L, out_x, fused_P, a)
            Pp = fused_P[:L + 1]
        out_var[a:b + 1] = np.column_stack([Pp[:, 0, 0], Pp[:, 1, 1], Pp[:, 2, 2], Pp[:, 0, 1]])
        integrate_position(out_x, r.t, a, b, out_x[a, 0:3].copy(), fw.jump[0])
        P = P_b
    return out_x, out_var


@pytest.mark.parametrize("with_rts", [False, True])
def test_fb_in_one_call_per_segment_is_the_passes_composed_bit_for_bit(walk, vicon_cut, with_rts):
    """One compiled call per segment (fb_segment: the reversed inputs built in it, the fusion's
    solve taking the position block's columns alone, or none) gives the numbers of the passes
    composed kernel by kernel with the whole fused covariance, through the fuser's corrections
    and a gap too."""
    kind = "fb-rts" if with_rts else "fb"
    recs = [walk[1]] + [vicon_cut.systems[foot].smoothing_record() for foot in ("left_foot", "right_foot")]
    assert recs[1]["gap_idx"].size == 1 and recs[1]["kept_idx"].size > 5
    for rec in recs:
        res = smooth_record(rec, KINDS[kind])
        x, var = _fb_composed(rec, with_rts)
        assert np.array_equal(res.x, x) and np.array_equal(res.pos_var, var)
        assert res.diagnostics["fusion_failures"] == 0 and res.diagnostics["state_rebuild_max_abs_error"] == 0.0


def test_segments_split_at_stance_midpoints():
    stance = np.zeros(100, dtype=bool)
    stance[0:10] = stance[40:50] = stance[80:90] = stance[60] = True  # the lone sample is a flicker
    b = segment_bounds(stance, rate_hz=100.0, min_stance_s=0.04, max_segment_s=10.0)
    np.testing.assert_array_equal(b, [0, 4, 44, 84, 99])
    b = segment_bounds(stance, rate_hz=100.0, min_stance_s=0.04, max_segment_s=0.2)
    assert np.all(np.diff(b) <= 20) and b[0] == 0 and b[-1] == 99


# --------------------------------------------------------------------------- never worse than the filter


@pytest.mark.slow
def test_rts_is_not_worse_than_its_filter_on_a_matched_model_walk(tmp_path_factory):
    """Simulation and filter share one error model: the whole-run RTS must not lose to the
    filter, on average and in most seeds, and its σ never exceeds the filter's."""
    filt, rts = [], []
    for seed in range(6):
        result = run_layout(load_layout(_simulate(tmp_path_factory, MATCHED_WALK, seed).config_path))
        rec, pos = _record_and_truth(result)
        res = smooth_record(rec, KINDS["rts"])
        filt.append(_rmse(rec["hist_x"], pos))
        rts.append(_rmse(res.x, pos))
        var_f = result.systems["foot"].hist_cov[:, :2]
        assert np.all(res.pos_var[:, :2] <= var_f * (1 + 1e-9) + 1e-15)
    filt, rts = np.asarray(filt), np.asarray(rts)
    assert rts.mean() <= filt.mean(), (filt, rts)
    assert np.sum(rts <= filt) >= 4, (filt, rts)  # on average, and in most seeds


def test_constrained_rts_keeps_the_constrained_filters_accuracy_on_the_vicon_walk():
    """Both feet of the Vicon walk kept within the shipped 0.6 m: each foot's smoother keeps
    the fuser's corrections as the filter made them, a known input (smoothed as measurements
    of that foot alone they cost the right foot 8 %: 0.076 -> 0.082 m) and the constraints
    hold again on the smoothed tracks: over both feet the smoothed RMSE is not above the
    constrained filter's, and no foot loses more than 5 % (today: left 0.088 -> 0.078 m,
    right 0.071 -> 0.073 m)."""
    forward = run_layout(load_layout(VICON_CFG))
    smoothed = run_layout(load_layout(VICON_CFG, ["smoother.kind=rts"]))
    rmse = {}
    for foot in ("left_foot", "right_foot"):
        rec = smoothed.systems[foot].smoothing_record()
        assert rec["kept_idx"].size > 5 and np.isin(rec["kept_idx"], rec["override_idx"]).all(), foot
        rmse[foot] = np.array([r.scores[foot].metrics["horizontal_error_m"]["rmse"] for r in (forward, smoothed)])
        assert rmse[foot][1] <= 1.05 * rmse[foot][0], (foot, rmse[foot])
    assert sum(rmse.values())[1] <= sum(rmse.values())[0], rmse
    assert smoothed.smoothed_constraints["method"] == "projection"


def test_smoothed_tracks_are_constrained_by_default_only_where_the_fuser_enforces_the_constraints():
    independent = ["fuser.method=none", "smoother.kind=rts", "constraints.0.distance_m=0.55"]
    assert run_layout(load_layout(VICON_CFG, independent)).smoothed_constraints is None
    asked = run_layout(load_layout(VICON_CFG, [*independent, "smoother.constrain_smoothed=true"]))
    assert asked.smoothed_constraints["constrained_samples"] > 0


# --------------------------------------------------------------------------- never fail


def test_too_short_or_no_stance_gives_the_filter_result_and_a_counted_warning(walk):
    sim, rec, _ = walk
    short = {k: (v[:5] if isinstance(v, np.ndarray) and v.shape[:1] == rec["t"].shape else v) for k, v in rec.items()}
    res = smooth_record(short, KINDS["fb-rts"])
    assert res.x is None and res.diagnostics["warnings"] == 1
    still = dict(rec, stance=np.zeros_like(rec["stance"]))
    res = smooth_record(still, KINDS["rts"])
    assert res.x is None and res.diagnostics["warnings"] == 1
    assert "no stance" in res.diagnostics["warning_messages"][0]
    # through a system: its smoother's warning in its diagnostics, its track the filter's
    foot = run_layout(load_layout(sim.config_path)).systems["foot"]
    foot.set_smoothed(res.x, res.pos_var, res.diagnostics)
    assert foot.diagnostics()["smoothing"]["warnings"] == 1
    np.testing.assert_array_equal(foot.trajectory().pos_n, foot.hist_x[:, 0:3])


# --------------------------------------------------------------------------- config


@pytest.mark.parametrize("kind", ["none", "rts", "fixed-lag", "fb", "fb-rts"])
def test_smoother_kind_accepted(kind):
    assert load_layout(VICON_CFG, [f"smoother.kind={kind}"]).layout.smoother.kind == kind


def test_span_names_what_runs():
    smoother = load_layout(VICON_CFG, ["smoother.kind=rts"]).layout.smoother
    assert smoother.span is None and not smoother.segmented  # rts: the whole run
    assert load_layout(VICON_CFG, ["smoother.kind=rts", "smoother.span=segment"]).layout.smoother.segmented
    assert load_layout(VICON_CFG, ["smoother.kind=fb", "smoother.span=segment"]).layout.smoother.segmented
    assert load_layout(VICON_CFG, ["smoother.kind=fb-rts"]).layout.smoother.segmented


@pytest.mark.parametrize("override,key", [("smoother.kind=fbrts", "smoother.kind"),
                                          ("smoother.span=all", "smoother.span"),
                                          ("smoother.lag_s=0", "smoother.lag_s"),
                                          ("smoother.colour=red", "smoother.colour")])
def test_bad_smoother_settings_are_refused_with_the_key_path(override, key):
    with pytest.raises(ConfigError) as ei:
        load_layout(VICON_CFG, [override])
    assert key in str(ei.value)


@pytest.mark.parametrize("kind", ["fb", "fb-rts", "fixed-lag"])
def test_whole_run_span_is_refused_for_the_segmented_kinds(kind):
    with pytest.raises(ConfigError) as ei:
        load_layout(VICON_CFG, [f"smoother.kind={kind}", "smoother.span=whole"])
    assert "smoother.span" in str(ei.value) and "per segment" in str(ei.value)


def test_a_smoothed_track_carries_the_smoothed_velocity_and_attitude_without_their_sigma(walk):
    """The smoothers keep the position block of the covariance only: a smoothed trajectory's
    velocity and attitude are the smoothed states, and it gives no σ for them (not the filter's)."""
    sim, _, _ = walk
    result = run_layout(load_layout(sim.config_path, ["smoother.kind=rts"]))
    foot = result.systems["foot"]
    traj = result.trajectories["foot"]
    assert traj.motion_cov is None
    np.testing.assert_array_equal(traj.vel_n, foot.smoothed_x[:, 3:6])
    np.testing.assert_array_equal(traj.q_nb, foot.smoothed_x[:, 6:10])


# --------------------------------------------------------------------------- fixed lag


def test_lag_windows_reach_the_lag_past_each_segment_or_the_runs_end():
    t = np.arange(1000) * 0.01
    bounds = np.array([0, 90, 200, 310, 420, 999])
    ends = lag_windows(t, bounds, 1.5)
    np.testing.assert_array_equal(ends, [3, 4, 5, 5, 5])  # 0.9 + 1.5 → 3.1 s: bound 3; 2.0 + 1.5 → 4.2 s: bound 4
    assert np.all(t[bounds[ends]] >= np.minimum(t[bounds[1:]] + 1.5, t[-1]))
    np.testing.assert_array_equal(lag_windows(t, bounds, 1e-6), [2, 3, 4, 5, 5])  # any lag reaches past the segment


def test_a_fixed_lag_longer_than_the_run_is_the_whole_run_rts(walk):
    _, rec, _ = walk
    whole = smooth_record(rec, SmootherConfig(kind="rts"))
    lag = smooth_record(rec, SmootherConfig(kind="fixed-lag", lag_s=1e3))
    np.testing.assert_allclose(lag.x, whole.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(lag.pos_var, whole.pos_var, rtol=1e-9, atol=1e-15)


def test_the_fixed_lag_estimate_of_a_stride_uses_no_data_past_its_window(walk):
    """Change every filter state and IMU sample after the window of one stride: that stride's
    smoothed states stay the same bits, the strides after it change (what a live run emits
    once the lag has passed is final)."""
    _, rec, _ = walk
    cfg = SmootherConfig(kind="fixed-lag", lag_s=1.0)
    bounds = segment_bounds(rec["stance"], rec["rate_hz"], cfg.min_stance_s, cfg.max_segment_s)
    ends = lag_windows(rec["t"], bounds, cfg.lag_s)
    k = bounds.size // 2
    a, b, w = bounds[k], bounds[k + 1], bounds[ends[k]]
    later = dict(rec)
    for key in ("hist_x", "acc", "gyro"):
        later[key] = rec[key].copy()
        later[key][w + 1:, :3] += 0.5
    before, after = smooth_record(rec, cfg), smooth_record(later, cfg)
    assert before.x[a:b].tobytes() == after.x[a:b].tobytes()
    assert before.pos_var[a:b].tobytes() == after.pos_var[a:b].tobytes()
    assert not np.array_equal(before.x[w + 1:], after.x[w + 1:])
    lag = before.diagnostics["lag_s"]
    assert lag["min"] >= cfg.lag_s and lag["median"] < lag["max"] and lag["tail_s"] > 0


def test_fixed_lag_closes_the_gap_to_the_whole_run_rts_as_the_lag_grows(walk):
    _, rec, pos = walk
    whole = smooth_record(rec, SmootherConfig(kind="rts")).x[:, :3]
    gaps = [np.sqrt(np.mean(np.sum((smooth_record(rec, SmootherConfig(kind="fixed-lag", lag_s=lag)).x[:, :3]
                                    - whole) ** 2, axis=1))) for lag in (0.5, 2.0, 8.0, 1e3)]
    assert gaps[0] > gaps[1] > gaps[2] > gaps[3] and gaps[3] < 1e-9, gaps
