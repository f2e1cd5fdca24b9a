"""Simulator: the hand-held phone (body path, bounce, sway, steps) and its GNSS receiver."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from bodyfusion.core.layout import Layout, load_layout
from bodyfusion.core.layout_io import validate_section
from bodyfusion.io.gnss import read_gnss_csv
from bodyfusion.nav.strapdown import integrate
from bodyfusion.plugins.hand_pdr.config import HandPdrConfig, StepConfig
from bodyfusion.plugins.hand_pdr.pdr import detect_steps
from bodyfusion.sim import simulate
from bodyfusion.sim.gait import plan_gait
from bodyfusion.sim.gait_config import GaitConfig
from bodyfusion.sim.gnss import RADIUS_68_PER_SIGMA, GnssReceiverConfig, simulate_fixes
from bodyfusion.sim.hand import HandSwayConfig, hand_motion
from bodyfusion.sim.imu import MotionState, ideal_imu
from bodyfusion.sim.paths import PolylinePath
from bodyfusion.sim.scenario import DEFAULT_GEODETIC_ORIGIN
from tests.paths import CONFIGS

G = 9.80665

SCENARIO = """
name: hand_short
rate_hz: 100
path: {kind: polyline, waypoints_m: [[0, 0], [0, 20], [15, 20]], turn_radius_m: 2}
gait: {end_still_s: 1}
systems:
  left_foot: {kind: foot_imu, foot: left, imu: {preset: icm20948}}
  right_foot: {kind: foot_imu, foot: right, imu: {preset: icm20948}}
  hand: {kind: hand_phone, mount_yaw_deg: 10,
         gnss: {outages: [{start_s: 10, duration_s: 5}, {start_s: 20, duration_s: 2}]}}
layout:
  constraints: [{between: [left_foot, hand], kind: max, distance_m: 1.5}]
