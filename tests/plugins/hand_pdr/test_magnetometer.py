"""Magnetometer heading aiding of the hand-held PDR: the measurement, the field check, the
offset state, and the filter on simulated walks whose truth is known."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import load_layout
from bodyfusion.core.layout_io import read_yaml
from bodyfusion.runner import run_layout
from bodyfusion.io.imu import ImuCsvConfig
from bodyfusion.plugins.hand_pdr import HandPdr
from bodyfusion.plugins.hand_pdr.config import FieldCheckConfig
from bodyfusion.plugins.hand_pdr.magnetometer import (
    device_azimuth,
    earth_like,
    read_magnetometer_csv,
)
from bodyfusion.sim import simulate
from bodyfusion.sim.magnetometer import MagnetometerSimConfig
from bodyfusion.testing import CHECKS, check_system, default_context, with_value
from tests.paths import CONFIGS, SHARED_DATA, needs_shared

SHORT = ["path.length_m=30", "path.width_m=20", "path.laps=1"]
MAG_ON = "systems.hand_phone.magnetometer={}"
IPIN = SHARED_DATA / "handheld_phone_ipin2023"


def _field(intensity: float, inclination_deg: float, declination_deg: float) -> np.ndarray:
    return MagnetometerSimConfig(intensity_uT=intensity, inclination_deg=inclination_deg,
                                 declination_deg=declination_deg).field_n()


def _wrap_deg(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


# --------------------------------------------------------------------------- the measurement


@settings(max_examples=200, deadline=None)
@given(azimuth=st.floats(-180, 180), pitch=st.floats(-70, 70), roll=st.floats(-70, 70),
       inclination=st.floats(-80, 80), declination=st.floats(-30, 30))
def test_tilt_compensated_azimuth_of_known_attitudes(azimuth, pitch, roll, inclination, declination):
    """Phone x axis at a known azimuth, pitched and rolled: the levelled compass heading plus
    the declination is that azimuth; the y axis reads 90° less (it points left)."""
    C_nb = Rotation.from_euler("ZYX", [90.0 - azimuth, pitch, roll], degrees=True).as_matrix()
    m_b = C_nb.T @ _field(48.0, inclination, declination)
    up_b = C_nb.T @ np.array([0.0, 0.0, 1.0])
    x_az = math.degrees(math.atan2(C_nb[0, 0], C_nb[1, 0]))  # the x axis's own azimuth (= azimuth unless vertical)
    psi_x = math.degrees(device_azimuth(m_b[None], up_b[None], np.array([1.0, 0, 0]))[0]) + declination
    assert abs(_wrap_deg(psi_x - x_az)) < 1e-6
    y_az = math.degrees(math.atan2(C_nb[0, 1], C_nb[1, 1]))
    psi_y = math.degrees(device_azimuth(m_b[None], up_b[None], np.array([0, 1.0, 0]))[0]) + declination
    assert abs(_wrap_deg(psi_y - y_az)) < 1e-6
    if abs(roll) < 1e-9:
        assert abs(_wrap_deg(psi_x - azimuth)) < 1e-6
        assert abs(_wrap_deg(psi_y - (azimuth - 90.0))) < 1e-6


def test_field_check_rejects_disturbed_samples():
    C_nb = Rotation.from_euler("ZYX", [30.0, 10.0, -5.0], degrees=True).as_matrix()
    up_b = C_nb.T @ np.array([0.0, 0.0, 1.0])
    earth = _field(48.8, 65.5, 4.0)
    stronger = earth + [0.0, 20.0, 0.0]  # a steel beam adds 20 µT northwards
    shallow_dip = _field(48.8, 40.0, 4.0)  # Earth's magnitude but bent towards the horizontal
    m_b = np.array([C_nb.T @ b for b in (earth, stronger, shallow_dip)])
    ups = np.tile(up_b, (3, 1))
    check = FieldCheckConfig(expected_uT=48.8, tolerance_uT=8.0, inclination_deg=65.5, inclination_tolerance_deg=10)
    assert earth_like(m_b, ups, check).tolist() == [True, False, False]
    magnitude_only = FieldCheckConfig(expected_uT=48.8, tolerance_uT=8.0)
    assert earth_like(m_b, ups, magnitude_only).tolist() == [True, False, True]
    assert earth_like(m_b, ups, None).all()


def test_csv_magnetometer_at_a_lower_rate_in_nanotesla(tmp_path):
    """Empty cells where the magnetometer has no sample; nT converted to µT."""
    rows = ["t,ax,ay,az,gx,gy,gz,mx,my,mz"]
    for k in range(40):
        mag = f"{20000 + k},0,-44000" if k % 4 == 0 else ",,"
        rows.append(f"{0.01 * k:.2f},0,0,9.8,0,0,0,{mag}")
    (tmp_path / "imu.csv").write_text("\n".join(rows) + "\n")
    d = ImuCsvConfig(path=tmp_path / "imu.csv", acc_columns=("ax", "ay", "az"), gyro_columns=("gx", "gy", "gz"),
                     time_column="t")
    t, m_uT = read_magnetometer_csv(d, ("mx", "my", "mz"), "nT")
    np.testing.assert_allclose(t, 0.04 * np.arange(10), atol=1e-12)
    np.testing.assert_allclose(m_uT[1], [20.004, 0.0, -44.0])


# --------------------------------------------------------------------------- simulated walks


@pytest.fixture(scope="module")
def biased_walk(tmp_path_factory) -> Path:
    """A 100 m walk without GNSS, the phone's gyro biased by 0.5 °/s about its z (≈ up) axis."""
    out = tmp_path_factory.mktemp("mag_biased")
    return simulate(CONFIGS / "foot_hand_gnss_outage.yaml", out, seed=3,
                    overrides=[*SHORT, MAG_ON, "systems.hand_phone.gnss=null",
                               "systems.hand_phone.imu.gyro_bias_radps=[0, 0, 0.0087]"]).config_path


