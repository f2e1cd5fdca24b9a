"""The trajectory files other tools read (bodyfusion.outputs.trajectories): trajectories.parquet beside
the CSV with velocity and attitude, TUM files for evo, track.geojson with times and truth, and the
reader of both tables (bodyfusion.io.trajectory_files)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pymap3d
import pytest

import bodyfusion
from bodyfusion.base.errors import InputError
from bodyfusion.base.types import NavigationFrame, Trajectory, TruthTrack
from bodyfusion.outputs import trajectories as exports
from bodyfusion.io.trajectory_files import MOTION_COLUMNS, MOTION_SD_COLUMNS, TRAJECTORY_COLUMNS, read_trajectories
from bodyfusion.nav.attitude import quat_from_azimuth_pitch_roll
from bodyfusion.outputs.trajectories import (
    GEOJSON_STEP_S,
    _json_floats,
    euler_deg,
    write_geojson,
    write_trajectories_csv,
    write_trajectories_parquet,
    write_tum,
)
from bodyfusion.core.layout import load_layout
from bodyfusion.outputs.write import write_outputs
from bodyfusion.results.run_result import RunResult
from bodyfusion.runner import run_layout
from bodyfusion.sim import simulate
from tests.paths import CONFIGS

ORIGIN = (49.4613, 11.1109, 390.0)


@pytest.fixture(scope="module")
def geo_run(tmp_path_factory) -> tuple[RunResult, Path]:
    """A 40 m foot + hand-phone walk about ``ORIGIN`` with truth, and the folder its outputs went to."""
    tmp = tmp_path_factory.mktemp("geo")
    sim = simulate(CONFIGS / "foot_hand_gnss_outage.yaml", tmp / "sim", seed=0,
                   overrides=["path.length_m=12", "path.width_m=6", "path.laps=1", "path.turn_radius_m=1",
                              "systems.hand_phone.gnss.outages=[]"])
    result = run_layout(load_layout(sim.config_path, ["output.plots=false"]))
    write_outputs(result, tmp / "out", "walk", 1.0)
    return result, tmp / "out"


def synthetic(n: int = 50) -> dict[str, Trajectory]:
    """Two systems, one giving its east-north covariance."""
    rng = np.random.default_rng(1)
    t = np.arange(n) * 0.01 + 3.0
    return {"foot": Trajectory(t, rng.normal(0, 5, (n, 3)), rng.uniform(0.1, 1, (n, 3)), rng.normal(0, 0.01, n)),
            "hand": Trajectory(t[::2], rng.normal(0, 5, (n // 2, 3)), rng.uniform(0.1, 1, (n // 2, 3)))}


def read_csv_rows(path: Path) -> tuple[list[str], np.ndarray]:
    with path.open() as fh:
        rows = list(csv.reader(fh))[1:]
    return [r[0] for r in rows], np.array([[float(v) if v else np.nan for v in r[1:]] for r in rows])


# --------------------------------------------------------------------------- trajectories.parquet


def test_parquet_holds_the_csv_values_typed_with_units_frame_and_provenance(geo_run):
    result, out = geo_run
    table = pq.read_table(out / "trajectories.parquet")
    names, values = read_csv_rows(out / "trajectories.csv")
    assert table.column_names == [*TRAJECTORY_COLUMNS, "cov_east_north_m2"]
    assert table.schema.field("system").type == pa.dictionary(pa.int32(), pa.string())
    assert all(table.schema.field(c).type == pa.float64() for c in table.column_names[1:])
    assert table.column("system").to_pylist() == names
    parquet = np.column_stack([table.column(c).to_numpy(zero_copy_only=False) for c in TRAJECTORY_COLUMNS[1:]])
    np.testing.assert_allclose(parquet, values, rtol=0, atol=5e-6)  # the CSV prints µs and 10 µm; null: empty
    cov = table.column("cov_east_north_m2").to_numpy(zero_copy_only=False)
    np.testing.assert_array_equal(cov, np.concatenate([tr.pos_cov_en for tr in result.trajectories.values()]))

    units = {f.name: f.metadata[b"unit"].decode() for f in table.schema if f.metadata and b"unit" in f.metadata}
    assert {k: v for k, v in units.items() if k[:3] not in ("v_e", "v_n", "v_u", "sd_") or k.endswith("_m")} == {
        "t": "s", "east_m": "m", "north_m": "m", "up_m": "m", "sd_east_m": "m", "sd_north_m": "m", "sd_up_m": "m",
        "qw": "1", "qx": "1", "qy": "1", "qz": "1", "roll_deg": "deg", "pitch_deg": "deg", "yaw_deg": "deg",
        "cov_east_north_m2": "m^2"}
    assert units["v_up_mps"] == units["sd_v_east_mps"] == "m/s" and units["sd_yaw_deg"] == "deg"
    meta = {k.decode(): v.decode() for k, v in table.schema.metadata.items()}
    assert meta["bodyfusion.version"] == bodyfusion.__version__
    assert meta["bodyfusion.config_sha256"] == result.loaded.sha256
    assert meta["bodyfusion.format_version"] == "2"
    frame = json.loads(meta["bodyfusion.frame"])
    assert frame["name"] == "ENU" and frame["unit"] == "m"
    assert frame["geodetic_origin"] == {"lat_deg": ORIGIN[0], "lon_deg": ORIGIN[1], "height_m": ORIGIN[2]}


def test_read_trajectories_round_trips_the_parquet_exactly_and_the_csv_to_its_precision(tmp_path):
    trajs = synthetic()
    write_trajectories_parquet(tmp_path / "t.parquet", trajs, config_sha256="0" * 64,
                               frame=NavigationFrame())
    write_trajectories_csv(tmp_path / "t.csv", trajs)
    from_parquet = read_trajectories(tmp_path / "t.parquet")
    from_csv = read_trajectories(tmp_path / "t.csv")
    assert list(from_parquet) == list(from_csv) == ["foot", "hand"]
    for name, tr in trajs.items():
        back = from_parquet[name]
        np.testing.assert_array_equal(back.t, tr.t)
        np.testing.assert_array_equal(back.pos_n, tr.pos_n)
        np.testing.assert_array_equal(back.pos_sd, tr.pos_sd)
        assert (back.pos_cov_en is None) == (tr.pos_cov_en is None)
        if tr.pos_cov_en is not None:
            np.testing.assert_array_equal(back.pos_cov_en, tr.pos_cov_en)
        np.testing.assert_allclose(from_csv[name].pos_n, tr.pos_n, rtol=0, atol=5e-6)
        assert from_csv[name].pos_cov_en is None  # the CSV has no covariance column
    frame = json.loads(pq.read_schema(tmp_path / "t.parquet").metadata[b"bodyfusion.frame"])
    assert frame["geodetic_origin"] is None


# --------------------------------------------------------------------------- TUM


def test_tum_files_are_eight_columns_increasing_times_unit_quaternions_and_the_positions(geo_run):
    result, out = geo_run
    expected = {**{n: tr for n, tr in result.trajectories.items()},
                **{f"{n}_truth": tr for n, tr in result.truths.items()}}
    assert {p.stem for p in (out / "tum").glob("*.txt")} == set(expected) == {
        "left_foot", "hand_phone", "left_foot_truth", "hand_phone_truth"}
    foot = result.systems["left_foot"].states()
    attitude = {"left_foot": np.column_stack([foot[k] for k in ("qx", "qy", "qz", "qw")])}  # the foot INS's, body to ENU
    for name, track in expected.items():
        rows = np.loadtxt(out / "tum" / f"{name}.txt", ndmin=2)
        assert rows.shape == (len(track.t), 8)
        assert np.all(np.diff(rows[:, 0]) > 0)
        np.testing.assert_array_equal(rows[:, 0], track.t)  # full precision
        np.testing.assert_array_equal(rows[:, 1:4], track.pos_n)
        np.testing.assert_allclose(np.linalg.norm(rows[:, 4:8], axis=1), 1.0)
        identity = np.tile([0.0, 0.0, 0.0, 1.0], (len(rows), 1))  # qx qy qz qw: the phone and the truth have none
        np.testing.assert_array_equal(rows[:, 4:8], attitude.get(name, identity))


def test_tum_text_is_what_the_csv_writer_prints_of_the_float64_columns(tmp_path, monkeypatch):
    """Times a truth shares with its system and the identity quaternion are printed once and
    reused: every file holds the bytes Arrow's CSV writer gives of its float64 columns."""
    import pyarrow.csv as pacsv

    monkeypatch.setattr(exports, "ROWS", 16)  # several pieces a file
    rng = np.random.default_rng(9)
    t = np.cumsum(rng.uniform(0.001, 0.02, 50))
    trajs = {"foot": Trajectory(t, rng.normal(scale=1e3, size=(50, 3)), np.ones((50, 3))),
             "hand": Trajectory(t[::2], rng.normal(size=(25, 3)), np.ones((25, 3)))}
    truths = {"foot": TruthTrack(t.copy(), rng.normal(size=(50, 3))),  # its system's times
              "hand": TruthTrack(t[::-1] * -1e-6, rng.normal(size=(50, 3)))}
    q = rng.normal(size=(50, 4))
    trajs["foot"].q_nb = q
    write_tum(tmp_path, trajs, truths)
    for name, (tt, pos, quat) in {"foot": (t, trajs["foot"].pos_n, q), "hand": (t[::2], trajs["hand"].pos_n, None),
                                  "foot_truth": (t, truths["foot"].pos_n, None),
                                  "hand_truth": (truths["hand"].t, truths["hand"].pos_n, None)}.items():
        quat = np.tile([1.0, 0.0, 0.0, 0.0], (len(tt), 1)) if quat is None else quat
        table = pa.table({k: v for k, v in zip(("t", "x", "y", "z", "qx", "qy", "qz", "qw"),
                                               (tt, *pos.T, *quat[:, [1, 2, 3, 0]].T))})
        pacsv.write_csv(table, tmp_path / "expected.txt",
                        pacsv.WriteOptions(include_header=False, delimiter=" ", quoting_style="none"))
        assert (tmp_path / f"{name}.txt").read_bytes() == (tmp_path / "expected.txt").read_bytes()


