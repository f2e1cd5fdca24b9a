"""Simulator gaits: running (flight, stance roll, impact), stairs, pauses; the walk unchanged."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import Layout, load_layout
from bodyfusion.core.layout_io import validate_section
from bodyfusion.runner import run_layout
from bodyfusion.nav.strapdown import integrate
from bodyfusion.sim import load_scenario, simulate
from bodyfusion.sim.gait import GaitPlan, plan_gait
from bodyfusion.sim.gait_config import GAIT_KINDS, GaitConfig
from bodyfusion.sim.imu import ideal_imu
from bodyfusion.sim.paths import PolylinePath
from tests.paths import CONFIGS

G = 9.80665

WALK = """
name: short
rate_hz: 100
path: {kind: polyline, waypoints_m: [[0, 0], [0, 5], [4, 5]]}
gait: {start_still_s: 1, end_still_s: 0.5}
systems:
  left_foot:  {kind: foot_imu, foot: left,  imu: {preset: icm20948},
               stance_noise: {colour_factor: 0.9, sigma_mps: 0.005}}
  right_foot: {kind: foot_imu, foot: right, imu: {preset: icm20948, acc_bias_sd_mps2: 0.05}, mount_yaw_deg: 7}
"""
PULSE = """
name: pulse
rate_hz: 125
path: {kind: square, side_m: 4, laps: 1, turn_radius_m: 0.5}
gait: {swing_s: 0.8, stance_s: 0.5, lift_m: 0.05, pitch_amplitude_deg: 10, lateral_offset_m: 0, first_foot: right,
       start_still_s: 1, end_still_s: 0.5}
systems:
  left_foot:  {kind: foot_imu, foot: left,  imu: {preset: icm20948}, mount_yaw_deg: -12}
  right_foot: {kind: foot_imu, foot: right, imu: {preset: perfect}}
"""
# SHA-256 of the files the walk wrote (seed 0) before gait kinds existed.
WALK_SHA256 = {
    "short": {
        "left_foot_imu.csv": "9677ab64df28e138df7c2332fb798c44bc43def1d73139587a589c3a26ea0bbe",
        "right_foot_imu.csv": "8679b5f1812df2963c927344f430a0df72a2bbdd77028518c2003de97285546b",
        "truth.csv": "a6c5340b0c19c33a77bc689273dd9ee1520b0e84aae10ac9bc87870f7d3cdd68",
    },
    "pulse": {
        "left_foot_imu.csv": "754f3a52fc60231f43559f8a014618e45dc3442c4ccdf8586e44ffb2dbac74f6",
        "right_foot_imu.csv": "398944243c1419304a6643289c5ccb4e2910fb99e60c546095a516b8dc3cbbc3",
        "truth.csv": "441ef7431b4b8fb0714cf17d97429ca8cdb3e7b5c2eeefae6cc34823e19477ee",
    },
}
RUN = """
name: short_run
rate_hz: 200
path: {kind: rectangle, length_m: 12, width_m: 6, laps: 1, turn_radius_m: 2}
gait: {kind: run, start_still_s: 1, end_still_s: 0.5}
systems:
  left_foot:  {kind: foot_imu, foot: left,  imu: {preset: icm20948}}
  right_foot: {kind: foot_imu, foot: right, imu: {preset: icm20948}, mount_yaw_deg: 5}
"""
STAIRS = """
name: short_stairs
rate_hz: 100
path: {kind: polyline, waypoints_m: [[0, 0], [0, 4.48]]}
gait:
  kind: stairs
  stairs: {flights: [{direction: up, steps: 8}, {direction: level, steps: 2}, {direction: down, steps: 3}]}
  start_still_s: 1
  end_still_s: 0.5
systems:
  left_foot:  {kind: foot_imu, foot: left,  imu: {preset: icm20948}}
  right_foot: {kind: foot_imu, foot: right, imu: {preset: icm20948}}