def test_magnetometer_bounds_the_heading_of_a_biased_gyro_without_gnss(biased_walk):
    """Steps of the true length (0.7 m), so that the errors are the heading's: the gyro alone
    drifts 40° over the walk; with the magnetometer the error stays at a few metres (its
    hard-iron and tilt errors, a few degrees)."""
    errors = {}
    for on in (False, True):
        result = run_layout(load_layout(biased_walk, ["fuser.method=none", "heading_alignment.continuous=false",
                                                      "systems.hand_phone.step.length=constant",
                                                      f"systems.hand_phone.magnetometer.enabled={str(on).lower()}"]))
        errors[on] = result.scores["hand_phone"].horizontal_error_m
        if on:
            counts = result.systems["hand_phone"].diagnostics()["magnetometer"]
            assert counts["accepted"] > 60 and counts["rejected_field"] == 0
    rmse = {on: np.sqrt(np.mean(e**2)) for on, e in errors.items()}
    assert errors[False].max() > 10.0
    assert errors[True].max() < 0.5 * errors[False].max() and rmse[True] < 0.5 * rmse[False]


def test_offset_state_converges_to_the_holding_offset(tmp_path):
    """The phone held 25° to the right of the walking direction (mount yaw): from a prior of
    0 ± 30°, GNSS and the magnetometer estimate the offset ψ − ψ_d = −25°."""
    res = simulate(CONFIGS / "foot_hand_gnss_outage.yaml", tmp_path, seed=4,
                   overrides=[*SHORT, MAG_ON, "systems.hand_phone.mount_yaw_deg=25",
                              "systems.hand_phone.gnss.outages=[]"])
    loaded = load_layout(res.config_path, ["systems.hand_phone.magnetometer.offset_deg=0"])
    hand = HandPdr("hand_phone", loaded.system_configs["hand_phone"], default_context(tmp_path))
    hand.advance(hand.t_end)
    offset, sd = math.degrees(hand.x[8]), math.degrees(math.sqrt(hand.P[9, 9]))
    assert abs(offset + 25.0) < 3.0 and abs(offset + 25.0) < 3 * sd
    assert hand.diagnostics()["magnetometer"]["offset_deg"] == pytest.approx(offset)