def test_tum_writes_a_truth_without_heights_at_zero_height(tmp_path):
    t = np.arange(5.0)
    truth = TruthTrack(t, np.column_stack([t, 2 * t, np.full(5, np.nan)]), sparse=True)
    write_tum(tmp_path, {}, {"foot": truth}, decimate=2)  # surveyed points are never decimated
    rows = np.loadtxt(tmp_path / "foot_truth.txt")
    np.testing.assert_array_equal(rows[:, :4], np.column_stack([t, t, 2 * t, np.zeros(5)]))


# --------------------------------------------------------------------------- GeoJSON


def test_geojson_lines_carry_times_and_sigma_and_round_trip_to_enu_within_a_millimetre(geo_run):
    result, out = geo_run
    doc = json.loads((out / "track.geojson").read_text())
    assert doc["type"] == "FeatureCollection"
    lines = {(f["properties"]["system"], f["properties"]["role"]): f for f in doc["features"]}
    assert set(lines) == {(n, r) for n in result.trajectories for r in ("estimate", "truth")}
    for (name, role), feature in lines.items():
        track = result.trajectories[name] if role == "estimate" else result.truths[name]
        geom, props = feature["geometry"], feature["properties"]
        assert feature["type"] == "Feature" and geom["type"] == "LineString"
        coords = np.array(geom["coordinates"])
        times = np.array(props["times"])
        assert coords.shape == (len(times), 3)
        assert np.all(np.abs(coords[:, 0] - ORIGIN[1]) < 0.01) and np.all(np.abs(coords[:, 1] - ORIGIN[0]) < 0.01)
        interval = np.floor((times[:-1] - times[0]) / GEOJSON_STEP_S + 1e-6)  # one vertex each, then the last
        assert np.all(np.diff(interval) > 0) and times[-1] > times[-2] and times[-1] == pytest.approx(track.t[-1])
        k = np.searchsorted(track.t, times - 1e-6)
        np.testing.assert_allclose(track.t[k], times, atol=1e-6)
        enu = np.column_stack(pymap3d.geodetic2enu(coords[:, 1], coords[:, 0], coords[:, 2], *ORIGIN))
        assert np.max(np.abs(enu - track.pos_n[k])) < 1e-3
        if role == "estimate":
            for axis, key in enumerate(("sd_east_m", "sd_north_m", "sd_up_m")):
                np.testing.assert_allclose(props[key], track.pos_sd[k, axis], atol=1e-5)


