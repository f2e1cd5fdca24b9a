"""HDF5 files as tables: a group's one-dimensional datasets, or a compound dataset's fields, as
columns (h5py); a foot INS runs from one as from the CSV it was made of."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

h5py = pytest.importorskip("h5py")

from bodyfusion.base.errors import InputError  # noqa: E402
from bodyfusion.core.layout import load_layout  # noqa: E402
from bodyfusion.io.hdf5 import read_group  # noqa: E402
from bodyfusion.runner import run_layout  # noqa: E402
from tests.paths import ROOT  # noqa: E402

CSV = ROOT / "examples" / "data" / "dual_foot_vicon_hu2025" / "imuMeasLeft.csv"
COLUMNS = ["acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z"]


@pytest.fixture(scope="module")
def h5(tmp_path_factory):
    """The Vicon walk's left IMU twice in one file: ``/imu/left`` a group of 1-D datasets, and
    ``/table`` a compound dataset of the same columns (as pandas or a logger writes a table)."""
    table = pd.read_csv(CSV)
    path = tmp_path_factory.mktemp("h5") / "walk.h5"
    with h5py.File(path, "w") as f:
        group = f.create_group("imu/left")
        group["t"] = table.time_index.to_numpy().astype(float)  # the sample counter, as in the CSV
        for c in COLUMNS:
            group[c] = table[c].to_numpy()
        group["label"] = np.array([b"x"] * len(table))  # a column that is no number
        records = np.zeros(len(table), dtype=[("t", "f8"), *((c, "f4") for c in COLUMNS)])
        records["t"] = table.time_index.to_numpy() / 60.0
        for c in COLUMNS:
            records[c] = table[c].to_numpy()
        f["table"] = records
    return path, table


def test_a_group_and_a_compound_dataset_read_as_columns(h5):
    path, table = h5
    group = read_group(path, "imu/left", ["t", *COLUMNS])
    np.testing.assert_array_equal(group["t"], table.time_index.to_numpy())
    for c in COLUMNS:
        np.testing.assert_array_equal(group[c], table[c].to_numpy())
    compound = read_group(path, "table", ["t", "gyro_z"])
    np.testing.assert_array_equal(compound["gyro_z"], table.gyro_z.to_numpy().astype(np.float32))


def test_what_is_not_there_is_refused_naming_what_is(h5):
    path, _ = h5
    with pytest.raises(InputError, match=r"no group or dataset 'imu/right'|no group or dataset"):
        read_group(path, "imu/right", ["t"])
    with pytest.raises(InputError, match=r"imu/left: no column\(s\) acc_w \(it has acc_x"):
        read_group(path, "imu/left", ["acc_w"])
    with pytest.raises(InputError, match=r"imu/left/label: not a one-dimensional numeric column"):
        read_group(path, "imu/left", ["label"])
    with pytest.raises(InputError, match="not an HDF5 file"):
        read_group(CSV, "imu/left", ["t"])


def test_a_foot_ins_runs_from_an_hdf5_group_as_from_the_csv(h5, write_yaml):
    path, _ = h5

    def run(data: dict, name: str):
        layout = write_yaml({"systems": {"left_foot": {"plugin": "foot_ins", "data": data,
                                                       "initial": {"stationary_s": 1.0}}},
                             "output": {"plots": False}}, name=name)
        return run_layout(load_layout(layout)).trajectories["left_foot"]

    h5_track = run({"path": str(path), "group": "imu/left", "time_column": "t", "time_scale": 1 / 60,
                    "acc_columns": COLUMNS[:3], "gyro_columns": COLUMNS[3:]}, "h5.yaml")
    csv_track = run({"path": str(CSV), "time_column": "time_index", "time_scale": 1 / 60, "acc_columns": COLUMNS[:3],
                     "gyro_columns": COLUMNS[3:]}, "csv.yaml")
    np.testing.assert_array_equal(h5_track.pos_n, csv_track.pos_n)  # the same numbers: the same bits
