"""Simulator: paths, gait, ideal IMU against the mechanisation, error model, scenario files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from bodyfusion.base.errors import ConfigError, FusionError
from bodyfusion.core.layout import Layout
from bodyfusion.core.layout_io import validate_section
from bodyfusion.base.seeding import stable_hash
from bodyfusion.io.imu import read_imu_csv
from bodyfusion.nav.attitude import azimuth_pitch_roll
from bodyfusion.nav.strapdown import integrate
from bodyfusion.plugins.foot_ins.config import FootInsConfig
from bodyfusion.sim import simulate
from bodyfusion.sim.gait import plan_gait
from bodyfusion.sim.gait_config import GaitConfig
from bodyfusion.sim.imu import (
    ImuErrorConfig,
    MotionState,
    SensorErrors,
    corrupt,
    dcm_from_quat,
    error_generators,
    ideal_imu,
)
from bodyfusion.sim.paths import (
    LoopsPath,
    OutAndBackPath,
    PolylinePath,
    RectanglePath,
    SquarePath,
)
from tests.paths import CONFIGS

G = 9.80665
SHIPPED = ["sim_dual_foot_square.yaml", "sim_perfect_walk.yaml"]


# --------------------------------------------------------------------------- helpers


def _walk(rate: float, waypoints=((0.0, 0.0), (0.0, 14.0), (12.0, 14.0)), mount_yaw_deg: float = 7.0, **gait):
    """A short walk with a right turn; returns (t, motion of the left IMU, plan)."""
    path = PolylinePath(kind="polyline", waypoints_m=list(waypoints), turn_radius_m=0.5).build()
    plan = plan_gait(path, GaitConfig(**gait), rate)
    return plan.t, plan.feet["left"].mounted(mount_yaw_deg), plan


def _free_inertial(t, motion):
    """Position error (N, 3) of unaided bodyfusion.nav.strapdown.integrate of the ideal IMU."""
    acc, gyro = ideal_imu(motion, t, G)
    truth = motion.evaluate(t)
    x0 = np.zeros(16)
    x0[0:3] = truth.pos[0]
    x0[6:10] = truth.q_nb[0]
    out = integrate(x0, t, acc, gyro, G, np.zeros(3))
    return out[:, 0:3] - truth.pos


def _one_stride_and_20s(t, motion, plan, rate):
    """Sample indices: end of the first full stride (second swing), and 20 s after walking starts."""
    return int(motion.k_end[1]), int(round((plan.start_still_s + 20.0) * rate))


def _write_scenario(tmp_path: Path, text: str, name: str = "scn.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


SHORT = """
name: short
rate_hz: 100
path: {kind: polyline, waypoints_m: [[0, 0], [0, 5], [4, 5]]}
gait: {start_still_s: 1, end_still_s: 0.5}
systems:
  left_foot:  {kind: foot_imu, foot: left,  imu: {preset: icm20948}}
  right_foot: {kind: foot_imu, foot: right, imu: {preset: icm20948, acc_bias_sd_mps2: 0.05}, mount_yaw_deg: 7}