def test_disturbance_zone_is_rejected_by_the_field_check(tmp_path):
    """A 30 µT disturbance around the first corner: its samples fail the field check."""
    zone = "systems.hand_phone.magnetometer={disturbances: [{position_m: [0, 30], radius_m: 6, field_uT: [0, 30, 0]}]}"
    res = simulate(CONFIGS / "foot_hand_gnss_outage.yaml", tmp_path, seed=1, overrides=[*SHORT, zone])
    loaded = load_layout(res.config_path)
    hand = HandPdr("hand_phone", loaded.system_configs["hand_phone"], default_context(tmp_path))
    hand.advance(hand.t_end)
    counts = hand.diagnostics()["magnetometer"]
    assert 3 <= counts["rejected_field"] <= 15 and counts["accepted"] > 60


def test_magnetometer_columns_leave_the_other_streams_alone(tmp_path):
    plain = simulate(CONFIGS / "foot_hand_gnss_outage.yaml", tmp_path / "a", seed=2, overrides=SHORT)
    mag = [simulate(CONFIGS / "foot_hand_gnss_outage.yaml", tmp_path / k, seed=2, overrides=[*SHORT, MAG_ON])
           for k in ("b", "c")]
    assert (mag[0].out_dir / "hand_phone_imu.csv").read_bytes() == (mag[1].out_dir / "hand_phone_imu.csv").read_bytes()
    a = np.genfromtxt(plain.out_dir / "hand_phone_imu.csv", delimiter=",", names=True)
    b = np.genfromtxt(mag[0].out_dir / "hand_phone_imu.csv", delimiter=",", names=True)
    assert b.dtype.names[-4:] == ("mag_x", "mag_y", "mag_z", "step")
    for col in a.dtype.names:
        np.testing.assert_array_equal(a[col], b[col])
    for f in ("hand_phone_gnss.csv", "left_foot_imu.csv"):
        assert (plain.out_dir / f).read_bytes() == (mag[0].out_dir / f).read_bytes()
    norm = np.linalg.norm(np.column_stack([b["mag_x"], b["mag_y"], b["mag_z"]]), axis=1)
    assert abs(np.median(norm) - 48.8) < 2.0


# --------------------------------------------------------------------------- contract and config


