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