"""


# --------------------------------------------------------------------------- helpers


def _write(tmp_path: Path, text: str, name: str = "scn.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _plan(rate: float, waypoints=((0.0, 0.0), (0.0, 16.0), (12.0, 16.0)), **gait) -> GaitPlan:
    path = PolylinePath(kind="polyline", waypoints_m=list(waypoints), turn_radius_m=1.5).build()
    return plan_gait(path, GaitConfig(**gait), rate)


def _stride_error(plan: GaitPlan, foot: str, swing: int, mount_yaw_deg: float = 7.0) -> tuple[float, float, float]:
    """bodyfusion.nav.strapdown.integrate of the ideal IMU from the last rest sample before swing
    ``swing`` to the first after it (toe roll, swing, impact, heel roll): the largest position
    error (m), the velocity (m/s) and the attitude error (rad) at the end."""
    motion = plan.feet[foot].mounted(mount_yaw_deg)
    t = plan.t
    rest = motion.stance_flags(t.size)
    a = int(motion.k_start[swing])
    while not rest[a]:
        a -= 1
    b = int(motion.k_end[swing])
    while not rest[b]:
        b += 1
    sl = slice(a, b + 1)
    acc, gyro = ideal_imu(motion, t[sl], G)
    truth = motion.evaluate(t[sl])
    x0 = np.zeros(16)
    x0[0:3] = truth.pos[0]
    x0[6:10] = truth.q_nb[0]
    out = integrate(x0, t[sl], acc, gyro, G, np.zeros(3))
    q, q_true = out[-1, 6:10], truth.q_nb[-1]
    att = 2.0 * math.acos(min(1.0, abs(float(np.dot(q, q_true)))))
    return float(np.abs(out[:, 0:3] - truth.pos).max()), float(np.linalg.norm(out[-1, 3:6])), att


def _airborne(plan: GaitPlan, foot: str, t: np.ndarray) -> np.ndarray:
    m = plan.feet[foot]
    j = np.searchsorted(m.t_start, t, side="right") - 1
    return (j >= 0) & (t < m.t_end[np.maximum(j, 0)])


# --------------------------------------------------------------------------- the walk is unchanged


@pytest.mark.parametrize("name", ["short", "pulse"])
def test_walk_default_is_bit_exact_with_the_walk_before_gait_kinds(tmp_path, name):
    text = {"short": WALK, "pulse": PULSE}[name]
    res = simulate(_write(tmp_path, text), tmp_path / "a", seed=0)
    explicit = simulate(_write(tmp_path, text.replace("gait: {", "gait: {kind: walk, "), "walk.yaml"),
                        tmp_path / "b", seed=0)
    for f, digest in WALK_SHA256[name].items():
        assert _sha(res.out_dir / f) == digest, f
        assert _sha(explicit.out_dir / f) == digest, f


def test_kind_defaults_and_overrides():
    assert GaitConfig() == GaitConfig(kind="walk")
    run = GaitConfig(kind="run")
    assert run.stride_m == 2.12 and run.cadence_steps_per_min == 170
    assert run.roll is not None and run.impact is not None
    cycle, swing = run.cycle_s()
    assert cycle - swing == pytest.approx(0.15, abs=1e-3)
    assert run.stride_m / cycle == pytest.approx(3.0, abs=0.01)
    tuned = GaitConfig(kind="run", cadence_steps_per_min=180, roll=None, impact={"peak_g": 6})
    assert tuned.stride_m == 2.12 and tuned.roll is None
    assert tuned.impact.peak_g == 6 and tuned.impact.duration_s == 0.03
    stairs = GaitConfig(kind="stairs")
    assert stairs.stride_m / 2 == pytest.approx(0.28) and stairs.stairs.rise_m == 0.17
    assert [f.direction for f in stairs.stairs.flights] == ["up"]
    assert set(GAIT_KINDS) == {"walk", "run", "stairs"}


# --------------------------------------------------------------------------- kinematics against the mechanisation


@pytest.mark.parametrize(("kind", "rate", "pos_tol", "vel_tol"), [
    ("run", 200.0, 5e-4, 1e-3),
    ("stairs", 100.0, 5e-4, 1e-4),
])
def test_strapdown_of_the_ideal_imu_reproduces_the_truth_over_a_stride(kind, rate, pos_tol, vel_tol):
    """Rest to rest over a whole swing (with the running stance's toe roll before it and
    impact and heel roll after it), mounted 7° off the foot, one swing in a 90° turn:
    sub-millimetre, and back at rest at the end."""
    plan = _plan(rate, kind=kind, start_still_s=1)
    in_turn = int(np.argmax(plan.feet["left"].footprints[:, 0] > 1.0)) - 1  # lands past the corner
    for swing in (2, in_turn):
        pos_err, vel, att = _stride_error(plan, "left", swing)
        assert pos_err < pos_tol and vel < vel_tol and att < 1e-4, (swing, pos_err, vel, att)


def test_running_stride_error_is_a_truncation_error_that_shrinks_with_dt():
    """Impact and roll included, the error falls faster than dt³ from 100 Hz to 200 Hz
    (measured: about dt³·⁷), as a truncation error of the mechanisation must."""
    errs = [_stride_error(_plan(rate, kind="run", start_still_s=1), "left", 3)[0] for rate in (100.0, 200.0)]
    assert errs[0] / errs[1] > 8.0, errs


# --------------------------------------------------------------------------- stance labels


@pytest.mark.parametrize("gait", [
    {"kind": "walk"},
    {"kind": "run"},
    {"kind": "stairs"},
    {"kind": "walk", "roll": {}, "pauses": [{"at_s": 5.0, "duration_s": 1.5}]},
])
def test_stance_labels_are_the_truth_of_rest(gait):
    """stance[k] ⇔ zero velocity and angular rate throughout one of the sample intervals
    next to t_k (checked at 11 instants in every interval, its end included)."""
    plan = _plan(100.0, start_still_s=1, end_still_s=0.5, **gait)
    t = plan.t
    inside = np.column_stack([t[:-1, None] + np.linspace(0.0, 1.0, 12)[1:-1] / plan.rate_hz, t[1:]])
    for foot in ("left", "right"):
        m = plan.feet[foot].mounted(-20.0)
        st = m.evaluate(inside.ravel())
        motion = np.maximum(np.linalg.norm(st.vel, axis=1), np.linalg.norm(st.omega_n, axis=1))
        still = (motion.reshape(inside.shape) == 0.0).all(axis=1)
        expect = np.zeros(t.size, dtype=bool)
        expect[1:] |= still
        expect[:-1] |= still
        flags = m.stance_flags(t.size)
        np.testing.assert_array_equal(flags, expect)
        at_k = m.evaluate(t)
        assert np.all(at_k.vel[flags] == 0.0) and np.all(at_k.omega_n[flags] == 0.0)
        assert flags[: int(plan.start_still_s * plan.rate_hz) + 1].all() and flags[-51:].all()
        assert 0.05 < (~flags).mean() < 0.95


def test_running_stance_rolls_and_is_labelled_at_rest_only_when_flat(tmp_path):
    """In a running contact (0.15 s) the foot rolls heel-to-toe: the label covers the flat
    50 ms only; during the rolls the gyro reads several rad/s while the foot is on the
    ground. The written IMU CSV carries exactly these labels."""
    scn = _write(tmp_path, RUN)
    res = simulate(scn, tmp_path / "o", seed=0)
    loaded = load_scenario(scn)
    plan = plan_gait(loaded.path.build(), loaded.scenario.gait, loaded.scenario.rate_hz)
    m = plan.feet["left"]
    t = plan.t
    flags = m.stance_flags(t.size)
    written = np.loadtxt(res.out_dir / "left_foot_imu.csv", delimiter=",", skiprows=1)[:, 7].astype(bool)
    np.testing.assert_array_equal(written, flags)
    _, gyro = ideal_imu(m, t, G)
    contact = ~_airborne(plan, "left", t) & ~flags
    assert contact.any() and np.linalg.norm(gyro[contact], axis=1).max() > 4.0
    k_end, k_next = int(m.k_end[2]), int(m.k_start[3])
    assert (k_next - k_end) / plan.rate_hz == pytest.approx(0.15, abs=0.005)
    assert flags[k_end:k_next + 1].sum() == 11  # 10 still intervals between 50 ms rolls


# --------------------------------------------------------------------------- running


def test_running_has_flight_phases_pace_and_impacts():
    plan = _plan(200.0, waypoints=((0.0, 0.0), (0.0, 40.0)), kind="run", start_still_s=1)
    t = plan.t
    left, right = _airborne(plan, "left", t), _airborne(plan, "right", t)
    both = left & right
    # one flight after each toe-off: (swing − half cycle) ≈ 0.20 s each
    edges = np.flatnonzero(np.diff(both.astype(int)))
    runs = (edges[1::2] - edges[0::2]) / plan.rate_hz
    assert runs.size >= 2 * (plan.feet["left"].k_start.size - 2)
    assert np.all(np.abs(runs[1:-1] - 0.2) < 0.02), runs
    m = plan.feet["left"]
    st = m.evaluate(t)
    mid = slice(int(m.k_start[2]), int(m.k_start[-3]))
    pace = (st.pos[mid.stop, 1] - st.pos[mid.start, 1]) / ((mid.stop - mid.start) / plan.rate_hz)
    assert pace == pytest.approx(3.0, abs=0.05)
    acc, gyro = ideal_imu(m, t, G)
    rate = np.linalg.norm(gyro, axis=1)
    swing_peak = max(rate[a:b].max() for a, b in zip(m.k_start, m.k_end))
    assert 10.0 <= swing_peak <= 15.0
    impact = slice(int(m.k_end[3]), int(m.k_end[3]) + 6)
    assert np.linalg.norm(acc[impact], axis=1).max() > 3.0 * G


# --------------------------------------------------------------------------- stairs


def test_stairs_change_height_by_rise_times_steps(tmp_path):
    """Each footprint one riser above (below) the one before it; the truth's up column ends
    at rise × (steps up − steps down) and holds the climb in between."""
    plan = _plan(100.0, waypoints=((0.0, 0.0), (0.0, 10 * 0.28)), kind="stairs", start_still_s=1)
    prints = np.concatenate([plan.feet[f].footprints[1:] for f in ("left", "right")])
    order = np.argsort(prints[:, 1], kind="stable")
    np.testing.assert_allclose(np.diff(prints[order, 2])[:-1], 0.17, atol=1e-12)  # last: beside the other foot
    for foot in ("left", "right"):
        assert plan.feet[foot].evaluate(plan.t[-1:]).pos[0, 2] == pytest.approx(10 * 0.17, abs=1e-12)

    res = simulate(_write(tmp_path, STAIRS), tmp_path / "s", seed=0)
    truth = np.genfromtxt(res.truth_path, delimiter=",", names=True, dtype=None, encoding="utf-8")
    for foot in ("left_foot", "right_foot"):
        up = truth["up_m"][truth["system"] == foot]
        rest = np.loadtxt(res.out_dir / f"{foot}_imu.csv", delimiter=",", skiprows=1)[:, 7].astype(bool)
        risers = up[rest] / 0.17  # standing: on a tread, a whole number of risers up
        np.testing.assert_allclose(risers, np.round(risers), atol=1e-8)
        assert set(np.round(risers).astype(int)) >= {0, 5, 8}
        assert up[-1] == pytest.approx((8 - 3) * 0.17, abs=1e-9)


# --------------------------------------------------------------------------- pauses


@pytest.mark.parametrize("kind", ["walk", "run"])
def test_a_pause_holds_both_feet_at_rest_and_leaves_the_rest_of_the_walk_alone(kind):
    base = _plan(100.0, kind=kind, start_still_s=1)
    paused = _plan(100.0, kind=kind, start_still_s=1, pauses=[{"at_s": 4.0, "duration_s": 2.5}])
    n = base.n_samples
    both = paused.feet["left"].stance_flags(paused.n_samples) & paused.feet["right"].stance_flags(paused.n_samples)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], both.astype(int), [0]])))
    runs = edges[1::2] - edges[0::2] - 1  # still intervals of each both-at-rest run
    assert runs.max() == 250  # exactly the pause
    shift = paused.n_samples - n
    for foot in ("left", "right"):
        a, b = base.feet[foot], paused.feet[foot]
        moved = b.k_start != a.k_start
        assert np.all(b.k_start[moved] - a.k_start[moved] == shift) and np.all(a.k_start[moved] >= 400)
        np.testing.assert_array_equal(a.footprints, b.footprints)
        np.testing.assert_array_equal(a.evaluate(base.t[:400]).pos, b.evaluate(base.t[:400]).pos)
    # walking: the double support already rests both feet; running: the foot in the air lands first
    assert (0 < shift < 250) if kind == "walk" else (shift > 250)


# --------------------------------------------------------------------------- determinism, scenarios, errors


@pytest.mark.parametrize("text", [RUN, STAIRS], ids=["run", "stairs"])
def test_same_seed_same_bytes(tmp_path, text):
    scn = _write(tmp_path, text)
    a = simulate(scn, tmp_path / "a", seed=4)
    b = simulate(scn, tmp_path / "b", seed=4)
    c = simulate(scn, tmp_path / "c", seed=5)
    for f in ("left_foot_imu.csv", "right_foot_imu.csv", "truth.csv", "config.yaml"):
        assert _sha(a.out_dir / f) == _sha(b.out_dir / f), f
    assert _sha(a.out_dir / "left_foot_imu.csv") != _sha(c.out_dir / "left_foot_imu.csv")
    assert _sha(a.out_dir / "truth.csv") == _sha(c.out_dir / "truth.csv")


@pytest.mark.parametrize(("name", "overrides"), [
    ("sim_running.yaml", ["path.laps=1"]),
    ("sim_stairs.yaml", []),
])
def test_shipped_gait_scenarios_simulate_and_run(tmp_path, name, overrides):
    """The shipped layouts run as written (SHOE detector, ICM-20948), and with error-free
    IMUs and the true labels the foot INS follows the truth to centimetres."""
    res = simulate(CONFIGS / name, tmp_path / "sim", seed=0, overrides=overrides)
    raw = yaml.safe_load(res.config_path.read_text())
    validate_section(Layout, raw, key="", path=res.config_path, base_dir=res.out_dir)
    result = run_layout(load_layout(res.config_path))
    for foot, score in result.scores.items():
        assert score.metrics["horizontal_error_m"]["rmse"] < 0.5, foot
    exact = simulate(CONFIGS / name, tmp_path / "exact", seed=0, overrides=overrides + [
        f"systems.{foot}.imu.preset=perfect" for foot in ("left_foot", "right_foot")] + [
        f"layout.systems.{foot}.detector.kind=labels" for foot in ("left_foot", "right_foot")])
    result = run_layout(load_layout(exact.config_path))
    for foot, score in result.scores.items():
        assert score.metrics["horizontal_error_m"]["max"] < 0.03, foot
        assert score.metrics["vertical_error_m"]["max"] < 0.03, foot


@pytest.mark.parametrize(("gait", "key"), [
    ("{kind: jog}", "gait.kind"),
    ("{kind: run, roll: {heel_s: 0.1}}", "gait.roll"),
    ("{kind: run, roll: {heel_z: 0.1}}", "gait.roll.heel_z"),
    ("{kind: run, impact: {duration_s: 0.001}}", "gait.impact.duration_s"),
    ("{kind: stairs, stairs: {flights: [{direction: up, steps: 40}]}}", "gait.stairs.flights.0.steps"),
    ("{kind: stairs, stairs: {flights: [{direction: up}, {direction: down, steps: 2}]}}",
     "gait.stairs.flights.0.steps"),
    ("{kind: stairs, stairs: {flights: [{direction: sideways}]}}", "gait.stairs.flights.0.direction"),
    ("{pauses: [{at_s: 99, duration_s: 1}]}", "gait.pauses.0.at_s"),
    ("{pauses: [{at_s: 0.5, duration_s: 1}]}", "gait.pauses.0.at_s"),
    ("{pauses: [{at_s: 4, duration_s: 5}, {at_s: 6, duration_s: 1}]}", "gait.pauses.1.at_s"),
    ("{pauses: [{at_s: 3}]}", "gait.pauses.0.duration_s"),
])
def test_bad_gait_sections_name_the_key(tmp_path, gait, key):
    text = WALK.replace("gait: {start_still_s: 1, end_still_s: 0.5}", f"gait: {gait}")
    scn = _write(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        simulate(scn, tmp_path / "x")
    assert err.value.key == key
    assert str(scn) in str(err.value) and "\n" not in str(err.value)