@pytest.fixture(scope="module")
def mag_walk(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("mag_walk")
    return simulate(CONFIGS / "foot_hand_gnss_outage.yaml", out, seed=1,
                    overrides=[*SHORT, MAG_ON, "systems.hand_phone.gnss.outages=[{start_s: 40, duration_s: 20}]"]
                    ).config_path


def test_hand_pdr_with_magnetometer_conforms(mag_walk):
    section = read_yaml(mag_walk)["systems"]["hand_phone"]
    assert section["magnetometer"]["enabled"] is True
    bad = [(with_value(section, "magnetometer.sigma_deg", 0.0), "magnetometer.sigma_deg"),
           (with_value(section, "magnetometer.field_check.tolerance_uT", -1.0),
            "magnetometer.field_check.tolerance_uT"),
           (with_value(section, "magnetometer.axis_b", [0.0, 0.0, 0.0]), "magnetometer.axis_b"),
           (with_value(section, "magnetometer.columns", None), "magnetometer.columns")]
    report = check_system(HandPdr, section, name="hand_phone", context=default_context(mag_walk.parent),
                          stochastic=False, checks=[c for c in CHECKS if c != "chunking"], bad_configs=bad)
    assert report.failed == []
    assert report.result("build").detail.startswith("error state of 10")


def test_bad_magnetometer_config_is_one_line_with_its_key(mag_walk):
    with pytest.raises(ConfigError) as err:
        load_layout(mag_walk, ["systems.hand_phone.magnetometer.gate_probability=1.5"])
    assert err.value.key == "systems.hand_phone.magnetometer.gate_probability"
    assert "\n" not in str(err.value)


@needs_shared("handheld_phone_ipin2023")
def test_ipin_indoor_field_fails_the_earth_field_check_but_is_quasi_static_while_read():
    """The museum's field reads 25–40 µT against the Earth's 48.8 µT: nearly every sample is
    rejected by the Earth-field check (the site's WMM values). Without it (the default) the
    quasi-static check keeps the samples taken while the phone is held to be read (from
    ~30 s on) and refuses those of the first 25 s, when it is carried and handled."""
    log = IPIN / "IPIN2023_T3_TrainingTrial01_repetition04.txt"
    wmm = "systems.hand_phone.magnetometer.field_check={expected_uT: 48.8, inclination_deg: 65.5}"
    loaded = load_layout(CONFIGS / "ipin2023_trial01.yaml", [f"systems.hand_phone.phone_log={log}", wmm])
    hand = HandPdr("hand_phone", loaded.system_configs["hand_phone"], default_context(CONFIGS))
    hand.advance(hand.t_end)
    counts = hand.diagnostics()["magnetometer"]
    assert counts["rejected_field"] > 0.9 * sum(counts.get(k) for k in ("accepted", "rejected_gate", "rejected_field",
                                                                       "rejected_turning"))
    loaded = load_layout(CONFIGS / "ipin2023_trial01.yaml", [f"systems.hand_phone.phone_log={log}"])
    hand = HandPdr("hand_phone", loaded.system_configs["hand_phone"], default_context(CONFIGS))
    mag = hand._mag
    assert mag.quasi_static[mag.t < 25.0].mean() < 0.1 and mag.quasi_static[mag.t > 60.0].mean() > 0.4


# --------------------------------------------------------------------------- the quasi-static check


def test_quasi_static_check_keeps_a_fixed_field_and_refuses_one_that_turns_on_its_own():
    """ψ_d follows the gyro (plus 1° noise) for 10 s, then wanders by ±30° at 0.5 Hz while the
    gyro does not turn (a bent field): the first kept, the second refused; the first window
    (not yet covered by data) is refused too."""
    from bodyfusion.plugins.hand_pdr.config import QuasiStaticConfig
    from bodyfusion.plugins.hand_pdr.magnetometer import quasi_static

    rng = np.random.default_rng(0)
    t = np.arange(0.0, 20.0, 0.02)
    psi_g = 0.3 * t  # turning at 0.3 rad/s
    psi_d = psi_g + 0.5 + np.deg2rad(1.0) * rng.standard_normal(t.size) + np.where(
        t > 10.0, np.deg2rad(30.0) * np.sin(np.pi * t), 0.0)
    keep = np.searchsorted(t, np.arange(1.0, 20.0))
    ok = quasi_static(t, np.angle(np.exp(1j * psi_d)), psi_g, keep, QuasiStaticConfig())
    assert not ok[0] and ok[1:9].all() and not ok[11:].any()
    assert quasi_static(t, psi_d, psi_g, keep, None).all()


def test_phone_log_defaults_are_those_of_an_android_phone_read_while_walking(tmp_path):
    """A phone log: magnetometer unset (on when the log has MAGN lines), device axis +y (the
    top of the screen), holding offset 0, gyro bias σ 0.01 rad/s; an IMU CSV: off, +x, auto, 0.002."""
    from bodyfusion.core.layout_io import validate_section
    from bodyfusion.plugins.hand_pdr.config import HandPdrConfig

    (tmp_path / "log.txt").write_text("")
    phone = validate_section(HandPdrConfig, {"phone_log": "log.txt", "gnss": {"format": "phone_log"}},
                             key="systems.h", path=None, base_dir=tmp_path)
    assert phone.magnetometer.enabled is None and phone.magnetometer.axis_b == (0.0, 1.0, 0.0)
    assert phone.magnetometer.offset_deg == 0.0 and phone.filter.gyro_bias_sd == 0.01
    (tmp_path / "imu.csv").write_text("t,ax,ay,az,gx,gy,gz\n")
    csv = validate_section(HandPdrConfig, {"imu": {"path": "imu.csv", "time_column": "t", "acc_columns": ["ax", "ay", "az"],
                                                   "gyro_columns": ["gx", "gy", "gz"]},
                                           "initial": {"position_m": [0, 0, 0], "heading_deg": 0}},
                           key="systems.h", path=None, base_dir=tmp_path)
    assert csv.magnetometer.enabled is False and csv.magnetometer.axis_b == (1.0, 0.0, 0.0)
    assert csv.magnetometer.offset_deg == "auto" and csv.filter.gyro_bias_sd == 0.002
