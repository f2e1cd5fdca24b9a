"""The clean recording the fuzzing suite corrupts: a 12 m simulated walk with both feet's IMUs,
a phone (IMU, magnetometer, GNSS) and foot-to-foot UWB ranges, written in every input format
the framework reads — IMU CSV, truth CSV, GNSS CSV, NMEA 0183, a GetSensorData phone log,
UWB range CSV — and three layouts that read them."""

from __future__ import annotations

import csv
import datetime as dt
from pathlib import Path

import numpy as np
import pymap3d
import pynmea2
import yaml

from bodyfusion.sim import simulate

SCENARIO = {
    "name": "fuzz_base",
    "rate_hz": 100,
    "gravity_mps2": 9.80665,
    "geodetic_origin": [49.4613, 11.1109, 390.0],
    "path": {"kind": "polyline", "waypoints_m": [[0, 0], [0, 12]], "turn_radius_m": 1.0},
    "gait": {"stride_m": 1.4, "cadence_steps_per_min": 108, "stance_fraction": 0.6, "start_still_s": 2,
             "end_still_s": 1},
    "systems": {
        "left_foot": {"kind": "foot_imu", "foot": "left", "imu": {"preset": "icm20948"}},
        "right_foot": {"kind": "foot_imu", "foot": "right", "imu": {"preset": "icm20948"}},
        "hand_phone": {"kind": "hand_phone", "imu": {"preset": "phone"}, "offset_m": [0.3, -0.2, 1.1],
                       "magnetometer": {},
                       "gnss": {"rate_hz": 1, "white_sigma_m": 1.5, "gm_sigma_m": 3.0, "gm_tau_s": 60}},
        "feet_tags": {"kind": "uwb_tag", "host": "left_foot", "lever_arm_m": [0, 0, 0.05],
                      "peers": {"right_foot": [0, 0, 0.05]}, "rate_hz": 10, "sigma_m": 0.05},
    },
    "layout": {
        "constraints": [{"between": ["left_foot", "right_foot"], "kind": "max", "distance_m": 0.9},
                        {"between": ["left_foot", "hand_phone"], "kind": "max", "distance_m": 1.5}],
        "fuser": {"method": "projection", "epochs": "events", "correct": "positions", "cross_covariance": True},
    },
}

PHONE_LOG_START_S = 1_700_000_000.0
"""UTC epoch of the phone log's first sample (its GNSS lines carry UTC times)."""


def _rows(path: Path) -> tuple[list[str], np.ndarray]:
    with path.open() as f:
        header = next(csv.reader(f))
    return header, np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def _checksummed(body: str) -> str:
    return f"${body}*{pynmea2.NMEASentence.checksum(body):02X}"


def write_nmea(gnss_csv: Path, out: Path) -> None:
    """GGA and RMC sentences of the simulated fixes (time of day = the IMU's seconds)."""
    header, rows = _rows(gnss_csv)
    col = {name: rows[:, header.index(name)] for name in header}
    lines = []
    for k in range(len(rows)):
        t = dt.datetime(2026, 1, 1) + dt.timedelta(seconds=float(col["t"][k]))
        hms = t.strftime("%H%M%S.") + f"{t.microsecond // 10000:02d}"
        lat, lon = col["lat_deg"][k], col["lon_deg"][k]
        lat_s = f"{int(lat):02d}{(lat % 1) * 60:07.4f},N"
        lon_s = f"{int(lon):03d}{(lon % 1) * 60:07.4f},E"
        lines.append(_checksummed(f"GPGGA,{hms},{lat_s},{lon_s},1,09,{col['accuracy_m'][k] / 5:.1f},"
                                  f"{col['height_m'][k]:.1f},M,0.0,M,,"))
        lines.append(_checksummed(f"GPRMC,{hms},A,{lat_s},{lon_s},{col['speed_mps'][k] / 0.514444:.2f},"
                                  f"{col['course_deg'][k]:.1f},010126,,,A"))
    out.write_text("\n".join(lines) + "\n")