def test_geojson_gives_surveyed_truth_as_timed_points_and_2d_positions_without_heights(tmp_path):
    t = np.array([1.0, 5.0, 9.0])
    truth = TruthTrack(t, np.array([[0.0, 0.0, np.nan], [10.0, 0.0, np.nan], [10.0, 10.0, np.nan]]), sparse=True)
    write_geojson(tmp_path / "track.geojson", synthetic(), {"foot": truth}, ORIGIN)
    points = [f for f in json.loads((tmp_path / "track.geojson").read_text())["features"]
              if f["properties"]["role"] == "truth"]
    assert [p["properties"]["t"] for p in points] == [1.0, 5.0, 9.0]
    assert all(p["geometry"]["type"] == "Point" and len(p["geometry"]["coordinates"]) == 2 for p in points)
    lon, lat = points[1]["geometry"]["coordinates"]
    e, n, _ = pymap3d.geodetic2enu(lat, lon, 0.0, *ORIGIN)
    assert abs(e - 10.0) < 1e-3 and abs(n) < 1e-3


def test_geojson_numbers_are_printed_as_json_dumps_prints_them():
    """Arrow's text of a float (the shortest round-trip digits) turned into Python's, at every
    magnitude, whole numbers, signed zeros, NaN and the infinities included."""
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(1.0, 10.0, 50) * 10.0**e for e in range(-323, 308)])
    with np.errstate(over="ignore"):  # rounding to 1e-6 overflows (to inf, kept) above 1e302
        rounded = np.round(x, 6)
    x = np.concatenate([x, -x, rounded, np.floor(x), rng.integers(-2**62, 2**62, 5000).view(np.float64),
                        [0.0, -0.0, np.nan, np.inf, -np.inf, 1e-4, 9.999999999999999e-5, 1e9, 999999999.9999999,
                         2.0**53, 5e-324]])
    assert _json_floats(x).to_pylist() == [json.dumps(v) for v in x.tolist()]


