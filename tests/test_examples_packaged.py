"""``fusion example``: the packaged layouts, scenarios and study, and the recording they read,
written into a folder that runs without the repository (the wheel itself: ``.ci/run``)."""

from __future__ import annotations

import filecmp
import json
import shlex
from importlib.resources import files

import pytest
import yaml

from bodyfusion.examples import EXAMPLES
from bodyfusion.sim import load_scenario
from bodyfusion.study.validation import load_study
from tests.paths import CONFIGS, EXAMPLE_DATA, ROOT
from tests.test_cli import assert_one_line_user_error
from tests.test_cli_conventions import fusion_here


def test_list_names_every_example():
    proc = fusion_here("example", "--list")
    assert proc.returncode == 0, proc.stderr
    assert [line.split()[0] for line in proc.stdout.splitlines()] == list(EXAMPLES)
    assert {"dual_foot_vicon", "sim_dual_foot_square", "gnss_outage_study_smoke"} <= set(EXAMPLES)


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_packaged_files_are_the_repository_configs_with_data_paths_into_the_folder(name):
    """The packaged copies say what configs/ says (comments aside), data paths moved to data/."""
    for f in EXAMPLES[name].files:
        packaged = yaml.safe_load(files("bodyfusion.examples").joinpath("files", f).read_text())
        repository = (CONFIGS / f).read_text().replace("../examples/data/", "data/")
        assert packaged == yaml.safe_load(repository), f


def test_dual_foot_vicon_is_written_with_its_data_and_licence_and_runs_from_anywhere(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # not the repository
    proc = fusion_here("example", "dual_foot_vicon", "--out", "walk")
    assert proc.returncode == 0, proc.stderr
    assert "next: fusion run walk/dual_foot_vicon.yaml --out walk/out" in proc.stdout
    recording = tmp_path / "walk" / "data" / "dual_foot_vicon_hu2025"
    for f in ("imuMeasLeft.csv", "imuMeasRight.csv", "positionGt.csv", "positionMeas.csv", "LICENSE"):
        assert filecmp.cmp(recording / f, EXAMPLE_DATA / "dual_foot_vicon_hu2025" / f, shallow=False), f
    assert "MIT" in (tmp_path / "walk" / "README.md").read_text()

    proc = fusion_here("run", "walk/dual_foot_vicon.yaml", "--out", "walk/out", "--set", "output.plots=false")
    assert proc.returncode == 0, proc.stderr
    here = json.loads((tmp_path / "walk" / "out" / "metrics.json").read_text())
    monkeypatch.chdir(ROOT)
    proc = fusion_here("run", "configs/dual_foot_vicon.yaml", "--out", tmp_path / "repo", "--set", "output.plots=false")
    assert proc.returncode == 0, proc.stderr
    repo = json.loads((tmp_path / "repo" / "metrics.json").read_text())
    assert here["systems"]["left_foot"]["horizontal_error_m"] == repo["systems"]["left_foot"]["horizontal_error_m"]


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_every_example_written_is_valid_where_it_lands(name, tmp_path):
    """Each command's file (layout, scenario or study) validates in the written folder: every
    relative path in it resolves there."""
    folder = tmp_path / name
    assert fusion_here("example", name, "--out", folder).returncode == 0
    for command in EXAMPLES[name].commands:
        verb, path = shlex.split(command)[1:3]
        path = path.format(dir=folder)
        if verb == "simulate":
            load_scenario(path)
        elif verb == "study":
            load_study(path)
        elif "/sim/" not in path:  # a layout the example holds (not one a simulation writes)
            proc = fusion_here("validate", path)
            assert proc.returncode == 0, proc.stderr


def test_a_file_already_there_is_not_overwritten_and_names_are_checked(tmp_path):
    assert fusion_here("example", "sim_dual_foot_square", "--out", tmp_path).returncode == 0
    again = fusion_here("example", "sim_dual_foot_square", "--out", tmp_path)
    assert_one_line_user_error(again, "error:", "sim_dual_foot_square.yaml: exists; not overwritten")
    assert_one_line_user_error(fusion_here("example", "nope"), "error: no example 'nope'", "dual_foot_vicon")
    assert_one_line_user_error(fusion_here("example"), "error: name an example")
