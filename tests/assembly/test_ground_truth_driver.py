"""Frames driven by ground truth: a log without sensors makes one per ground-truth message; a
sensor map can ask for it (driver = "ground_truth"), not on a log without ground truth."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.assembly.sensor_map import infer_sensor_map, load_sensor_map_overrides
from redrive.errors import ConfigError
from redrive.io.base import DecodedKind, TopicInfo
from redrive.types import SensorType


def _topics(*, objects: bool) -> dict[str, TopicInfo]:
    out = {
        "/points": TopicInfo(
            topic="/points", msgtype="redrive/PointCloud", count=2, encoding="native",
            kind=DecodedKind.SENSOR, sensor_type=SensorType.LIDAR,
        ),
    }  # fmt: skip
    if objects:
        out["/gt"] = TopicInfo(
            topic="/gt", msgtype="redrive/GroundTruthObjects", count=10, encoding="native",
            kind=DecodedKind.OBJECTS,
        )  # fmt: skip
    return out


def test_a_sensor_map_file_can_make_the_ground_truth_drive(tmp_path: Path) -> None:
    path = tmp_path / "map.toml"
    path.write_text('driver = "ground_truth"\n')
    overrides = load_sensor_map_overrides(path)
    smap = infer_sensor_map(_topics(objects=True), duration_ns=10**9, overrides=overrides)
    assert smap.driver is None
    assert smap.ground_truth_topic == "/gt"
    assert [s.sensor_id for s in smap.sensors] == ["points"]  # still read, nearest each frame
    with pytest.raises(ConfigError, match="has no ground truth"):
        infer_sensor_map(_topics(objects=False), duration_ns=10**9, overrides=overrides)


def test_without_the_file_the_lidar_drives() -> None:
    assert infer_sensor_map(_topics(objects=True), duration_ns=10**9).driver == "points"


def test_an_imu_paces_a_log_without_lidar_camera_radar_or_ground_truth() -> None:
    # issue 35 item 11: an IMU/odometry-only log made no frames open loop
    imu = TopicInfo(
        topic="/imu", msgtype="sensor_msgs/msg/Imu", count=500, encoding="ros1",
        kind=DecodedKind.SENSOR, sensor_type=SensorType.IMU,
    )  # fmt: skip
    fix = TopicInfo(
        topic="/fix", msgtype="sensor_msgs/msg/NavSatFix", count=20, encoding="ros1",
        kind=DecodedKind.SENSOR, sensor_type=SensorType.GNSS,
    )  # fmt: skip
    smap = infer_sensor_map({"/imu": imu, "/fix": fix}, duration_ns=10 * 10**9)
    assert smap.driver == "imu"  # the busiest sensor
    gt = _topics(objects=True)["/gt"]
    smap = infer_sensor_map({"/imu": imu, "/gt": gt}, duration_ns=10 * 10**9)
    assert smap.driver is None  # recorded traffic with an IMU: the ground truth still drives
    assert smap.ground_truth_topic == "/gt"
