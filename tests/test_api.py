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