"""


# --------------------------------------------------------------------------- ideal IMU


def test_ideal_imu_at_rest_reads_gravity_and_no_rate():
    t, motion, plan = _walk(100.0)
    acc, gyro = ideal_imu(motion, t, G)
    still = slice(0, plan.feet["left"].k_start[0] + 1)
    np.testing.assert_allclose(acc[still], np.tile([0.0, 0.0, G], (still.stop, 1)), atol=1e-12)
    np.testing.assert_allclose(gyro[still], 0.0, atol=1e-15)
    assert np.abs(acc[still.stop + 2] - [0, 0, G]).max() > 1e-3  # and it does move afterwards


class _YawTurn:
    """Standing still, turning from azimuth a0 by da (rad) over [1, 3] s with a smooth profile."""

    def __init__(self, a0: float, da: float) -> None:
        self.a0, self.da = a0, da

    def evaluate(self, t):
        tau = np.clip((np.asarray(t, float) - 1.0) / 2.0, 0.0, 1.0)
        u = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
        du = (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / 2.0
        yaw = 0.5 * np.pi - (self.a0 + self.da * u)
        q = np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=-1)
        z = np.zeros((tau.size, 3))
        omega = z.copy()
        omega[:, 2] = -self.da * du
        return MotionState(pos=z.copy(), vel=z.copy(), acc=z.copy(), q_nb=q, omega_n=omega)


def test_pure_yaw_turn_integrates_to_the_right_heading():
    t = np.arange(0, 401) / 100.0
    motion = _YawTurn(math.radians(20.0), math.radians(-135.0))
    acc, gyro = ideal_imu(motion, t, G)
    np.testing.assert_allclose(acc, np.tile([0, 0, G], (t.size, 1)), atol=1e-12)
    x0 = np.zeros(16)
    x0[6:10] = motion.evaluate(t[:1]).q_nb[0]
    out = integrate(x0, t, acc, gyro, G, np.zeros(3))
    az = azimuth_pitch_roll(out[-1, 6:10])[0]
    assert math.degrees(az) == pytest.approx(360.0 - 115.0, abs=1e-9)
    assert np.abs(out[:, 0:6]).max() < 1e-12


def test_free_inertial_integration_follows_truth():
    """3-D, 100 Hz, bodyfusion.nav.strapdown.integrate of the ideal IMU with no aiding: < 1 mm
    after one stride, < 5 cm after 20 s of walking (with a 90° turn and a 7° mounting yaw)."""
    rate = 100.0
    t, motion, plan = _walk(rate)
    err = _free_inertial(t, motion)
    k_stride, k_20 = _one_stride_and_20s(t, motion, plan, rate)
    assert np.linalg.norm(err[k_stride]) < 1e-3
    assert np.linalg.norm(err[k_20]) < 0.05


def test_free_inertial_error_is_a_truncation_error_that_shrinks_with_dt():
    """What is left falls at least as dt³ from 100 Hz to 200 Hz (measured: about dt⁴): a
    truncation error of the two-sample mechanisation, not an inconsistency of the simulated
    IMU (that would not shrink with dt)."""
    errs = {}
    for rate in (100.0, 200.0):
        t, motion, plan = _walk(rate)
        k_stride, k_20 = _one_stride_and_20s(t, motion, plan, rate)
        errs[rate] = np.linalg.norm(_free_inertial(t, motion)[[k_stride, k_20]], axis=1)
    assert np.all(errs[100.0] / errs[200.0] > 8.0), errs


# --------------------------------------------------------------------------- paths and gait


def test_paths_are_arc_length_parametrised_and_headings_follow_the_tangent():
    for cfg in (
        SquarePath(kind="square", side_m=6, laps=2, clockwise=True, start_heading_deg=30),
        RectanglePath(kind="rectangle", length_m=8, width_m=3, clockwise=False),
        LoopsPath(kind="loops", radius_m=3, laps=1.5),
        OutAndBackPath(kind="out_and_back", length_m=5, repeats=2),
        PolylinePath(kind="polyline", waypoints_m=[(0, 0), (3, 4), (3, 9), (-2, 9)], turn_radius_m=1.0),
    ):
        path = cfg.build()
        s = np.linspace(0, path.length, 20001)
        xy, az = path.at(s)
        d = np.diff(xy, axis=0)
        step = np.hypot(d[:, 0], d[:, 1])
        np.testing.assert_allclose(step, s[1] - s[0], rtol=1e-6)
        travel = np.arctan2(d[:, 0], d[:, 1])
        mid = 0.5 * (az[1:] + az[:-1])
        assert np.abs(np.angle(np.exp(1j * (travel - mid)))).max() < 1e-3  # O(ds/r) where a step straddles line→arc
        assert np.abs(np.diff(az)).max() < 1e-2  # no heading jumps (corners are rounded)
    sq = SquarePath(kind="square", side_m=10, laps=2, clockwise=True, turn_radius_m=0.5).build()
    start, end = sq.start, sq.end
    np.testing.assert_allclose(end[0], start[0], atol=1e-9)
    assert end[1] - start[1] == pytest.approx(4 * math.pi - math.pi / 2)  # 7 right turns
    assert sq.closed
    corner_saving = 2 * 0.5 - 0.5 * math.pi / 2
    assert sq.length == pytest.approx(80 - 7 * corner_saving)
    xy, _ = sq.at(np.array([10.0 - 0.5, 10.0 + 0.5 * math.pi / 2 + 5.0]))
    assert xy[1, 0] > 4.9  # clockwise from North: the second leg goes East


def test_gait_stance_flags_are_exactly_the_still_samples_and_durations_as_configured():
    rate = 100.0
    gait = dict(stride_m=1.4, cadence_steps_per_min=108, stance_fraction=0.6, start_still_s=3, end_still_s=2)
    t, _, plan = _walk(rate, **gait)
    cycle = 120.0 / 108
    for foot in ("left", "right"):
        m = plan.feet[foot]
        st = m.evaluate(t)
        speed = np.linalg.norm(st.vel, axis=1)
        rate_norm = np.linalg.norm(st.omega_n, axis=1)
        flags = m.stance_flags(t.size)
        np.testing.assert_array_equal(flags, speed < 1e-9)
        assert np.all(rate_norm[flags] == 0.0)
        # Interior stance periods and swings, from the flags alone.
        edges = np.flatnonzero(np.diff(flags.astype(int)))
        runs = np.diff(np.concatenate([[-1], edges, [t.size - 1]]))
        values = flags[np.concatenate([[0], edges + 1])]
        swings = (runs[~values] + 1) / rate  # a swing of n intervals has n−1 moving samples
        stances = (runs[values][1:-1] - 1) / rate  # a stance from k_end to k_start spans runs−1 intervals
        assert np.all(np.abs(swings - cycle * 0.4) <= 0.5 / rate + 1e-12)
        assert np.all(np.abs(stances - cycle * 0.6) <= 1.0 / rate + 1e-12)
        assert flags[: int(3 * rate) + 1].all() and flags[-int(2 * rate) - 1:].all()
        # Flat and still during stance.
        apr = azimuth_pitch_roll(st.q_nb[flags])
        np.testing.assert_allclose(apr[1:], 0.0, atol=1e-12)
        np.testing.assert_allclose(st.pos[flags, 2], 0.0, atol=1e-12)
    # The feet never farther apart than stride + lateral offset, start and end side by side.
    tf = np.linspace(0, t[-1], 40 * t.size)
    pl, pr = plan.feet["left"].evaluate(tf).pos, plan.feet["right"].evaluate(tf).pos
    sep = np.linalg.norm((pl - pr)[:, :2], axis=1)
    assert sep.max() <= 1.4 + 0.1
    assert sep[0] == pytest.approx(0.2) and sep[-1] == pytest.approx(0.2)


def test_swing_is_smooth_at_both_ends():
    _, motion, plan = _walk(100.0)
    for ts in (motion.t_start[2], motion.t_end[2]):
        st = motion.evaluate(np.array([ts - 1e-4, ts + 1e-4]))
        assert np.abs(st.vel).max() < 1e-5 and np.abs(st.acc).max() < 1e-3
        assert np.abs(st.omega_n).max() < 1e-3
    # Peak toe pitch equals the configured amplitude, lift as configured.
    tf = np.linspace(motion.t_start[2], motion.t_end[2], 2001)
    st = motion.evaluate(tf)
    C = dcm_from_quat(st.q_nb)
    x_up = C[:, 2, 0] * math.cos(math.radians(7)) + C[:, 2, 1] * math.sin(math.radians(7))
    toe = np.degrees(np.arcsin(np.clip(x_up, -1, 1)))  # toe elevation of the foot's own axis
    assert toe.min() == pytest.approx(-30, abs=0.05) and toe.max() == pytest.approx(30, abs=0.05)
    assert st.pos[:, 2].max() == pytest.approx(0.1, abs=1e-4)


def test_pulse_profile_of_the_fbrts_paper():
    """One foot: 1 s move, 1 s still, no pitch, no lift."""
    rate = 125.0
    path = SquarePath(kind="square", side_m=24.48, laps=1, turn_radius_m=0.5).build()
    plan = plan_gait(path, GaitConfig(swing_s=1, stance_s=1, lift_m=0, pitch_amplitude_deg=0,
                                      lateral_offset_m=0, start_still_s=2), rate)
    m = plan.feet["left"]
    flags = m.stance_flags(plan.n_samples)
    moving = np.flatnonzero(~flags)
    assert np.all((m.k_end - m.k_start) == 125) and np.all(np.diff(m.k_start) == 250)
    st = m.evaluate(plan.t)
    track = plan.track("left")
    np.testing.assert_array_equal(track.stance, flags)
    np.testing.assert_array_equal(track.pos, st.pos)
    assert np.abs(st.pos[:, 2]).max() == 0.0
    apr = azimuth_pitch_roll(st.q_nb)
    assert np.abs(apr[1:]).max() < 1e-12
    assert moving.size > 0


def test_gait_config_checks():
    with pytest.raises(ValueError):
        GaitConfig(swing_s=1.0)
    path = PolylinePath(kind="polyline", waypoints_m=[(0, 0), (0, 5)]).build()
    with pytest.raises(ConfigError) as err:
        plan_gait(path, GaitConfig(swing_s=0.02, stance_s=0.5), 100.0)
    assert err.value.key == "gait"
    for absurd in ({"stride_m": 100.0}, {"lift_m": 50.0}, {"lateral_offset_m": 3.0},
                   {"swing_s": 60.0, "stance_s": 1.0}):
        with pytest.raises(ValueError):
            GaitConfig(**absurd)
    with pytest.raises(ValueError, match="faster than any person runs"):
        GaitConfig(stride_m=5.0, cadence_steps_per_min=400.0)  # 16.7 m/s


# --------------------------------------------------------------------------- error model


def test_white_noise_and_gauss_markov_sigma_match_parameters():
    n, rate = 400_000, 100.0
    errors = SensorErrors(noise_density=2e-3)
    white = corrupt(np.zeros((n, 3)), rate, errors, error_generators(3, "a"), "acc")
    assert white.std(axis=0) == pytest.approx(np.full(3, 2e-3 * math.sqrt(rate)), rel=0.02)
    assert abs(np.corrcoef(white[1:, 0], white[:-1, 0])[0, 1]) < 0.01

    tau, sigma = 0.5, 3e-4
    gm = corrupt(np.zeros((n, 3)), rate, SensorErrors(bias_instability=sigma, bias_tau_s=tau),
                 error_generators(3, "a"), "gyro")
    assert gm.std(axis=0) == pytest.approx(np.full(3, sigma), rel=0.06)
    lag = int(tau * rate)
    rho = np.mean([np.corrcoef(gm[lag:, i], gm[:-lag, i])[0, 1] for i in range(3)])
    assert rho == pytest.approx(math.exp(-1), abs=0.05)

    rw = np.stack([corrupt(np.zeros((101, 3)), rate, SensorErrors(bias_random_walk=1e-3),
                           error_generators(s, "a"), "acc")[-1] for s in range(400)])
    assert rw.std() == pytest.approx(1e-3 * math.sqrt(1.0), rel=0.1)


def test_turn_on_bias_scale_and_misalignment():
    ideal = np.tile([0.0, 0.0, G], (10, 1))
    e = SensorErrors(bias=(0.01, 0, 0), scale_ppm=(0, 0, 1000), misalignment_mrad=(0, 2, 0, 0, 0, 0))
    y = corrupt(ideal, 100.0, e, error_generators(0, "s"), "acc")
    np.testing.assert_allclose(y[:, 0], 0.01 + 2e-3 * G)
    np.testing.assert_allclose(y[:, 2], G * 1.001)


def test_warm_up_drift_settles_the_bias_at_its_own_draw_and_leaves_the_other_terms_alone():
    """b_w (1 − e^(−t/τ_w)): zero at the first sample, 1 − e^(−1) of the settled bias at τ_w; the
    other terms' draws are those of the same unit without it (its stream is its own)."""
    rate, n = 100.0, 60_001
    plain = SensorErrors(noise_density=1e-3, bias_instability=1e-3, bias_sd=0.01)
    warm = SensorErrors(noise_density=1e-3, bias_instability=1e-3, bias_sd=0.01, warmup_sd=0.05, warmup_tau_s=120.0)
    drift = (corrupt(np.zeros((n, 3)), rate, warm, error_generators(4, "w"), "acc")
             - corrupt(np.zeros((n, 3)), rate, plain, error_generators(4, "w"), "acc"))
    settled = drift[-1] / -np.expm1(-600.0 / 120.0)
    np.testing.assert_allclose(drift[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(drift[12_000], settled * -np.expm1(-1.0), rtol=1e-9)
    assert np.all(np.abs(settled) > 1e-4) and np.all(np.abs(settled) < 0.25)  # a draw of σ 0.05 per axis
    draws = np.array([corrupt(np.zeros((2, 3)), rate, SensorErrors(warmup_sd=0.05, warmup_tau_s=1e-9),
                              error_generators(s, "w"), "gyro")[-1] for s in range(400)])
    assert np.std(draws) == pytest.approx(0.05, rel=0.1)


def test_presets_and_overrides():
    icm = ImuErrorConfig(preset="icm20948").resolve()
    assert icm.gyro.noise_density == pytest.approx(0.5 * math.pi / 180 / 60)
    assert icm.gyro.bias_instability == pytest.approx(13 * math.pi / 180 / 3600)
    assert icm.acc.noise_density == pytest.approx(168e-6 * G)
    assert icm.acc.bias_instability == pytest.approx(162e-6 * G)
    assert icm.acc.bias_tau_s == 100.0
    over = ImuErrorConfig(preset="icm20948", acc_bias_mps2=(0.01, 0, 0), gyro_noise_density=0.0).resolve()
    assert over.acc.bias == (0.01, 0.0, 0.0) and over.gyro.noise_density == 0.0
    assert over.acc.noise_density == icm.acc.noise_density
    perfect = ImuErrorConfig().resolve()
    assert perfect.acc == SensorErrors() and perfect.gyro == SensorErrors()
    assert stable_hash("left_foot") == stable_hash("left_foot") != stable_hash("right_foot")


def test_same_seed_same_bytes_and_independent_systems(tmp_path):
    scn = _write_scenario(tmp_path, SHORT)
    a = simulate(scn, tmp_path / "a", seed=5)
    b = simulate(scn, tmp_path / "b", seed=5)
    c = simulate(scn, tmp_path / "c", seed=6)
    for f in ("left_foot_imu.csv", "right_foot_imu.csv", "truth.csv", "config.yaml"):
        assert (a.out_dir / f).read_bytes() == (b.out_dir / f).read_bytes()
    for f in ("left_foot_imu.csv", "right_foot_imu.csv"):
        assert (a.out_dir / f).read_bytes() != (c.out_dir / f).read_bytes()
    assert (a.out_dir / "truth.csv").read_bytes() == (c.out_dir / "truth.csv").read_bytes()
    third = SHORT + "  spare_left: {kind: foot_imu, foot: left, imu: {preset: icm20948}}\n"
    d = simulate(_write_scenario(tmp_path, third, "third.yaml"), tmp_path / "d", seed=5)
    for f in ("left_foot_imu.csv", "right_foot_imu.csv"):
        assert (a.out_dir / f).read_bytes() == (d.out_dir / f).read_bytes()
    assert (d.out_dir / "spare_left_imu.csv").read_bytes() != (d.out_dir / "left_foot_imu.csv").read_bytes()


def test_a_folder_holding_files_of_the_simulations_names_is_refused_unless_overwrite(tmp_path):
    scn = _write_scenario(tmp_path, SHORT)
    out = tmp_path / "out"
    out.mkdir()
    (out / "truth.csv").write_text("my own\n")
    (out / "notes.txt").write_text("kept\n")
    with pytest.raises(FusionError, match=r"out: holds truth\.csv, which the simulation would replace"):
        simulate(scn, out, seed=5)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "truth.csv"]
    assert (out / "truth.csv").read_text() == "my own\n"
    written = simulate(scn, out, seed=5, overwrite=True)
    assert (out / "truth.csv").read_bytes() == simulate(scn, tmp_path / "fresh", seed=5).truth_path.read_bytes()
    assert (out / "notes.txt").read_text() == "kept\n" and written.config_path.is_file()
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no staging or lock left


# --------------------------------------------------------------------------- scenarios and files


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scenarios_write_runnable_layouts(tmp_path, name):
    res = simulate(CONFIGS / name, tmp_path / "out", seed=0)
    assert res.config_path.exists() and res.truth_path.exists()
    assert res.truth_path.read_text().splitlines()[0] == "system,t,east_m,north_m,up_m"
    raw = yaml.safe_load(res.config_path.read_text())
    layout = validate_section(Layout, raw, key="", path=res.config_path, base_dir=res.out_dir)
    assert layout.truth.format == "long" and layout.truth.alignment == "none"
    scenario = yaml.safe_load((CONFIGS / name).read_text())
    assert layout.gravity_mps2 == scenario["gravity_mps2"]
    walking = res.duration_s - scenario["gait"].get("start_still_s", 3) - scenario["gait"].get("end_still_s", 2)
    assert walking >= 60.0
    truth = np.genfromtxt(res.truth_path, delimiter=",", names=True, dtype=None, encoding="utf-8")
    for sys_name, section in raw["systems"].items():
        cfg = validate_section(FootInsConfig, section, key=f"systems.{sys_name}", path=res.config_path,
                               base_dir=res.out_dir)
        assert not cfg.filter.earth_rate
        imu = read_imu_csv(cfg.data.path, acc_columns=cfg.data.acc_columns, gyro_columns=cfg.data.gyro_columns,
                           stance_column=cfg.data.stance_column, time_column=cfg.data.time_column)
        assert len(imu) == res.samples[sys_name]
        rows = truth[truth["system"] == sys_name]
        assert rows.size == res.samples[sys_name]
        np.testing.assert_allclose(rows["t"], imu.t)
        np.testing.assert_allclose([rows["east_m"][0], rows["north_m"][0], rows["up_m"][0]],
                                   cfg.initial.position_m, atol=1e-9)
        assert imu.stance[: int(cfg.initial.stationary_s * 100)].all()
        assert cfg.initial.stationary_s <= scenario["gait"].get("start_still_s", 3)
        spec = scenario["systems"][sys_name]
        # Heading: the truth's first steps go along the path heading; the IMU adds its mount yaw.
        de, dn = rows["east_m"] - rows["east_m"][0], rows["north_m"] - rows["north_m"][0]
        moving = np.flatnonzero(np.hypot(de, dn) > 0.5)[0]
        walk_az = math.degrees(math.atan2(de[moving], dn[moving]))
        expect = walk_az + spec.get("mount_yaw_deg", 0.0)
        assert abs((cfg.initial.heading_deg - expect + 180) % 360 - 180) < 3.0
    if name == "sim_dual_foot_square.yaml":
        assert raw["systems"]["right_foot"]["initial"]["heading_deg"] == pytest.approx(7.0)
        assert raw["systems"]["left_foot"]["filter"]["acc_noise_density"] == pytest.approx(168e-6 * G)
        assert layout.truth.loop
    else:
        assert raw["systems"]["left_foot"]["detector"] == {"kind": "labels"}


def test_overrides_apply(tmp_path):
    scn = _write_scenario(tmp_path, SHORT)
    res = simulate(scn, tmp_path / "o", seed=0, overrides=["gait.stride_m=1.0", "rate_hz=50",
                                                           "layout.systems.left_foot.detector.kind=labels"])
    raw = yaml.safe_load(res.config_path.read_text())
    assert raw["systems"]["left_foot"]["detector"] == {"kind": "labels"}
    t = np.loadtxt(tmp_path / "o" / "left_foot_imu.csv", delimiter=",", skiprows=1)[:, 0]
    assert t[1] == pytest.approx(0.02)


def test_written_filter_priors_follow_the_simulated_sensor(tmp_path):
    """The config tells the filter the uncertainty the simulation has: heading σ (the
    floor when the heading is true, the drawn error's σ otherwise) and bias σ."""
    scn = _write_scenario(tmp_path, SHORT)
    exact = yaml.safe_load(simulate(scn, tmp_path / "e", seed=3).config_path.read_text())["systems"]
    off = yaml.safe_load(simulate(scn, tmp_path / "h", seed=3, overrides=[
        "systems.left_foot.heading_error_sd_deg=2.0"]).config_path.read_text())["systems"]
    ini, ini_off = exact["left_foot"]["initial"], off["left_foot"]["initial"]
    assert ini["heading_sd_deg"] == 0.05 and ini_off["heading_sd_deg"] == 2.0
    delta = (ini_off["heading_deg"] - ini["heading_deg"] + 180.0) % 360.0 - 180.0
    assert 0.0 < abs(delta) < 4 * 2.0
    assert off["right_foot"]["initial"] == exact["right_foot"]["initial"]  # its own stream
    # icm20948: 1 s still window → gyro bias σ² = (N/√1 s)² + the Gauss–Markov bias's move
    # from the first sample to the window's mean, σ_GM² (1 − 2m + 2 (τ/T)(1 − m)),
    # m = (τ/T)(1 − e^(−T/τ)), τ = 100 s; accelerometer 0.05 m/s² turn-on σ beside its
    # 162 µg Gauss–Markov σ
    n_g, gm_g = 0.5 * math.pi / 180 / 60, 13.0 * math.pi / 180 / 3600
    m = 100.0 * -math.expm1(-1.0 / 100.0)
    assert ini["gyro_bias_sd_radps"] == pytest.approx(math.hypot(n_g, gm_g * math.sqrt(1 - 2 * m + 200 * (1 - m))))
    assert exact["right_foot"]["initial"]["acc_bias_sd_mps2"] == pytest.approx(math.hypot(0.05, 162e-6 * G))


@pytest.mark.parametrize(("text", "key"), [
    (SHORT + "bogus: 1\n", "bogus"),
    (SHORT.replace("rate_hz: 100", "rate_hz: -5"), "rate_hz"),
    (SHORT.replace("gait: {", "gait: {stirde_m: 1, "), "gait.stirde_m"),
    (SHORT.replace("[4, 5]]}", "[4, 5]], side_m: 3}"), "path.side_m"),
    (SHORT.replace("kind: polyline", "kind: spiral"), "path.kind"),
    (SHORT.replace("preset: icm20948}}", "preset: bmi}}", 1), "systems.left_foot.imu.preset"),
    (SHORT.replace("kind: foot_imu, foot: left", "kind: foot_imu, foot: middle"), "systems.left_foot.foot"),
    (SHORT.replace("kind: foot_imu, foot: left", "kind: phone, foot: left"), "systems.left_foot.kind"),
    (SHORT + "layout: {systems: {nose: {detector: {kind: labels}}}}\n", "layout.systems.nose"),
    (SHORT.replace("[4, 5]]}", "[4, 5]], turn_radius_m: 9}"), "path.turn_radius_m"),
])
def test_bad_scenarios_name_the_key(tmp_path, text, key):
    scn = _write_scenario(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        simulate(scn, tmp_path / "x")
    assert err.value.key == key
    assert str(scn) in str(err.value) and "\n" not in str(err.value)
    assert not (tmp_path / "x").exists()


def test_a_walk_too_long_to_hold_is_refused_before_it_is_built(tmp_path):
    scenario = yaml.safe_load((CONFIGS / "sim_dual_foot_square.yaml").read_text())
    scenario["path"]["laps"] = 10_001
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(scenario))
    with pytest.raises(ConfigError, match="laps"):
        simulate(path, tmp_path / "out")
    scenario["path"]["laps"] = 10_000
    scenario["gait"]["start_still_s"] = 6e5  # within a week (the unit's bound), but 6e7 samples at 100 Hz
    path.write_text(yaml.safe_dump(scenario))
    with pytest.raises(ConfigError, match=r"samples are simulated"):
        simulate(path, tmp_path / "out")
    scenario["gait"]["start_still_s"] = 1e9
    path.write_text(yaml.safe_dump(scenario))
    with pytest.raises(ConfigError, match=r"gait.start_still_s: 1e\+09 is beyond 604800 s, a week"):
        simulate(path, tmp_path / "out")
