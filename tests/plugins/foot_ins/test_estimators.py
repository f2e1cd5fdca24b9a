"""The foot INS estimators beside the EKF: ckf (coloured-noise ZUPT), enekf and cenekf
(ensembles), and the simulator's coloured stance noise.

Most runs use the first 30 s of the vendored dual-foot Vicon walk (copied to a temporary
folder) to stay fast.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import load_layout
from bodyfusion.core.layout_io import read_yaml
from bodyfusion.runner import build_systems, layout_context, run_layout
from bodyfusion.nav.error_state import FilterParams, accumulate_propagation, filter_params, process_noise_diag
from bodyfusion.plugins.foot_ins import FootIns
from bodyfusion.plugins.foot_ins.coloured import (
    coloured_zero_velocity_update,
    velocity_rows_of_inverse_transition,
)
from bodyfusion.plugins.foot_ins.kernels import (C_CALL_RECORDS, C_COLOURED, C_ZUPTS, COUNTERS_SIZE,
                                                 run_foot_ins, run_foot_ins_coloured)
from bodyfusion.plugins.foot_ins.records import (RECORDED_COVARIANCE, FilterHistory, FilterState, ImuSamples,
                                                 StepScratch, no_record)
from bodyfusion.testing import check_system, default_context, random_nominal_state, with_value
from tests.paths import ROOT

VICON_CFG = ROOT / "configs" / "dual_foot_vicon.yaml"
VICON_DATA = ROOT / "examples" / "data" / "dual_foot_vicon_hu2025"
SCENARIO = ROOT / "configs" / "sim_dual_foot_coloured_stance.yaml"
FEET = ("left_foot", "right_foot")
SLICE_ROWS = 1800  # 30 s at 60 Hz


def kind_overrides(kind: str, alpha: float = 0.9) -> list[str]:
    out = [f"systems.{f}.filter.kind={kind}" for f in FEET]
    if kind in ("ckf", "cenekf"):
        out += [f"systems.{f}.filter.colour_factor={alpha}" for f in FEET]
    return out


@pytest.fixture(scope="module")
def vicon_slice(tmp_path_factory) -> dict[str, Path]:
    """The first 30 s of the Vicon walk: both IMU files and the truth."""
    folder = tmp_path_factory.mktemp("vicon_slice")
    out = {}
    for name in ("imuMeasLeft.csv", "imuMeasRight.csv", "positionGt.csv"):
        lines = (VICON_DATA / name).read_text().splitlines()
        (folder / name).write_text("\n".join(lines[:SLICE_ROWS + 1]) + "\n")
        out[name] = folder / name
    return out


def slice_overrides(paths: dict[str, Path]) -> list[str]:
    return [f"systems.left_foot.data.path={paths['imuMeasLeft.csv']}",
            f"systems.right_foot.data.path={paths['imuMeasRight.csv']}",
            f"truth.path={paths['positionGt.csv']}"]


def left_foot(paths: dict[str, Path], overrides: list[str]) -> FootIns:
    loaded = load_layout(VICON_CFG, [*slice_overrides(paths), *overrides])
    return build_systems(loaded, layout_context(loaded))["left_foot"]


# --------------------------------------------------------------------------- ckf


def test_inverse_transition_rows_are_exact():
    C = Rotation.random(random_state=3).as_matrix()
    f_n = np.array([0.4, -2.0, 9.6])
    dt = 0.02
    F = np.eye(15)
    accumulate_propagation(F, C, f_n, dt)
    rows = np.empty((3, 15))
    velocity_rows_of_inverse_transition(C, f_n, dt, rows)
    np.testing.assert_allclose(rows, np.linalg.inv(F)[3:6], atol=1e-15)


def walk_params(zupt_sigma: float) -> FilterParams:
    """The filter's parameters: the default densities, ZUPT σ (m/s), no ZARU, g = 9.8 m/s², no
    Earth rate, no gate, random-walk biases."""
    return filter_params(acc_noise_density=0.02, gyro_noise_density=0.002, acc_bias_walk=1e-4, gyro_bias_walk=1e-5,
                         zupt_sigma=zupt_sigma, gravity=9.8)


def test_coloured_update_matches_the_dense_equations():
    """Kernel against eqs. 7–12 written densely: H̄ = H − αHF⁻¹ with the heading column that
    hides a rotation about Up (−(1 − α) e_z × v̂), θ = Q T̄ᵀ, correlated-noise gain, then the
    reset G = I + (e_z × δv̂) e_ψᵀ of bodyfusion.nav.error_state.keep_yaw_unobservable."""
    rng = np.random.default_rng(0)
    A = rng.normal(0, 0.1, (15, 15))
    P = A @ A.T + 1e-4 * np.eye(15)
    C = Rotation.random(random_state=1).as_matrix()
    f_n = np.array([0.2, 0.1, 9.8])
    dt, alpha, sigma = 0.01, 0.7, 0.005
    q = process_noise_diag(walk_params(sigma))
    x = np.zeros(16)
    x[3:6] = [0.01, -0.02, 0.005]
    x[6] = 1.0
    v_prev = np.array([0.008, -0.01, 0.0])
    F = np.eye(15)
    accumulate_propagation(F, C, f_n, dt)
    H = np.zeros((3, 15))
    H[:, 3:6] = np.eye(3)
    T = alpha * H @ np.linalg.inv(F)
    Hb = H - T
    Hb[:, 8] = -(1.0 - alpha) * np.cross([0.0, 0.0, 1.0], x[3:6])
    Q = np.diag(q[:15] * dt)
    theta = Q @ T.T
    Rb = T @ theta + sigma**2 * np.eye(3)
    S = Hb @ P @ Hb.T + Rb + Hb @ theta + theta.T @ Hb.T
    K = (P @ Hb.T + theta) @ np.linalg.inv(S)
    y = alpha * v_prev - x[3:6]
    E = np.eye(15) - K @ Hb
    G = np.eye(15)
    G[3:6, 8] = np.cross([0.0, 0.0, 1.0], (K @ y)[3:6])
    P_want = G @ (E @ P @ E.T + K @ Rb @ K.T - E @ theta @ K.T - K @ theta.T @ E.T) @ G.T
    P_got = P.copy()
    dx = np.empty(15)
    phi = np.eye(15)
    step = StepScratch(q, f_n, C, np.empty((15, 15)), dx)
    nis = coloured_zero_velocity_update(FilterState(x.copy(), P_got, np.zeros(6), phi), v_prev, step, dt, alpha, sigma,
                                        0.0)
    np.testing.assert_allclose(dx, K @ y, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(P_got, P_want, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(phi, G @ E, rtol=1e-12, atol=1e-15)
    assert nis == pytest.approx(y @ np.linalg.solve(S, y), rel=1e-9)


def test_ckf_first_stance_sample_takes_the_stationary_noise():
    """A stance phase's first sample has no previous measurement to difference with: the ckf
    applies the ordinary ZUPT with the stationary variance σ_ξ² / (1 − α²) of the AR(1) noise
    v_k = α v_{k−1} + ξ_k, not σ_ξ², and records its covariance for the smoothers."""
    rng = np.random.default_rng(7)
    t = np.array([0.0, 0.01])
    acc, gyro = np.array([[0.0, 0.0, 9.8], [0.3, -0.2, 9.9]]), np.array([[0.0, 0.0, 0.0], [0.02, -0.01, 0.03]])
    stance = np.array([False, True])
    x0 = random_nominal_state(rng)
    x0[3:6] = [0.02, -0.01, 0.005]
    A = rng.normal(0, 0.03, (15, 15))
    P0 = A @ A.T + 1e-6 * np.eye(15)
    alpha, sigma = 0.9, 0.005
    params = walk_params(sigma)

    def run(kernel, sigma_ekf: float | None = None):
        x, P = x0.copy(), P0.copy()
        hist_x, hist_cov, hist_nis, counters = np.zeros((2, 16)), np.zeros((2, RECORDED_COVARIANCE)), np.zeros(2), np.zeros(COUNTERS_SIZE)
        if sigma_ekf is None:
            post_idx, post_P = np.zeros(1, dtype=np.int64), np.zeros((1, 15, 15))
            kernel(FilterState(x, P, np.zeros(6), np.empty((0, 0))), ImuSamples(t, acc, gyro, stance), 1, 2, params,
                   alpha, FilterHistory(hist_x, hist_cov, hist_nis, counters), post_idx, post_P)
            return x, P, counters, post_idx, post_P
        kernel(FilterState(x, P, np.zeros(6), np.empty((0, 0))), ImuSamples(t, acc, gyro, stance), 1, 2,
               walk_params(sigma_ekf), FilterHistory(hist_x, hist_cov, hist_nis, counters), no_record())
        return x, P

    x, P, counters, post_idx, post_P = run(run_foot_ins_coloured)
    x_want, P_want = run(run_foot_ins, sigma / np.sqrt(1.0 - alpha**2))
    np.testing.assert_allclose(P, P_want, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(x, x_want, rtol=1e-12, atol=1e-15)
    _, P_driving = run(run_foot_ins, sigma)
    assert not np.allclose(P, P_driving, rtol=1e-3, atol=0)
    assert counters[C_ZUPTS] == 1 and counters[C_COLOURED] == 0
    assert counters[C_CALL_RECORDS] == 1 and post_idx[0] == 1
    np.testing.assert_array_equal(post_P[0], P)


@pytest.mark.parametrize("method", ["none", "projection"])
def test_ckf_with_colour_factor_zero_reproduces_the_ekf(method):
    ekf = run_layout(load_layout(VICON_CFG, [f"fuser.method={method}"]))
    ckf = run_layout(load_layout(VICON_CFG, [f"fuser.method={method}", *kind_overrides("ckf", 0.0)]))
    for foot in FEET:
        a, b = ekf.systems[foot], ckf.systems[foot]
        assert b.diagnostics()["coloured_updates"] > 1000
        assert np.max(np.abs(a.hist_x - b.hist_x)) <= 1e-9
        assert np.max(np.abs(a.P - b.P)) <= 1e-9


def test_ckf_is_smoothed_with_its_own_covariances(vicon_slice):
    res = run_layout(load_layout(VICON_CFG, [*slice_overrides(vicon_slice), *kind_overrides("ckf"),
                                             "smoother.kind=rts"]))
    for foot in FEET:
        diag = res.systems[foot].diagnostics()["smoothing"]
        assert diag["warnings"] == 0
        assert diag["covariance_rebuild_rel_error"] < 1e-9
        assert np.isfinite(res.scores[foot].metrics["horizontal_error_m"]["rmse"])


# --------------------------------------------------------------------------- ensembles


@pytest.mark.parametrize("kind", ["enekf", "cenekf"])
def test_ensemble_same_seed_same_bits_other_seed_differs(vicon_slice, kind):
    def run(seed):
        loaded = load_layout(VICON_CFG, [*slice_overrides(vicon_slice), *kind_overrides(kind)])
        s = build_systems(loaded, layout_context(loaded, seed))["left_foot"]
        s.advance(s.t_start + 10.0)
        return s

    a, b, c = run(3), run(3), run(4)
    assert a.hist_x[: a._i + 1].tobytes() == b.hist_x[: b._i + 1].tobytes()
    assert a.filter.ensemble.ens.tobytes() == b.filter.ensemble.ens.tobytes()
    assert a.hist_x[: a._i + 1].tobytes() != c.hist_x[: c._i + 1].tobytes()


@pytest.mark.parametrize("kind", ["enekf", "cenekf"])
def test_ensemble_quaternions_stay_unit(vicon_slice, kind):
    s = left_foot(vicon_slice, kind_overrides(kind))
    s.advance(s.t_end)
    q_members = s.filter.ensemble.ens[:, 6:10]
    assert np.max(np.abs(np.linalg.norm(q_members, axis=1) - 1.0)) < 1e-12
    assert np.max(np.abs(np.linalg.norm(s.hist_x[:, 6:10], axis=1) - 1.0)) < 1e-12
    assert s.P.shape == ((18, 18) if kind == "cenekf" else (15, 15))


@pytest.mark.parametrize("kind", ["enekf", "cenekf"])
def test_ensemble_correction_moves_the_mean_and_sets_the_covariance(vicon_slice, kind):
    s = left_foot(vicon_slice, kind_overrides(kind))
    s.advance(s.t_start + 12.0)
    x0, P0 = s.x.copy(), s.covariance()
    n = P0.shape[0]
    rng = np.random.default_rng(2)
    dx = np.zeros(n)
    dx[0:3] = [0.2, -0.1, 0.05]
    dx[3:6] = rng.normal(0, 1e-3, 3)
    dx[6:9] = rng.normal(0, 1e-3, 3)
    # a fuser-shaped update, (I − P_xp G) P (I − P_xp G)ᵀ: it keeps the directions the
    # members do not span (after a cenekf ZUPT, v + V has no spread)
    G = rng.normal(size=(3, n)) / np.sqrt(np.diag(P0)[0:3])[:, None] / np.sqrt(np.diag(P0))[None, :] * 0.1
    B = np.eye(n) - P0[:, 0:3] @ G
    P_new = B @ P0 @ B.T
    s.apply_correction(dx, P_new)
    np.testing.assert_array_equal(s.position_n(), x0[0:3] + dx[0:3])
    np.testing.assert_array_equal(s.covariance(), 0.5 * (P_new + P_new.T))
    # the members themselves: their mean at x + dx, their sample covariance P
    mean = s.filter.ensemble.ens.mean(axis=0)
    np.testing.assert_allclose(mean[0:6], x0[0:6] + dx[0:6], rtol=0, atol=1e-12)
    P_members = s.filter.ensemble.covariance()
    scale = np.sqrt(np.outer(np.diag(P_new), np.diag(P_new)))
    assert np.max(np.abs(P_members - P_new) / scale) < 1e-6


def test_ensemble_refuses_cross_covariance_tracking_at_run_time(vicon_slice):
    s = left_foot(vicon_slice, kind_overrides("enekf"))
    with pytest.raises(Exception, match="cannot track cross-covariances"):
        s.track_transition()


@pytest.mark.parametrize("kind", ["ekf", "ckf", "enekf", "cenekf"])
@pytest.mark.parametrize("method", ["projection", "qp", "socp"])
def test_every_kind_runs_with_every_fuser_method(vicon_slice, kind, method):
    res = run_layout(load_layout(VICON_CFG, [*slice_overrides(vicon_slice), *kind_overrides(kind),
                                             f"fuser.method={method}"]))
    assert res.fuser.epochs > 10
    for foot in FEET:
        rmse = res.scores[foot].metrics["horizontal_error_m"]["rmse"]
        assert np.isfinite(rmse) and rmse < 2.0


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize("override,key", [
    ("systems.left_foot.filter.colour_factor=1.0", "systems.left_foot.filter.colour_factor"),
    ("systems.left_foot.filter.colour_factor=-0.1", "systems.left_foot.filter.colour_factor"),
    ("systems.left_foot.filter.members=1", "systems.left_foot.filter.members"),
])
def test_bad_estimator_parameters_are_refused_with_their_key(override, key):
    with pytest.raises(ConfigError) as ei:
        load_layout(VICON_CFG, ["systems.left_foot.filter.kind=cenekf", override])
    assert ei.value.key == key


def test_colour_factor_needs_a_coloured_kind():
    with pytest.raises(ConfigError) as ei:
        load_layout(VICON_CFG, ["systems.left_foot.filter.colour_factor=0.5"])
    assert ei.value.key == "systems.left_foot.filter.colour_factor"


@pytest.mark.parametrize("override,key", [("smoother.kind=rts", "smoother.kind"),
                                          ("fuser.cross_covariance=true", "fuser.cross_covariance")])
def test_ensemble_refuses_smoothing_and_cross_covariances_at_validation(override, key):
    with pytest.raises(ConfigError) as ei:
        load_layout(VICON_CFG, ["systems.right_foot.filter.kind=enekf", override])
    assert ei.value.key == key
    assert "right_foot" in ei.value.reason


def test_fusion_validate_prints_one_line_for_colour_factor_one():
    proc = subprocess.run([sys.executable, "-m", "bodyfusion.cli", "validate", str(VICON_CFG), "--set",
                           "systems.left_foot.filter.kind=ckf", "--set", "systems.left_foot.filter.colour_factor=1"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "systems.left_foot.filter.colour_factor" in lines[0]


# --------------------------------------------------------------------------- conformance


@pytest.mark.parametrize("kind", ["ckf", "enekf", "cenekf"])
def test_every_kind_conforms(vicon_slice, kind):
    foot = read_yaml(VICON_CFG)["systems"]["left_foot"]
    foot = with_value(foot, "data.path", str(vicon_slice["imuMeasLeft.csv"]))
    foot = with_value(foot, "filter.kind", kind)
    if kind != "enekf":
        foot = with_value(foot, "filter.colour_factor", 0.9)
    ensemble = kind != "ckf"
    if ensemble:
        foot = with_value(foot, "filter.members", 40)
    report = check_system(
        FootIns, foot, name="left_foot", context=default_context(VICON_CFG.parent), stochastic=ensemble, chunks=3,
        bad_configs=[(with_value(foot, "filter.colour_factor", 1.0), "filter.colour_factor"),
                     (with_value(foot, "filter.members", 1), "filter.members")])
    assert report.failed == []
    assert report.skipped == (["cross_covariance"] if ensemble else [])


# --------------------------------------------------------------------------- simulation


def test_stance_noise_moves_the_truth_and_the_imu_consistently():
    from bodyfusion.nav.strapdown import integrate
    from bodyfusion.sim.foot_motion import stance_drift
    from bodyfusion.sim.gait import plan_gait
    from bodyfusion.sim.gait_config import StanceNoiseConfig
    from bodyfusion.sim.imu import ideal_imu
    from bodyfusion.sim.scenario import load_scenario

    loaded = load_scenario(SCENARIO)
    plan = plan_gait(loaded.path.build(), loaded.scenario.gait, 100.0)
    t = plan.t[:900]
    foot = plan.feet["left"]
    drift = stance_drift(foot, plan.t.size, StanceNoiseConfig(colour_factor=0.9, sigma_mps=0.005),
                         np.random.default_rng(0))
    g = 9.80665
    residual = []
    for motion in (foot, drift):
        acc, gyro = ideal_imu(motion, t, g)
        state = motion.evaluate(t)
        x0 = np.zeros(16)
        x0[0:3], x0[3:6], x0[6:10] = state.pos[0], state.vel[0], state.q_nb[0]
        residual.append(np.abs(integrate(x0, t, acc, gyro, g, np.zeros(3))[:, 0:3] - state.pos).max())
    assert residual[1] == pytest.approx(residual[0], abs=1e-5)  # the drift adds no inconsistency
    stance = foot.stance_flags(plan.t.size)
    moved = drift.evaluate(plan.t)
    assert np.abs(moved.pos - foot.evaluate(plan.t).pos).max() > 1e-3
    v = moved.vel[stance]
    assert 0.005 < v.std() < 0.02
    east = drift.vel[:, 0]
    pairs = (east[1:] != 0) & (east[:-1] != 0)
    lag1 = np.sum(east[1:][pairs] * east[:-1][pairs]) / np.sum(east[:-1][pairs] ** 2)
    assert lag1 == pytest.approx(0.9, abs=0.05)
    np.testing.assert_array_equal(moved.vel[~stance], foot.evaluate(plan.t).vel[~stance])


def test_simulated_stance_noise_is_seeded_and_scored(tmp_path):
    from bodyfusion.sim import simulate

    a = simulate(SCENARIO, tmp_path / "a", seed=5, overrides=["path.length_m=6", "path.width_m=3"])
    simulate(SCENARIO, tmp_path / "b", seed=5, overrides=["path.length_m=6", "path.width_m=3"])
    for name in ("left_foot_imu.csv", "truth.csv"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    res = run_layout(load_layout(a.config_path, kind_overrides("ckf")))
    for foot in FEET:
        assert res.scores[foot].metrics["horizontal_error_m"]["rmse"] < 0.5


class _Step:
    """An estimator's step that moves its state and says where it ran."""

    def __init__(self) -> None:
        self.moved_in: list[int] = []

    def run(self, data, i0: int, i1: int, phi) -> None:
        import os

        self.moved_in.append(os.getpid())