def write_phone_log(imu_csv: Path, gnss_csv: Path, truth_csv: Path, origin: list[float], out: Path) -> None:
    """A GetSensorData log of the phone: ACCE, GYRO, MAGN, GNSS and POSI lines every 2 s of the
    hand's truth."""
    header, imu = _rows(imu_csv)
    c = {name: imu[:, header.index(name)] for name in header}
    lines = ["% GetSensorData log written by the fuzzing suite", "% ACCE;AppTimestamp(s);SensorTimestamp(s);..."]
    for k in range(len(imu)):
        app, sensor = c["t"][k], 1000.0 + c["t"][k]
        lines.append(f"ACCE;{app:.3f};{sensor:.3f};{c['acc_x'][k]:.5f};{c['acc_y'][k]:.5f};{c['acc_z'][k]:.5f};3")
        lines.append(f"GYRO;{app:.3f};{sensor:.3f};{c['gyro_x'][k]:.5f};{c['gyro_y'][k]:.5f};{c['gyro_z'][k]:.5f};3")
        lines.append(f"MAGN;{app:.3f};{sensor:.3f};{c['mag_x'][k]:.3f};{c['mag_y'][k]:.3f};{c['mag_z'][k]:.3f};3")
    gh, gnss = _rows(gnss_csv)
    g = {name: gnss[:, gh.index(name)] for name in gh}
    for k in range(len(gnss)):
        lines.append(f"GNSS;{g['t'][k]:.3f};{PHONE_LOG_START_S + g['t'][k]:.3f};{g['lat_deg'][k]:.8f};"
                     f"{g['lon_deg'][k]:.8f};{g['height_m'][k]:.2f};{g['course_deg'][k]:.1f};"
                     f"{g['accuracy_m'][k]:.1f};{g['speed_mps'][k]:.2f};12;9")
    with truth_csv.open() as f:
        hand = [r for r in csv.DictReader(f) if r["system"] == "hand_phone"]
    for counter, r in enumerate(hand[::200], start=1):
        lat, lon, _ = pymap3d.enu2geodetic(float(r["east_m"]), float(r["north_m"]), 0.0, *origin)
        lines.append(f"POSI;{float(r['t']):.3f};{counter};{lat:.8f};{lon:.8f};0;1")
    out.write_text("\n".join(lines) + "\n")


def write_recording(folder: Path) -> dict[str, Path]:
    """Simulate the walk into ``folder`` and write the other formats and the three layouts
    (``csv``: every system, GNSS as CSV; ``nmea``: the same with GNSS as NMEA; ``phone_log``:
    the phone alone from its GetSensorData log, scored on the log's surveyed points)."""
    scenario = folder / "scenario.yaml"
    scenario.write_text(yaml.safe_dump(SCENARIO, sort_keys=False))
    config_path = simulate(scenario, folder, seed=0).config_path
    layout = yaml.safe_load(config_path.read_text())
    layout["output"] = {"plots": False}
    write_nmea(folder / "hand_phone_gnss.csv", folder / "hand_phone_gnss.nmea")
    write_phone_log(folder / "hand_phone_imu.csv", folder / "hand_phone_gnss.csv", folder / "truth.csv",
                    SCENARIO["geodetic_origin"], folder / "hand_phone_log.txt")
    nmea = yaml.safe_load(yaml.safe_dump(layout))
    nmea["systems"]["hand_phone"]["gnss"] = {"format": "nmea", "path": "hand_phone_gnss.nmea"}
    phone = {
        "name": "fuzz_phone_log",
        "systems": {"hand_phone": {"plugin": "hand_pdr", "phone_log": "hand_phone_log.txt",
                                   "gnss": {"format": "phone_log"},
                                   "initial": {"position_m": "gnss", "heading_deg": "gnss_track"}}},
        "truth": {"path": "hand_phone_log.txt", "format": "phone_log", "score_systems": ["hand_phone"],
                  "alignment": "none"},
        "output": {"plots": False},
    }
    layouts = {}
    for name, doc in (("csv", layout), ("nmea", nmea), ("phone_log", phone)):
        layouts[name] = folder / f"layout_{name}.yaml"
        layouts[name].write_text(yaml.safe_dump(doc, sort_keys=False))
    return layouts
