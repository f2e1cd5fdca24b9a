"""Robot recordings as tables: a topic of a ROS 2 bag (MCAP storage), an MCAP file or a ROS 1 bag
read with rosbags, its messages' field paths as columns; a foot INS runs from one as from the
CSV it was made of."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from bodyfusion.base.errors import InputError  # noqa: E402
from bodyfusion.core.layout import load_layout  # noqa: E402
from bodyfusion.io.ros import RECEIVE_TIME, read_topic  # noqa: E402
from bodyfusion.runner import run_layout  # noqa: E402
from tests.paths import ROOT  # noqa: E402

VICON = ROOT / "examples" / "data" / "dual_foot_vicon_hu2025"
ACC = ["linear_acceleration.x", "linear_acceleration.y", "linear_acceleration.z"]
GYRO = ["angular_velocity.x", "angular_velocity.y", "angular_velocity.z"]


def _imu_messages(store_name: Stores):
    """(stamp ns, message) of the Vicon walk's left foot IMU as sensor_msgs/Imu (60 Hz)."""
    store = get_typestore(store_name)
    imu, header, vector, quaternion = (store.types[t] for t in (
        "sensor_msgs/msg/Imu", "std_msgs/msg/Header", "geometry_msgs/msg/Vector3", "geometry_msgs/msg/Quaternion"))
    time = store.types["builtin_interfaces/msg/Time"]
    table = pd.read_csv(VICON / "imuMeasLeft.csv")
    out = []
    for k, row in enumerate(table.itertuples(index=False)):
        ns = 1_000_000_000 + round(row.time_index * 1e9 / 60)
        fields = dict(stamp=time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="imu_left")
        if store_name == Stores.ROS1_NOETIC:
            fields["seq"] = k
        out.append((ns, imu(header=header(**fields), orientation=quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
                                orientation_covariance=np.full(9, -1.0),
                                angular_velocity=vector(x=row.gyro_x, y=row.gyro_y, z=row.gyro_z),
                                angular_velocity_covariance=np.zeros(9),
                                linear_acceleration=vector(x=row.acc_x, y=row.acc_y, z=row.acc_z),
                                linear_acceleration_covariance=np.zeros(9))))
    return store, imu.__msgtype__, out, table


@pytest.fixture(scope="module")
def ros2_bag(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("ros2") / "walk"
    store, msgtype, messages, _ = _imu_messages(Stores.ROS2_HUMBLE)
    with Writer2(folder, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection("/imu/left", msgtype, typestore=store)
        for ns, message in messages:
            writer.write(connection, ns + 2_000_000, store.serialize_cdr(message, msgtype))  # recorded 2 ms later
    return folder


def test_a_topic_reads_as_the_csv_it_was_made_of(ros2_bag):
    _, _, _, table = _imu_messages(Stores.ROS2_HUMBLE)
    columns = read_topic(ros2_bag, "/imu/left", ["header.stamp", RECEIVE_TIME, *ACC, *GYRO])
    np.testing.assert_allclose(columns["header.stamp"] - 1.0, table.time_index / 60, rtol=0, atol=1e-9)
    np.testing.assert_allclose(columns[RECEIVE_TIME] - columns["header.stamp"], 0.002, rtol=0, atol=1e-9)
    for field, column in zip(ACC + GYRO, ["acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z"]):
        np.testing.assert_array_equal(columns[field], table[column].to_numpy())  # float64 through CDR, exactly
    mcap = next(ros2_bag.glob("*.mcap"))  # the bag's MCAP file read on its own
    np.testing.assert_array_equal(read_topic(mcap, "/imu/left", ACC)[ACC[2]], columns[ACC[2]])


def test_a_ros1_bag_reads_the_same_fields(tmp_path):
    store, msgtype, messages, table = _imu_messages(Stores.ROS1_NOETIC)
    path = tmp_path / "walk.bag"
    with Writer1(path) as writer:
        connection = writer.add_connection("/imu", msgtype, typestore=store)
        for ns, message in messages[:300]:
            writer.write(connection, ns, store.serialize_ros1(message, msgtype))
    columns = read_topic(path, "/imu", ["header.stamp", *GYRO])
    assert columns["header.stamp"].size == 300
    np.testing.assert_array_equal(columns[GYRO[1]], table.gyro_y.to_numpy()[:300])


def test_a_missing_topic_or_field_is_refused_naming_what_the_recording_has(ros2_bag):
    with pytest.raises(InputError, match=r"no topic '/imu/right' \(it has /imu/left\)"):
        read_topic(ros2_bag, "/imu/right", ACC)
    with pytest.raises(InputError, match=r"sensor_msgs/msg/Imu.*no field 'linear_accel'"):
        read_topic(ros2_bag, "/imu/left", ["linear_accel.x"])


def test_a_foot_ins_runs_from_a_bag_topic_as_from_the_csv(ros2_bag, write_yaml):
    """The same walk from the bag's topic and from the CSV, stance detected in both (the bag has
    no labels): the same track, to the stamps' nanosecond rounding."""
    def run(data: dict, name: str):
        layout = write_yaml({"systems": {"left_foot": {"plugin": "foot_ins", "data": data,
                                                       "initial": {"stationary_s": 1.0}}},
                             "output": {"plots": False}}, name=name)
        return run_layout(load_layout(layout)).trajectories["left_foot"]

    bag = run({"path": str(ros2_bag), "topic": "/imu/left", "time_column": "header.stamp", "acc_columns": ACC,
               "gyro_columns": GYRO}, "bag.yaml")
    csv = run({"path": str(VICON / "imuMeasLeft.csv"), "time_column": "time_index", "time_scale": 1 / 60,
               "acc_columns": ["acc_x", "acc_y", "acc_z"], "gyro_columns": ["gyro_x", "gyro_y", "gyro_z"]}, "csv.yaml")
    assert len(bag.t) == len(csv.t) == 7201
    np.testing.assert_allclose(bag.pos_n, csv.pos_n, rtol=0, atol=1e-6)
