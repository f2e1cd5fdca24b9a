"""A run's result: frozen, built from what the run made without copying it, carrying its own
frame and units, and drawn by the figures as it is."""

from __future__ import annotations

import dataclasses
import json
import pickle

import pyarrow.parquet as pq
import pytest

from bodyfusion.base.types import NavigationFrame
from bodyfusion.core.layout import load_layout, validate_layout
from bodyfusion.evaluation.plots import plot_trajectories, write_run_plots
from bodyfusion.evaluation.report_data import read_run_folder
from bodyfusion.evaluation.scored_run import ScoredRun, ScoredTracks
from bodyfusion.runner import run, run_layout
from bodyfusion.sim.scenario import simulated
from tests.paths import CONFIGS


@pytest.fixture(scope="module")
def vicon():
    return run_layout(load_layout(CONFIGS / "dual_foot_vicon.yaml", ["output.plots=false"]))


def test_a_result_cannot_be_changed_after_the_run(vicon):
    with pytest.raises(dataclasses.FrozenInstanceError):
        vicon.scores = {}
    for mapping in (vicon.systems, vicon.trajectories, vicon.truths, vicon.scores, vicon.nees, vicon.timings_s):
        with pytest.raises(TypeError):
            mapping["left_foot"] = None
    assert isinstance(vicon.findings, tuple)


def test_a_result_is_built_from_the_runs_own_objects_without_copies(vicon):
    again = dataclasses.replace(vicon)
    for name in vicon.trajectories:
        assert again.trajectories[name] is vicon.trajectories[name]
        assert again.trajectories[name].pos_n is vicon.trajectories[name].pos_n
        assert again.systems[name] is vicon.systems[name]
    tracks = ScoredTracks.of(vicon)
    assert tracks.scores["left_foot"] is vicon.scores["left_foot"] and tracks.frame is vicon.frame


def test_two_feet_with_no_geographic_heading_are_in_the_left_foots_frame_and_say_so(vicon):
    assert vicon.frame == NavigationFrame(None, "left_foot")
    assert "left_foot's initial heading" in vicon.frame.describe()
    table = vicon.to_frame()
    assert table.attrs["frame"] == vicon.frame.to_dict() and table.attrs["units"]["position"] == "m"
    assert vicon.states("left_foot").attrs["units"]["velocity"] == "m/s"
    assert "truth's" in vicon.errors().attrs["frame"]


def test_a_run_with_gnss_is_in_a_north_referenced_frame_about_its_geodetic_origin():
    layout, tables = simulated(CONFIGS / "foot_hand_gnss_outage.yaml", 0).in_memory()
    result = run_layout(validate_layout(layout, None, CONFIGS, tables=tables))
    assert result.frame.heading_reference == "north"
    assert result.frame.geodetic_origin == result.loaded.layout.geodetic_origin


def test_the_frame_goes_to_metrics_json_and_the_parquet_schema_and_comes_back_from_the_folder(tmp_path):
    result, out = run(CONFIGS / "dual_foot_vicon.yaml", ["output.plots=false"], out_dir=tmp_path / "out")
    doc = json.loads((out / "metrics.json").read_text())
    assert NavigationFrame.from_dict(doc["frame"]) == result.frame
    meta = pq.read_schema(out / "trajectories.parquet").metadata
    assert json.loads(meta[b"bodyfusion.frame"]) == doc["frame"]
    assert read_run_folder(out).tracks.frame == result.frame


def test_the_figures_take_the_result_as_it_is_and_label_a_frame_whose_north_is_unknown(vicon, tmp_path):
    assert isinstance(vicon, ScoredRun)
    ax = plot_trajectories(vicon).axes[0]
    if vicon.transform.rotation_rad == 0.0:
        assert "left_foot" in ax.get_ylabel()
    names = [p.name for p in write_run_plots(tmp_path, vicon)]
    assert names == ["trajectory.png", "error_vs_time.png", "error_cdf.png", "nees.png"]


def test_the_figures_content_of_a_result_pickles_for_the_figure_process(vicon):
    tracks = pickle.loads(pickle.dumps(ScoredTracks.of(vicon)))
    assert list(tracks.trajectories) == list(vicon.trajectories) and tracks.frame == vicon.frame
    assert tracks.scores["left_foot"].metrics == vicon.scores["left_foot"].metrics
