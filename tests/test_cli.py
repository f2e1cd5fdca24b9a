"""Tests of the command line (docs/contract.md), run as a user runs it: in a subprocess.

User errors: non-zero exit, exactly one line on stderr naming the file (and line, or the
config key's dotted path), never a Python traceback.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from tests.paths import ROOT

XIO_CFG = "configs/xio_long_walk.yaml"
VICON_CFG = "configs/dual_foot_vicon.yaml"
VICON_LEFT = ROOT / "examples" / "data" / "dual_foot_vicon_hu2025" / "imuMeasLeft.csv"

VICON_CFG_TEXT = (ROOT / VICON_CFG).read_text().replace("../examples/", str(ROOT / "examples") + "/")
"""The Vicon layout with its data paths absolute, to edit into a broken copy."""
CONTRACT_HEADER = ("system,t,east_m,north_m,up_m,sd_east_m,sd_north_m,sd_up_m,v_east_mps,v_north_mps,v_up_mps,"
                   "qw,qx,qy,qz,roll_deg,pitch_deg,yaw_deg,sd_v_east_mps,sd_v_north_mps,sd_v_up_mps,sd_qw,sd_qx,"
                   "sd_qy,sd_qz,sd_roll_deg,sd_pitch_deg,sd_yaw_deg")
"""docs/contract.md's header of trajectories.csv, written out."""


def fusion(*args: str, cwd: Path = ROOT, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bodyfusion.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout)


def assert_one_line_user_error(proc: subprocess.CompletedProcess, *fragments: str) -> str:
    assert proc.returncode != 0, proc.stdout
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip("\n").splitlines()
    assert len(lines) == 1, proc.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


def layout_text(data_path: Path | str, extra_filter: str = "") -> str:
    return (
        "name: one_foot\n"
        "systems:\n"
        "  foot:\n"
        "    plugin: foot_ins\n"
        "    data:\n"
        f"      path: {data_path}\n"
        "      time_column: time_index\n"
        "      time_scale: 0.016666666666666666\n"
        "      acc_columns: [acc_x, acc_y, acc_z]\n"
        "      gyro_columns: [gyro_x, gyro_y, gyro_z]\n"
        "      stance_column: is_zero_vel\n"
        "    detector: {kind: labels}\n"
        f"{extra_filter}"
        "output: {plots: false}\n"
    )


# --------------------------------------------------------------------------- plugins / validate


def test_plugins_lists_foot_ins_with_its_package_and_version():
    proc = fusion("plugins")
    assert proc.returncode == 0, proc.stderr
    rows = [ln.split() for ln in proc.stdout.splitlines() if ln.strip()]
    foot = [r for r in rows if r[0] == "foot_ins"]
    assert len(foot) == 1, proc.stdout
    assert "bodyfusion" in foot[0]
    assert foot[0][foot[0].index("bodyfusion") + 1] == version("bodyfusion")


def test_validate_good_config_prints_ok_and_exits_0():
    proc = fusion("validate", VICON_CFG)
    assert proc.returncode == 0, proc.stderr
    assert "ok" in proc.stdout
    assert "left_foot" in proc.stdout and "right_foot" in proc.stdout
    assert proc.stderr == ""


def test_validate_bad_config_one_line_with_file_and_dotted_key(tmp_path):
    cfg = tmp_path / "typo.yaml"
    cfg.write_text(layout_text(VICON_LEFT, "    filter:\n      acc_noise_densty: 0.02\n"))
    proc = fusion("validate", cfg)
    line = assert_one_line_user_error(proc, "typo.yaml", "systems.foot.filter.acc_noise_densty")
    assert "unknown key" in line
    assert proc.stdout == ""


def test_validate_yaml_syntax_error_names_file_and_line(tmp_path):
    cfg = tmp_path / "broken.yaml"
    cfg.write_text("name: x\nsystems:\n  foot: {plugin: foot_ins\n  other: 1\n")
    assert_one_line_user_error(fusion("validate", cfg), f"{cfg}:4")