def test_a_first_runs_step_is_compiled_ahead_in_a_copy_and_never_here():
    import threading
    from types import SimpleNamespace

    from bodyfusion.plugins.foot_ins.estimators import compile_step_ahead

    step, data, ahead = _Step(), SimpleNamespace(t=np.zeros(5)), {}
    compile_step_ahead(step, data, np.empty((0, 0)), ahead)
    assert len(ahead) == 1
    forked = next(iter(ahead.values()))
    compile_step_ahead(_Step(), data, np.empty((0, 0)), ahead)
    assert list(ahead.values()) == [forked]  # one per estimator class
    forked.result()
    assert step.moved_in == []  # taken in the copy: this process's state did not move
    compile_step_ahead(step, data, np.empty((0, 0)), None)  # not a first run: nothing to do
    gate = threading.Event()
    other = threading.Thread(target=gate.wait)
    other.start()
    beside: dict = {}
    try:  # beside another thread: no fork, and the step is not taken here instead
        compile_step_ahead(step, data, np.empty((0, 0)), beside)
    finally:
        gate.set()
        other.join()
    assert beside == {} and step.moved_in == []


@pytest.mark.parametrize("kind", ["ekf", "ckf", "enekf", "cenekf"])
def test_every_filter_records_its_velocity_and_attitude_covariance_with_the_state(vicon_slice, kind):
    """The history's row after the last sample holds P's velocity variances and attitude block
    (RECORDED_COVARIANCE; for an ensemble, the members' spread), and the trajectory hands them on."""
    s = left_foot(vicon_slice, kind_overrides(kind))
    s.advance(s.t_start + 12.0)
    P = s.covariance()
    expected = [P[3, 3], P[4, 4], P[5, 5], P[6, 6], P[7, 7], P[8, 8], P[6, 7], P[6, 8], P[7, 8]]
    np.testing.assert_allclose(s.hist_cov[s._i, 4:], expected, rtol=1e-9, atol=1e-18)
    traj = s.trajectory()
    np.testing.assert_array_equal(traj.motion_cov[-1], s.hist_cov[s._i, 4:])
    attitude = traj.motion_cov[:, 3:6]
    assert np.all(np.isfinite(traj.motion_cov)) and np.all(attitude > 0) and np.all(traj.motion_cov[:, :3] >= 0)