"""


def _write(tmp_path: Path, text: str, name: str = "scn.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _motion(rate: float = 100.0, seed: int = 0, mount_yaw_deg: float = 10.0):
    path = PolylinePath(kind="polyline", waypoints_m=[(0, 0), (0, 20), (15, 20)], turn_radius_m=2.0).build()
    gait = GaitConfig()
    plan = plan_gait(path, gait, rate)
    cycle = int(round(gait.cycle_s()[0] * rate))
    motion = hand_motion(plan, cycle, seed=seed, name="hand", offset_m=(0.3, -0.2, 1.1), bounce_m=0.03,
                         lateral_sway_m=0.02, mount_yaw_deg=mount_yaw_deg, sway=HandSwayConfig())
    return plan, motion


# --------------------------------------------------------------------------- motion and IMU


def test_hand_imu_at_rest_reads_gravity():
    plan, motion = _motion()
    t = plan.t
    acc, gyro = ideal_imu(motion, t, G)
    still = t <= motion.progress.t0
    assert still.sum() > 250  # the 3 s start minus the step before the first heel strike
    np.testing.assert_allclose(acc[still], np.tile([0.0, 0.0, G], (still.sum(), 1)), atol=1e-12)
    np.testing.assert_allclose(gyro[still], 0.0, atol=1e-15)
    st = motion.evaluate(t[still])
    np.testing.assert_allclose(st.pos, np.tile(st.pos[0], (still.sum(), 1)), atol=1e-12)
    assert st.pos[0, 2] == pytest.approx(1.1)
    walking = acc[~still]
    assert np.abs(walking - [0, 0, G]).max() > 1.0


def test_free_inertial_integration_of_the_hand_imu_follows_truth():
    """Unaided bodyfusion.nav.strapdown.integrate of the ideal hand IMU from rest through the start of
    the walk (bounce, sway, wobble, 10° mount yaw), then from a moving start across the turn."""
    plan, motion = _motion()
    t = plan.t
    acc, gyro = ideal_imu(motion, t, G)
    truth = motion.evaluate(t)

    def run(k0: int, k1: int) -> np.ndarray:
        x0 = np.zeros(16)
        x0[0:3], x0[3:6], x0[6:10] = truth.pos[k0], truth.vel[k0], truth.q_nb[k0]
        out = integrate(x0, t[k0:k1], acc[k0:k1], gyro[k0:k1], G, np.zeros(3))
        return np.linalg.norm(out[:, 0:3] - truth.pos[k0:k1], axis=1)

    err = run(0, int(8.0 * 100))  # 3 s still + 5 s of walking
    assert err.max() < 0.01, err.max()
    # 4 s through the 90° turn (≈ 20 m along the path, reached about 19 s in).
    k0 = int(17.0 * 100)
    err = run(k0, k0 + 400)
    assert err.max() < 0.02, err.max()


def test_heading_and_offset_follow_the_body_path():
    plan, motion = _motion(mount_yaw_deg=10.0)
    t = np.array([8.0])  # on the first (northbound) leg
    st = motion.evaluate(t)
    from bodyfusion.nav.attitude import azimuth_pitch_roll

    az, pitch, roll = azimuth_pitch_roll(st.q_nb[0])
    assert abs(math.degrees(az) - 10.0) < 3 * 2.0 + 1  # mount yaw plus a few σ of wobble
    assert abs(math.degrees(pitch)) < 8 and abs(math.degrees(roll)) < 8
    assert st.vel[0, 1] == pytest.approx(0.7 / (60 / 108), abs=0.25)  # gait speed northwards
    assert st.pos[0, 0] == pytest.approx(0.2, abs=0.08)  # 0.2 m right of the path (East)


def test_one_step_peak_per_true_step(tmp_path):
    res = simulate(_write(tmp_path, SCENARIO), tmp_path / "out", seed=3)
    raw = np.loadtxt(res.out_dir / "hand_imu.csv", delimiter=",", skiprows=1)
    t, acc, step = raw[:, 0], raw[:, 1:4], raw[:, 7].astype(int)
    true = np.flatnonzero(step)
    assert true.size > 20
    peaks = detect_steps(t, acc, StepConfig(), G)
    assert peaks.size == true.size
    assert np.abs(peaks - true).max() <= 2
    # The step column marks every heel strike of either foot: where a foot's stance starts.
    strikes = []
    for foot in ("left_foot", "right_foot"):
        stance = np.loadtxt(res.out_dir / f"{foot}_imu.csv", delimiter=",", skiprows=1)[:, 7].astype(int)
        strikes.append(np.flatnonzero(np.diff(stance) == 1) + 1)
    np.testing.assert_array_equal(np.sort(np.concatenate(strikes)), true)


# --------------------------------------------------------------------------- GNSS


class _Still:
    def evaluate(self, t):
        z = np.zeros((np.size(t), 3))
        q = np.tile([1.0, 0, 0, 0], (np.size(t), 1))
        return MotionState(pos=z + [10.0, -5.0, 1.0], vel=z, acc=z, q_nb=q, omega_n=z)


def test_gnss_error_statistics_match_the_parameters():
    n = 60000
    white = GnssReceiverConfig(white_sigma_m=1.5, gm_sigma_m=0.0, height_white_sigma_m=2.5, height_gm_sigma_m=0.0)
    _, err = simulate_fixes(_Still(), n - 1, DEFAULT_GEODETIC_ORIGIN, white, seed=1, name="h")
    assert err.shape == (n, 3)
    np.testing.assert_allclose(err.std(axis=0), [1.5, 1.5, 2.5], rtol=0.03)
    assert abs(np.corrcoef(err[1:, 0], err[:-1, 0])[0, 1]) < 0.02

    gm = GnssReceiverConfig(white_sigma_m=0.0, gm_sigma_m=3.0, gm_tau_s=20.0, height_white_sigma_m=0.0,
                            height_gm_sigma_m=4.0)
    _, err = simulate_fixes(_Still(), n - 1, DEFAULT_GEODETIC_ORIGIN, gm, seed=1, name="h")
    np.testing.assert_allclose(err.std(axis=0), [3.0, 3.0, 4.0], rtol=0.1)
    lag = 20
    rho = np.mean([np.corrcoef(err[lag:, i], err[:-lag, i])[0, 1] for i in range(3)])
    assert rho == pytest.approx(math.exp(-1), abs=0.06)

    both = GnssReceiverConfig()
    fixes, err = simulate_fixes(_Still(), 3000, DEFAULT_GEODETIC_ORIGIN, both, seed=1, name="h")
    # The fixes are the truth plus the error, in WGS84 about the origin.
    np.testing.assert_allclose(fixes.enu(DEFAULT_GEODETIC_ORIGIN), np.array([10.0, -5.0, 1.0]) + err, atol=1e-6)
    assert np.all(fixes.accuracy_m == pytest.approx(RADIUS_68_PER_SIGMA * math.hypot(1.5, 3.0)))
    assert np.all(np.diff(fixes.t) == 1.0) and fixes.t[0] == 0.0


def test_gnss_file_speed_course_and_outages_in_layout(tmp_path):
    res = simulate(_write(tmp_path, SCENARIO), tmp_path / "out", seed=0)
    raw = yaml.safe_load(res.config_path.read_text())
    assert raw["geodetic_origin"] == list(DEFAULT_GEODETIC_ORIGIN)
    assert raw["outages"] == [{"system": "hand", "start_s": 10.0, "duration_s": 5.0},
                              {"system": "hand", "start_s": 20.0, "duration_s": 2.0}]
    layout = validate_section(Layout, raw, key="", path=res.config_path, base_dir=res.out_dir)
    assert layout.geodetic_origin == DEFAULT_GEODETIC_ORIGIN and len(layout.outages) == 2
    section = raw["systems"]["hand"]
    cfg = validate_section(HandPdrConfig, section, key="systems.hand", path=res.config_path, base_dir=res.out_dir)
    assert cfg.gnss.format == "csv" and cfg.imu.time_column == "t"
    assert section["initial"]["heading_deg"] == pytest.approx(0.0)  # walking north first
    truth = np.genfromtxt(res.truth_path, delimiter=",", names=True, dtype=None, encoding="utf-8")
    rows = truth[truth["system"] == "hand"]
    assert rows.size == res.samples["hand"]
    np.testing.assert_allclose(cfg.initial.position_m, [rows["east_m"][0], rows["north_m"][0], rows["up_m"][0]])
    fixes = read_gnss_csv(cfg.gnss.path, time_column="t", lat_column="lat_deg", lon_column="lon_deg",
                          height_column="height_m", accuracy_column="accuracy_m", speed_column="speed_mps",
                          course_column="course_deg")
    assert len(fixes) == int(res.duration_s) + 1  # no fix dropped for the outages
    # While walking north on the first leg, course ≈ 0° and speed ≈ gait speed.
    leg = (fixes.t > 6) & (fixes.t < 14)
    course = (fixes.course_deg[leg] + 180) % 360 - 180
    assert np.abs(course).max() < 20 and np.median(fixes.speed_mps[leg]) == pytest.approx(1.26, abs=0.2)
    enu = fixes.enu(DEFAULT_GEODETIC_ORIGIN)
    true_at = np.column_stack([np.interp(fixes.t, rows["t"], rows[c]) for c in ("east_m", "north_m", "up_m")])
    assert np.sqrt(np.mean((enu - true_at)[:, :2] ** 2)) < 12  # metres, not degrees
    # The whole layout loads with the plugins.
    loaded = load_layout(res.config_path)
    assert set(loaded.system_configs) == {"left_foot", "right_foot", "hand"}


def test_seeds_and_independence_of_the_feet(tmp_path):
    feet_only = "\n".join(line for line in SCENARIO.splitlines()
                          if not line.startswith(("  hand", "         gnss", "layout", "  constraints")))
    scn = _write(tmp_path, SCENARIO)
    a = simulate(scn, tmp_path / "a", seed=5)
    b = simulate(scn, tmp_path / "b", seed=5)
    c = simulate(scn, tmp_path / "c", seed=6)
    d = simulate(_write(tmp_path, feet_only, "feet.yaml"), tmp_path / "d", seed=5)
    for f in ("left_foot_imu.csv", "right_foot_imu.csv", "hand_imu.csv", "hand_gnss.csv", "truth.csv", "config.yaml"):
        assert (a.out_dir / f).read_bytes() == (b.out_dir / f).read_bytes(), f
    for f in ("hand_imu.csv", "hand_gnss.csv"):
        assert (a.out_dir / f).read_bytes() != (c.out_dir / f).read_bytes(), f
    for f in ("left_foot_imu.csv", "right_foot_imu.csv"):
        assert (a.out_dir / f).read_bytes() == (d.out_dir / f).read_bytes(), f
    feet_truth = [line for line in (a.out_dir / "truth.csv").read_text().splitlines() if not line.startswith("hand,")]
    assert feet_truth == (d.out_dir / "truth.csv").read_text().splitlines()
    assert "geodetic_origin" not in yaml.safe_load((d.out_dir / "config.yaml").read_text())
    # The GNSS stream is separate from the IMU's: switching the receiver off keeps the IMU file.
    no_gnss = SCENARIO.replace("gnss: {outages: [{start_s: 10, duration_s: 5}, {start_s: 20, duration_s: 2}]}",
                               "gnss: null")
    e = simulate(_write(tmp_path, no_gnss, "nognss.yaml"), tmp_path / "e", seed=5)
    assert (a.out_dir / "hand_imu.csv").read_bytes() == (e.out_dir / "hand_imu.csv").read_bytes()
    assert not (e.out_dir / "hand_gnss.csv").exists()
    raw = yaml.safe_load((e.out_dir / "config.yaml").read_text())
    assert "gnss" not in raw["systems"]["hand"] and "outages" not in raw


def test_truth_keeps_the_hand_within_reach_of_the_feet(tmp_path):
    res = simulate(_write(tmp_path, SCENARIO), tmp_path / "out", seed=0)
    truth = np.genfromtxt(res.truth_path, delimiter=",", names=True, dtype=None, encoding="utf-8")
    p = {s: np.column_stack([truth[truth["system"] == s][c] for c in ("east_m", "north_m")])
         for s in ("left_foot", "right_foot", "hand")}
    assert np.linalg.norm(p["left_foot"] - p["right_foot"], axis=1).max() < 0.8
    for foot in ("left_foot", "right_foot"):
        assert np.linalg.norm(p[foot] - p["hand"], axis=1).max() < 1.1


@pytest.mark.parametrize("name", ["foot_hand_gnss_outage.yaml", "dual_foot_hand_gnss.yaml"])
def test_shipped_hand_scenarios_load(name):
    from bodyfusion.sim.scenario import load_scenario

    loaded = load_scenario(CONFIGS / name)
    assert "hand_phone" in loaded.systems and loaded.systems["hand_phone"].gnss.outages
    assert loaded.scenario.geodetic_origin is not None
    layout = loaded.scenario.layout
    assert layout["fuser"]["method"] == "projection"
    assert all(c["kind"] == "max" for c in layout["constraints"])
    assert len(layout["constraints"]) == (1 if name.startswith("foot_hand") else 3)
