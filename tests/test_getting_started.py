"""docs/getting_started.md: its layouts run as written, on the Vicon walk converted to the file
format the page shows (time in s, g and deg/s, z pointing down)."""

from __future__ import annotations

import csv
import json
import math
import re

import numpy as np
import pytest
import yaml

from tests.paths import EXAMPLE_DATA, ROOT
from tests.test_cli import fusion

PAGE = ROOT / "docs" / "getting_started.md"
VICON = EXAMPLE_DATA / "dual_foot_vicon_hu2025"
G = 9.80665


def yaml_blocks() -> list[dict]:
    return [yaml.safe_load(block) for block in re.findall(r"```yaml\n(.*?)```", PAGE.read_text(), re.S)]


def write_as_the_page_shows(side: str, path) -> None:
    """The walk's IMU file as ``t,ax,ay,az,gx,gy,gz``: s, g, deg/s, y and z turned round (z down)."""
    with (VICON / f"imuMeas{side}.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    sign = {"x": 1.0, "y": -1.0, "z": -1.0}
    out = ["t,ax,ay,az,gx,gy,gz"]
    for r in rows:
        acc = [sign[a] * float(r[f"acc_{a}"]) / G for a in "xyz"]
        gyro = [sign[a] * math.degrees(float(r[f"gyro_{a}"])) for a in "xyz"]
        out.append(",".join([f"{int(r['time_index']) / 60:.6f}", *(f"{v:.6f}" for v in acc + gyro)]))
    path.write_text("\n".join(out) + "\n")


def test_the_sample_row_on_the_page_is_the_walks_first_converted(tmp_path):
    write_as_the_page_shows("Left", tmp_path / "my_walk.csv")
    first = np.array(tmp_path.joinpath("my_walk.csv").read_text().splitlines()[1].split(","), dtype=float)
    shown = re.search(r"^0\.000000,.*$", PAGE.read_text(), re.M).group(0)
    np.testing.assert_allclose(first, np.array(shown.split(","), dtype=float), atol=1e-6)


@pytest.mark.slow
def test_the_one_foot_and_two_feet_layouts_validate_and_run_as_written(tmp_path):
    one, two, truth = yaml_blocks()
    write_as_the_page_shows("Left", tmp_path / "my_walk.csv")
    write_as_the_page_shows("Left", tmp_path / "my_left.csv")
    write_as_the_page_shows("Right", tmp_path / "my_right.csv")
    (tmp_path / "my_walk.yaml").write_text(yaml.safe_dump(one))
    assert fusion("validate", "my_walk.yaml", cwd=tmp_path).returncode == 0
    proc = fusion("run", "my_walk.yaml", "--out", "out/my_walk", "--set", "output.plots=false", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "out" / "my_walk" / "metrics.json").read_text())
    assert doc["systems"]["left_foot"]["samples"] > 7000
    # both feet with the body's limit, and a truth in the long format the page names
    with (VICON / "positionGt.csv").open() as fh:
        gt = list(csv.DictReader(fh))
    lines = ["system,t,east_m,north_m,up_m"] + [
        f"{foot}_foot,{int(r['time_index']) / 60:.6f},{r[f'pos_{foot}_x']},{-float(r[f'pos_{foot}_y'])},"
        f"{-float(r[f'pos_{foot}_z'])}" for foot in ("left", "right") for r in gt]
    (tmp_path / "my_truth.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "my_two_feet.yaml").write_text(yaml.safe_dump({**two, **truth}))
    proc = fusion("run", "my_two_feet.yaml", "--out", "out/two", "--set", "output.plots=false",
                  "--set", "smoother.kind=rts", cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "out" / "two" / "metrics.json").read_text())
    assert doc["constraints"]["epochs"] > 100
    for foot in ("left_foot", "right_foot"):
        assert doc["systems"][foot]["horizontal_error_m"]["rmse"] < 0.5