def test_geojson_is_the_text_json_dumps_gives_of_the_document(tmp_path, monkeypatch):
    """The writer's pieces (Arrow-printed numbers, written a piece at a time) add up to
    ``json.dumps`` of the whole document."""
    monkeypatch.setattr(exports, "ROWS", 64)
    truth = TruthTrack(np.arange(400) * 0.05, np.random.default_rng(4).normal(size=(400, 3)))
    trajs = synthetic()
    write_geojson(tmp_path / "track.geojson", trajs, {"foot": truth}, ORIGIN)
    text = (tmp_path / "track.geojson").read_text()
    assert text == json.dumps(json.loads(text)) + "\n"


def test_the_csv_prints_each_number_rounded_to_its_unit_and_quotes_names_only_where_csv_needs_it(tmp_path):
    """µs and 10 µm, each the shortest decimal of the rounded number (what ``%.6f``/``%.5f``
    print, without their trailing zeros); names bare, all quoted when one holds a comma."""
    rng = np.random.default_rng(8)
    t = np.cumsum(rng.uniform(0.001, 0.02, 500))
    pos = rng.normal(scale=50.0, size=(500, 3))
    sd = rng.uniform(0.0, 2.0, size=(500, 3))
    trajs = {"foot": Trajectory(t, pos, sd), "hand, left": Trajectory(t, pos[::-1], sd[::-1])}
    write_trajectories_csv(tmp_path / "t.csv", trajs)
    rows = list(csv.reader((tmp_path / "t.csv").open()))
    assert rows[0] == list(TRAJECTORY_COLUMNS)
    lines = (tmp_path / "t.csv").read_text().splitlines()
    assert lines[1].startswith('"foot",') and lines[501].startswith('"hand, left",')
    write_trajectories_csv(tmp_path / "bare.csv", {"foot": trajs["foot"]})
    assert (tmp_path / "bare.csv").read_text().splitlines()[1].startswith("foot,")
    for k, (name, tr) in enumerate(trajs.items()):
        body = rows[1 + 500 * k:1 + 500 * (k + 1)]
        assert {r[0] for r in body} == {name}
        printed = [[float(f"{v:.6f}")] + [float(f"{x:.5f}") for x in (*p, *s)] for v, p, s in zip(tr.t, tr.pos_n, tr.pos_sd)]
        assert [[float(c) for c in r[1:8]] for r in body] == printed
        assert all(len(c.partition(".")[2]) <= (6 if j == 1 else 5) for r in body for j, c in enumerate(r[:8]) if j)
        assert all(c == "" for r in body for c in r[8:])  # no velocity, no attitude: empty cells


# --------------------------------------------------------------------------- velocity and attitude


