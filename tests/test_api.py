"""The library API at the package root: layouts from files, dicts and models, overrides as a
dict, runs in-process with their tables as DataFrames."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import bodyfusion as bf
from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import FuserConfig
from tests.paths import CONFIGS

WALKER = {"plugin": "random_walk", "velocity_mps": [1.0, 0.0, 0.0], "rate_hz": 20, "duration_s": 20,
          "increment_variance_m2": 4e-3}
WALKERS = {"systems": {"a": WALKER, "b": {**WALKER, "start_m": [0.0, 0.5, 0.0]}},
           "constraints": [{"between": ["a", "b"], "kind": "max", "distance_m": 0.6}],
           "fuser": {"method": "projection", "epochs": "interval", "interval_s": 0.5}}


def test_the_root_exports_the_api_beside_the_version():
    assert isinstance(bf.__version__, str)
    for name in ("load_layout", "run", "run_study", "Layout", "LoadedLayout", "RunResult"):
        assert name in bf.__all__ and callable(getattr(bf, name))
    with pytest.raises(AttributeError):
        bf.no_such_name  # noqa: B018


def test_a_layout_from_a_dict_from_models_and_from_a_file_agree(tmp_path):
    from_dict = bf.load_layout(WALKERS)
    from_models = bf.load_layout({**WALKERS, "fuser": FuserConfig(method="projection", epochs="interval",
                                                                   interval_s=0.5)})
    model = bf.Layout.model_validate(WALKERS)
    assert from_models.to_dict() == from_dict.to_dict() == bf.load_layout(model).to_dict()
    assert from_dict.path is None and from_dict.name == "layout"
    vicon = bf.load_layout(CONFIGS / "dual_foot_vicon.yaml", {"fuser.method": "qp"})
    assert vicon.fuser.method == "qp" and vicon.systems["left_foot"].data.path.is_file()


def test_a_dict_layout_names_the_bad_key_without_a_file():
    with pytest.raises(ConfigError, match=r"^constraints\.0\.between: unknown system 'c'"):
        bf.load_layout({**WALKERS, "constraints": [{"between": ["a", "c"], "distance_m": 1.0}]})


def test_overrides_apply_to_a_loaded_layout_and_leave_it_as_it_was():
    loaded = bf.load_layout(WALKERS)
    other = bf.load_layout(loaded, {"fuser.method": "none"})
    assert other.fuser.method == "none" and loaded.fuser.method == "projection"


def test_a_run_gives_its_trajectories_as_a_long_frame():
    result = bf.run(WALKERS)
    frame = result.to_frame()
    assert list(frame.columns[:9]) == ["system", "t", "east_m", "north_m", "up_m", "sd_east_m", "sd_north_m",
                                       "sd_up_m", "cov_east_north_m2"]
    for name, traj in result.trajectories.items():
        rows = frame[frame.system == name]
        np.testing.assert_array_equal(rows[["east_m", "north_m", "up_m"]].to_numpy(), traj.pos_n)
        np.testing.assert_array_equal(rows[["sd_east_m", "sd_north_m", "sd_up_m"]].to_numpy(), traj.pos_sd)


def test_an_edited_layout_runs_as_edited_and_hashes_as_edited(tmp_path):
    loaded = bf.load_layout(WALKERS)
    loaded.fuser.method = "none"
    result = bf.run(loaded, out_dir=tmp_path)
    assert result.fuser.epochs == 0 and result.constraint_events().empty
    doc = pd.read_json(tmp_path / "metrics.json", typ="series")
    assert doc["config_sha256"] == loaded.sha256 == bf.load_layout(WALKERS, {"fuser.method": "none"}).sha256


# --------------------------------------------------------------------------- in-memory data

VICON_DATA = CONFIGS.parent / "examples" / "data" / "dual_foot_vicon_hu2025"


def _vicon_frames() -> dict[str, pd.DataFrame]:
    return {name: pd.read_csv(VICON_DATA / f"{file}.csv")
            for name, file in (("left_foot", "imuMeasLeft"), ("right_foot", "imuMeasRight"), ("truth", "positionGt"))}


def _without_paths(loaded: bf.LoadedLayout) -> dict:
    raw = loaded.to_dict()
    for name in raw["systems"]:
        raw["systems"][name]["data"].pop("path")
    raw["truth"].pop("path")
    return raw


def test_an_in_memory_run_and_the_same_data_through_csv_give_the_same_trajectories():
    """The Vicon walk read by the CSV readers and the same numbers given as DataFrames (pandas
    parses them to the same doubles as the readers) run to the same bits."""
    from_files = bf.run(CONFIGS / "dual_foot_vicon.yaml")
    frames = _vicon_frames()
    layout = _without_paths(from_files.loaded)
    in_memory = bf.run(layout, data={"left_foot": frames["left_foot"], "right_foot": frames["right_foot"]},
                       truth=frames["truth"])
    for name, traj in from_files.trajectories.items():
        np.testing.assert_array_equal(in_memory.trajectories[name].pos_n, traj.pos_n)
        np.testing.assert_array_equal(in_memory.trajectories[name].pos_sd, traj.pos_sd)
    assert in_memory.scores["left_foot"].metrics == from_files.scores["left_foot"].metrics
    pd.testing.assert_frame_equal(in_memory.to_frame(), from_files.to_frame())


def test_numpy_arrays_by_column_are_a_table_too():
    frame = _vicon_frames()["left_foot"]
    arrays = {"time_index": frame["time_index"].to_numpy(), "acc": frame[["acc_x", "acc_y", "acc_z"]].to_numpy(),
              "gyro": frame[["gyro_x", "gyro_y", "gyro_z"]].to_numpy(), "is_zero_vel": frame["is_zero_vel"].to_numpy()}
    raw = _without_paths(bf.load_layout(CONFIGS / "dual_foot_vicon.yaml"))
    raw = {"systems": {"left_foot": raw["systems"]["left_foot"]}}
    a = bf.run(raw, data={"left_foot": arrays})
    b = bf.run(raw, data={"left_foot": frame})
    np.testing.assert_array_equal(a.trajectories["left_foot"].pos_n, b.trajectories["left_foot"].pos_n)


def test_bad_in_memory_data_names_the_system_column_and_row():
    frames = _vicon_frames()
    raw = _without_paths(bf.load_layout(CONFIGS / "dual_foot_vicon.yaml"))
    left = frames["left_foot"].copy()
    left.loc[17, "gyro_y"] = np.nan
    with pytest.raises(bf_input_error(), match=r"^systems\.left_foot\.data \(in-memory table\): NaN in column "
                                                r"'gyro_y' \(row 17\)$"):
        bf.run(raw, data={"left_foot": left, "right_foot": frames["right_foot"]})
    with pytest.raises(bf_input_error(), match=r"systems\.right_foot\.data \(in-memory table\): missing column 'acc_x'"):
        bf.run(raw, data={"left_foot": frames["left_foot"], "right_foot": frames["right_foot"].drop(columns="acc_x")})
    with pytest.raises(ConfigError, match=r"^systems\.right_foot\.data\.path: Field required"):
        bf.run(raw, data={"left_foot": frames["left_foot"]})
    with pytest.raises(ConfigError, match=r"^data\.nose: not a system of the layout"):
        bf.run(raw, data={"nose": frames["left_foot"]})


def test_the_imu_checks_run_on_in_memory_data():
    frames = _vicon_frames()
    raw = _without_paths(bf.load_layout(CONFIGS / "dual_foot_vicon.yaml"))
    raw["systems"]["left_foot"]["data"]["gyro_unit"] = "deg/s"  # the numbers are rad/s
    result = bf.run(raw, data={"left_foot": frames["left_foot"], "right_foot": frames["right_foot"]},
                    truth=frames["truth"])
    warned = [w for w in result.input_report.warnings if w.startswith("systems.left_foot.data (in-memory table)")]
    assert any("gyro_unit" in w for w in warned)


def test_truth_by_system_in_enu_columns():
    result = bf.run(WALKERS)
    truth = {name: pd.DataFrame({"t": s.t, "east_m": s.truth_pos_n[:, 0], "north_m": s.truth_pos_n[:, 1],
                                 "up_m": s.truth_pos_n[:, 2]}) for name, s in result.systems.items()}
    scored = bf.run({**WALKERS, "truth": {"alignment": "none"}}, truth=truth)
    assert set(scored.scores) == {"a", "b"}
    frame = scored.truth_frame()
    np.testing.assert_array_equal(frame.loc[frame.system == "b", "north_m"], truth["b"]["north_m"])


def bf_input_error():
    from bodyfusion.base.errors import InputError

    return InputError


# --------------------------------------------------------------------------- simulation in memory

SCENARIO = {
    "name": "api_walk", "rate_hz": 100,
    "path": {"kind": "rectangle", "length_m": 12, "width_m": 6, "laps": 1, "clockwise": True},
    "gait": {"start_still_s": 3, "end_still_s": 1},
    "systems": {
        "left_foot": {"kind": "foot_imu", "foot": "left", "imu": {"preset": "icm20948"}},
        "hand_phone": {"kind": "hand_phone", "magnetometer": {}},
        "tag": {"kind": "uwb_tag", "host": "left_foot", "rate_hz": 10, "dropout_probability": 0.05,
                "anchors": {"A1": [-3.0, -3.0, 2.0], "A2": [-3.0, 15.0, 2.0], "A3": [10.0, 15.0, 2.0]}},
    },
    "layout": {"constraints": [{"between": ["left_foot", "hand_phone"], "distance_m": 1.5}]},
}


@pytest.fixture(scope="module")
def simulated_walk(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    sim = bf.simulate(SCENARIO, seed=4, out_dir=out)
    return sim, bf.run(sim.layout), bf.run(out / "config.yaml")


def test_a_simulation_in_memory_runs_as_its_written_files_do(simulated_walk):
    """The streams handed over in memory hold what the files hold: the run on them equals
    ``fusion simulate`` + ``fusion run`` on the files, bit for bit (IMUs, GNSS, magnetometer,
    UWB ranges and truth)."""
    sim, in_memory, from_files = simulated_walk
    assert set(sim.data) == {"left_foot", "hand_phone", "tag"} and set(sim.data["hand_phone"]) == {"imu", "gnss"}
    assert all(section.path is None for section in (sim.layout.systems["left_foot"].data,
                                                     sim.layout.systems["tag"].ranges, sim.layout.truth))
    for name, traj in from_files.trajectories.items():
        np.testing.assert_array_equal(in_memory.trajectories[name].pos_n, traj.pos_n)
        np.testing.assert_array_equal(in_memory.trajectories[name].pos_sd, traj.pos_sd)
    pd.testing.assert_frame_equal(in_memory.innovations(), from_files.innovations())
    pd.testing.assert_frame_equal(in_memory.constraint_events(), from_files.constraint_events())
    assert in_memory.scores["hand_phone"].metrics == from_files.scores["hand_phone"].metrics
    assert sim.written is not None and sim.written.config_path.is_file()


def test_every_plugin_gives_its_results_in_the_shared_names(simulated_walk):
    _, result, _ = simulated_walk
    hand = result.states("hand_phone")
    assert {"t", "east_m", "north_m", "up_m", "heading_deg", "holding_offset_deg"} <= set(hand.columns)
    np.testing.assert_array_equal(hand["t"], result.trajectories["hand_phone"].t)
    cov = result.covariances("hand_phone")
    assert cov.states[:3] == ("east_m", "north_m", "up_m") and cov.matrix.shape == (len(hand), 10, 10)
    assert not np.isnan(cov.matrix).any()
    events = result.events()
    assert set(events.event) == {"stance", "step"}
    assert events.loc[events.event == "step", "length_m"].between(0.2, 1.5).all()
    aiding = set(result.innovations().groupby(["system", "aiding"]).size().index)
    assert {("hand_phone", "gnss_position"), ("hand_phone", "magnetometer"), ("tag", "anchor_range")} <= aiding
    frame = result.to_frame()
    assert frame.loc[frame.system == "hand_phone", "heading_deg"].notna().all()
    assert frame.loc[frame.system == "hand_phone", "v_east_mps"].isna().all()


# --------------------------------------------------------------------------- the documented examples

README = CONFIGS.parent / "README.md"


def test_the_readmes_python_snippet_runs_a_dict_layout_on_in_memory_data(monkeypatch):
    text = README.read_text()
    section = text[text.index("## From Python"):]
    snippet = section[section.index("```python\n") + 10:section.index("\n```", section.index("```python"))]
    assert len(snippet.splitlines()) <= 10
    monkeypatch.chdir(CONFIGS.parent)
    scope: dict = {}
    exec(compile(snippet, "README.md", "exec"), scope)  # noqa: S102 - the README's own code
    frame = scope["frame"]
    assert isinstance(frame, pd.DataFrame) and len(frame) > 7000 and {"east_m", "heading_deg"} <= set(frame.columns)


def test_the_notebook_example_runs(capsys):
    import runpy

    runpy.run_path(str(CONFIGS.parent / "examples" / "notebook_api.py"), run_name="__main__")
    out = capsys.readouterr().out
    for shown in ("refused:", "gnss_position", "zupt", "left_foot-hand_phone", "stance"):
        assert shown in out