def test_validate_warns_of_files_on_another_clock(tmp_path):
    imu = tmp_path / "imu.csv"
    imu.write_text(VICON_LEFT.read_text())
    truth = tmp_path / "truth.csv"
    truth.write_text("t,x,y,z\n5000,0,0,0\n5100,1,0,0\n")
    cfg = tmp_path / "clocks.yaml"
    cfg.write_text(layout_text(imu) + f"truth: {{path: {truth}, time_column: t, systems: {{foot: [x, y, z]}}}}\n")
    proc = fusion("validate", cfg)
    assert proc.returncode == 0 and "ok" in proc.stdout
    assert "warning: systems.foot.data (0–" in proc.stderr and "and truth (5000–5100 s) do not overlap" in proc.stderr


def test_validate_lists_every_file_and_column_problem_at_once(tmp_path):
    """A column the IMU file lacks and one the truth lacks, then a missing file beside the truth's:
    every problem, one line each naming the layout and the key, exit 2 — not the first of them."""
    imu = tmp_path / "imu.csv"
    imu.write_text(VICON_LEFT.read_text().replace("acc_y", "accel_y", 1))
    truth = tmp_path / "truth.csv"
    truth.write_text("t,x,y,z\n0,0,0,0\n1,1,0,0\n")
    cfg = tmp_path / "broken.yaml"
    cfg.write_text(layout_text(imu) + f"truth: {{path: {truth}, time_column: t, systems: {{foot: [x, y, height]}}}}\n")
    proc = fusion("validate", cfg)
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert len(errors) == 2, proc.stderr
    assert any("systems.foot.data: imu.csv has no column(s) acc_y" in e for e in errors)
    assert any("truth: truth.csv has no column(s) height" in e for e in errors)
    (tmp_path / "imu.csv").unlink()
    errors = [line for line in fusion("validate", cfg).stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 2 and any("systems.foot.data.path" in e and "file not found" in e for e in errors)


def test_validate_lists_every_schema_error_of_every_section_and_run_names_the_first(tmp_path):
    """Errors in the layout's own sections and in two systems' plugin sections: validate gives
    every one, one line each; run gives the first on its one line and says how many more."""
    cfg = tmp_path / "four.yaml"
    text = VICON_CFG_TEXT.replace("fuser: {method: projection, epochs: events, correct: positions}",
                                  "fuser: {method: projection, epochs: events, correct: positions, interval_s: 1.0e-5}")
    text = text.replace("    initial: {stationary_s: 1.0}\n  right_foot:",
                        "    initial: {stationary_s: -1.0}\n  right_foot:")
    text = text.replace("    detector: {kind: labels, min_stance_s: 0.05, min_swing_s: 0.05}   # drop 1–3 sample label "
                        "flickers\n    initial: {stationary_s: 1.0}\n# A foot",
                        "    detector: {kind: bogus}\n    initial: {stationary_s: 1.0}\n# A foot")
    cfg.write_text(text + "body: {height_m: 50}\n")
    proc = fusion("validate", cfg)
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    keys = ["body.height_m", "fuser.interval_s", "systems.left_foot.initial.stationary_s",
            "systems.right_foot.detector.kind"]
    assert [next(k for k in keys if f": {k}: " in e) for e in errors] == keys, errors
    run = fusion("run", cfg, "--out", tmp_path / "out")
    assert run.returncode == 2 and run.stderr.strip().count("\n") == 0
    assert "body.height_m" in run.stderr and "(and 3 more: fusion validate lists every one)" in run.stderr


def test_validate_missing_config_file(tmp_path):
    assert_one_line_user_error(fusion("validate", tmp_path / "absent.yaml"), "absent.yaml")


def test_set_bogus_fuser_method_is_refused_with_the_key_path():
    proc = fusion("run", XIO_CFG, "--set", "fuser.method=bogus")
    assert_one_line_user_error(proc, "fuser.method", "xio_long_walk.yaml")
    proc = fusion("validate", XIO_CFG, "--set", "fuser.method=bogus")
    assert_one_line_user_error(proc, "fuser.method")


def test_bad_set_form_is_one_line():
    assert_one_line_user_error(fusion("validate", XIO_CFG, "--set", "nokey"), "nokey")


# --------------------------------------------------------------------------- run: bad data


def test_run_missing_data_file_names_that_file(tmp_path):
    cfg = tmp_path / "layout.yaml"
    cfg.write_text(layout_text("no_such_imu.csv"))
    proc = fusion("run", cfg, "--out", tmp_path / "out")
    line = assert_one_line_user_error(proc, str(tmp_path / "no_such_imu.csv"))
    assert "not found" in line


def test_run_non_numeric_cell_names_file_and_line(tmp_path):
    lines = VICON_LEFT.read_text().splitlines()[:601]
    bad_line = 123  # 1-based file line, as an editor shows it
    cells = lines[bad_line - 1].split(",")
    cells[3] = "9.8x"
    lines[bad_line - 1] = ",".join(cells)
    data = tmp_path / "bad.csv"
    data.write_text("\n".join(lines) + "\n")
    cfg = tmp_path / "layout.yaml"
    cfg.write_text(layout_text("bad.csv"))
    proc = fusion("run", cfg, "--out", tmp_path / "out")
    line = assert_one_line_user_error(proc, f"{data}:{bad_line}")
    assert "acc_z" in line
    assert not (tmp_path / "out" / "metrics.json").exists()


# --------------------------------------------------------------------------- run: the real walk


@pytest.fixture(scope="module")
def xio_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("xio") / "out"
    proc = fusion("run", XIO_CFG, "--out", out)
    return proc, out


@pytest.mark.slow
def test_run_xio_exits_0(xio_run):
    proc, out = xio_run
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert (out / "metrics.json").is_file()
    assert (out / "trajectories.csv").is_file()


def test_run_xio_metrics_json_has_the_contract_keys(xio_run):
    proc, out = xio_run
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["config"] == XIO_CFG
    assert isinstance(doc["config_sha256"], str) and len(doc["config_sha256"]) == 64
    int(doc["config_sha256"], 16)
    assert "alignment" in doc
    foot = doc["systems"]["foot"]
    assert foot["samples"] == 28132 - 252  # rows in the file minus the dropped ones
    assert 50.0 < foot["distance_m"] < 70.0  # a ~60 m walk
    assert 0.0 <= foot["loop_closure_m"] < 2.0  # the walk is a loop
    assert "horizontal_error_m" not in foot  # no truth
    assert "constraints" not in doc  # no constraints
    assert doc["input"]["dropped_samples"] == 252
    assert doc["input"]["reordered_samples"] == 0
    assert doc["runtime"]["samples_per_s"] > 0
    assert doc["runtime"]["samples"] == foot["samples"]
    assert doc["runtime"]["wall_s"] > 0


def test_run_xio_trajectories_csv_has_the_contract_header(xio_run):
    proc, out = xio_run
    with (out / "trajectories.csv").open() as fh:
        header = fh.readline().rstrip("\n")
        rows = list(csv.reader(fh))
    assert header == CONTRACT_HEADER
    doc = json.loads((out / "metrics.json").read_text())
    assert len(rows) == doc["systems"]["foot"]["samples"]
    assert {r[0] for r in rows} == {"foot"}
    t = [float(r[1]) for r in rows]
    assert all(b > a for a, b in zip(t, t[1:]))
    assert all(len(r) == len(CONTRACT_HEADER.split(",")) for r in rows)
    assert all(float(r[5]) >= 0 and float(r[6]) >= 0 and float(r[7]) >= 0 for r in rows[::500])
    # loop: last position near the first, as metrics.json says
    first, last = rows[0], rows[-1]
    gap = ((float(last[2]) - float(first[2])) ** 2 + (float(last[3]) - float(first[3])) ** 2) ** 0.5
    assert gap == pytest.approx(doc["systems"]["foot"]["loop_closure_m"], abs=1e-4)


def test_run_xio_writes_parquet_and_tum_and_no_geojson_without_a_geodetic_origin(xio_run):
    _, out = xio_run
    with (out / "trajectories.csv").open() as fh:
        rows = sum(1 for _ in fh) - 1
    assert pq.read_metadata(out / "trajectories.parquet").num_rows == rows
    assert [p.name for p in (out / "tum").iterdir()] == ["foot.txt"]  # no truth, no truth file
    assert not (out / "track.geojson").exists()


def test_run_xio_prints_a_summary(xio_run):
    proc, out = xio_run
    assert "foot" in proc.stdout
    assert "samples" in proc.stdout


def test_run_config_error_found_by_the_plugin_names_the_file(tmp_path):
    cfg = tmp_path / "nolabels.yaml"
    cfg.write_text(layout_text(VICON_LEFT).replace("      stance_column: is_zero_vel\n", ""))
    proc = fusion("run", cfg, "--out", tmp_path / "out")
    assert_one_line_user_error(proc, "systems.foot.detector.kind", "nolabels.yaml")
