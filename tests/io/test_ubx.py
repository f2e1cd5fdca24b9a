"""u-blox UBX logs as GNSS fixes: the NAV-PVT messages of a log written with pyubx2 read back as
the CSV of the same fixes reads; fixes without a valid fix and other messages skipped and
counted; the GPS week's restart of the time of week carried over; a corrupt log refused."""

from __future__ import annotations

import numpy as np
import pytest

pyubx2 = pytest.importorskip("pyubx2")

from bodyfusion.base.errors import InputError  # noqa: E402
from bodyfusion.io.gnss import UBX_WEEK_S, read_gnss_csv, read_ubx  # noqa: E402


def _pvt(tow_ms: int, lat: float, lon: float, fix: int = 3, ok: int = 1) -> bytes:
    return pyubx2.UBXMessage("NAV", "NAV-PVT", pyubx2.GET, iTOW=tow_ms, fixType=fix, gnssFixOk=ok, numSV=12,
                             lat=lat, lon=lon, height=390_000 + tow_ms % 1000, hMSL=343_000, hAcc=1_500, vAcc=2_500,
                             gSpeed=1_250, headMot=45.0, sAcc=200, headAcc=5.0).serialize()


@pytest.fixture()
def ubx_log(tmp_path):
    """60 one-second fixes across a week's end (time of week restarts at 0), a no-fix PVT and a
    NAV-STATUS message among them."""
    tows = [UBX_WEEK_S * 1000 - 30_000 + 1000 * k for k in range(30)] + [1000 * k for k in range(30)]
    lats = 49.4613 + 1e-5 * np.arange(60)
    lons = 11.1109 + 1e-5 * np.arange(60)
    body = b"".join(_pvt(int(t), float(a), float(o)) for t, a, o in zip(tows, lats, lons))
    body += _pvt(40_000, 49.0, 11.0, fix=0, ok=0)
    body += pyubx2.UBXMessage("NAV", "NAV-STATUS", pyubx2.GET, iTOW=41_000, gpsFix=3).serialize()
    path = tmp_path / "walk.ubx"
    path.write_bytes(body)
    return path, np.array(tows, dtype=float) / 1000.0, lats, lons


def test_nav_pvt_fixes_read_as_the_csv_of_the_same_fixes(ubx_log, tmp_path):
    path, tows, lats, lons = ubx_log
    fixes = read_ubx(path)
    expected_t = np.where(np.arange(60) >= 30, tows + UBX_WEEK_S, tows)  # one clock across the week's end
    np.testing.assert_allclose(fixes.t, expected_t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fixes.lat_deg, lats, rtol=0, atol=1e-9)  # UBX carries 1e-7 deg
    np.testing.assert_allclose(fixes.accuracy_m, 1.5)
    np.testing.assert_allclose(fixes.speed_mps, 1.25)
    np.testing.assert_allclose(fixes.course_deg, 45.0)
    assert fixes.report.dropped_samples == 1 and "1 other message" in fixes.report.notes[-1]
    csv = tmp_path / "fixes.csv"
    rows = np.column_stack([fixes.t, fixes.lat_deg, fixes.lon_deg, fixes.height_m, fixes.accuracy_m,
                            fixes.speed_mps, fixes.course_deg])
    np.savetxt(csv, rows, delimiter=",", header="t,lat_deg,lon_deg,height_m,accuracy_m,speed_mps,course_deg",
               comments="", fmt="%.12g")
    again = read_gnss_csv(csv, time_column="t", lat_column="lat_deg", lon_column="lon_deg", height_column="height_m",
                          accuracy_column="accuracy_m", speed_column="speed_mps", course_column="course_deg")
    for name in ("t", "lat_deg", "lon_deg", "height_m", "accuracy_m", "speed_mps", "course_deg"):
        np.testing.assert_allclose(getattr(again, name), getattr(fixes, name), rtol=1e-11)


def test_a_corrupt_ubx_log_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "broken.ubx"
    good = _pvt(1000, 49.4613, 11.1109)
    path.write_bytes(good + good[:20] + b"\x00" * 10 + good[22:])  # a message with a damaged length and checksum
    with pytest.raises(InputError, match=r"broken\.ubx: not a UBX log"):
        read_ubx(path)


def test_a_phone_runs_from_a_ubx_log_as_from_the_csv_of_its_fixes(tmp_path):
    """The simulated foot + phone walk with its GNSS fixes as a UBX log (time of week = the
    run's clock): the phone's fused track is the CSV run's, to the UBX's 1e-7° and 1 mm."""
    import pandas as pd

    from bodyfusion.core.layout import load_layout
    from bodyfusion.runner import run_layout
    from bodyfusion.sim import simulate
    from tests.paths import CONFIGS

    sim = simulate(CONFIGS / "foot_hand_gnss_outage.yaml", tmp_path / "sim", seed=0,
                   overrides=["path.length_m=12", "path.width_m=6", "path.laps=1", "path.turn_radius_m=1"])
    fixes = pd.read_csv(tmp_path / "sim" / "hand_phone_gnss.csv")
    (tmp_path / "sim" / "walk.ubx").write_bytes(b"".join(pyubx2.UBXMessage(
        "NAV", "NAV-PVT", pyubx2.GET, iTOW=round(row.t * 1000), fixType=3, gnssFixOk=1, numSV=10,
        lat=row.lat_deg, lon=row.lon_deg, height=round(row.height_m * 1000), hAcc=round(row.accuracy_m * 1000),
        gSpeed=round(row.speed_mps * 1000), headMot=row.course_deg).serialize() for row in fixes.itertuples()))
    csv = run_layout(load_layout(sim.config_path, ["output.plots=false"]))
    ubx = run_layout(load_layout(sim.config_path, ["output.plots=false", "systems.hand_phone.gnss.format=ubx",
                                                   "systems.hand_phone.gnss.path=walk.ubx"]))
    a, b = csv.trajectories["hand_phone"], ubx.trajectories["hand_phone"]
    assert len(a.t) == len(b.t)
    np.testing.assert_allclose(b.pos_n, a.pos_n, rtol=0, atol=0.02)  # 7 mm here