def test_velocity_and_attitude_follow_the_positions_with_euler_angles_in_enu(tmp_path):
    """The contract's columns after the positions: the foot's velocity, quaternion and ZYX Euler
    angles (yaw counter-clockwise from East: 90° − azimuth), the σ columns empty without a
    covariance; a system without such states has empty cells; both files read back to what was
    written."""
    n = 40
    t = np.arange(n) * 0.01
    angles = np.column_stack([np.linspace(10.0, 350.0, n), np.linspace(-20.0, 20.0, n), np.linspace(5.0, -5.0, n)])
    q = np.array([quat_from_azimuth_pitch_roll(*np.radians(a)) for a in angles])
    vel = np.column_stack([np.sin(t), np.cos(t), 0.1 * t])
    foot = Trajectory(t, np.zeros((n, 3)), np.ones((n, 3)), vel_n=vel, q_nb=q)
    trajs = {"foot": foot, "hand": Trajectory(t, np.ones((n, 3)), np.ones((n, 3)))}
    roll_pitch_yaw = euler_deg(q)
    np.testing.assert_allclose(roll_pitch_yaw[:, :2], angles[:, [2, 1]], atol=1e-9)
    np.testing.assert_allclose(np.mod(90.0 - roll_pitch_yaw[:, 2], 360.0), angles[:, 0], atol=1e-9)
    write_trajectories_csv(tmp_path / "t.csv", trajs)
    write_trajectories_parquet(tmp_path / "t.parquet", trajs, config_sha256="0", frame=NavigationFrame())
    rows = list(csv.DictReader((tmp_path / "t.csv").open()))
    foot_rows = [r for r in rows if r["system"] == "foot"]
    np.testing.assert_allclose([[float(r[c]) for c in MOTION_COLUMNS] for r in foot_rows],
                               np.column_stack([vel, q, roll_pitch_yaw]), rtol=0, atol=5e-6)
    assert all(r[c] == "" for r in foot_rows for c in MOTION_SD_COLUMNS)
    assert all(r[c] == "" for r in rows if r["system"] == "hand" for c in (*MOTION_COLUMNS, *MOTION_SD_COLUMNS))
    table = pq.read_table(tmp_path / "t.parquet")
    assert table.schema.field("yaw_deg").metadata[b"unit"] == b"deg"
    assert table.schema.field("sd_v_east_mps").metadata[b"unit"] == b"m/s"
    for path, atol in ((tmp_path / "t.parquet", 0.0), (tmp_path / "t.csv", 5e-8)):
        back = read_trajectories(path)
        np.testing.assert_allclose(back["foot"].q_nb, q, rtol=0, atol=atol)
        np.testing.assert_allclose(back["foot"].vel_n, vel, rtol=0, atol=max(atol * 100, 0.0))
        assert back["hand"].vel_n is None and back["hand"].q_nb is None


def test_a_foot_runs_files_carry_its_filters_velocity_and_attitude_and_their_sigma(geo_run):
    result, out = geo_run
    back = read_trajectories(out / "trajectories.parquet")
    states = result.states("left_foot")
    np.testing.assert_array_equal(back["left_foot"].vel_n, states[["v_east_mps", "v_north_mps", "v_up_mps"]])
    np.testing.assert_array_equal(back["left_foot"].q_nb, states[["qw", "qx", "qy", "qz"]])
    assert back["hand_phone"].q_nb is None
    table = pq.read_table(out / "trajectories.parquet")
    foot = table.filter(pa.compute.equal(table.column("system"), "left_foot"))
    sd = np.column_stack([foot.column(c).to_numpy() for c in MOTION_SD_COLUMNS])
    assert np.all(np.isfinite(sd)) and np.all(sd[:, :3] >= 0) and np.all(sd[:, 7:] > 0)
    cov = result.trajectories["left_foot"].motion_cov
    np.testing.assert_array_equal(sd[:, :3], np.sqrt(cov[:, :3]))  # the filter's own velocity σ
    hand = table.filter(pa.compute.equal(table.column("system"), "hand_phone"))
    assert all(hand.column(c).null_count == hand.num_rows for c in MOTION_SD_COLUMNS)


@pytest.mark.parametrize("content", [b"garbage\x00\xff\n", b"system,t\xff\n", b"", b"\xff\xfe\x00"],
                         ids=["bytes", "header", "empty", "utf16-bom"])
def test_a_trajectory_file_that_is_not_one_is_an_input_error(tmp_path, content):
    for name in ("t.csv", "t.parquet"):
        (tmp_path / name).write_bytes(content)
        with pytest.raises(InputError, match=name):
            read_trajectories(tmp_path / name)
