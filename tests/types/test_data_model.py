"""The data model checks shapes and dtypes, freezes arrays, and never freezes the caller's array."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest

from redrive.types import (
    Box3D,
    ControlCommands,
    DetectedObject,
    ExtensionPayload,
    Frame,
    Image,
    Imu,
    ObjectClass,
    PlannedPath,
    PointCloud,
    SensorData,
    SensorType,
    Transform,
    VehicleState,
)


def test_point_cloud_freezes_views_and_keeps_the_caller_array_writable() -> None:
    xyz = np.zeros((4, 3), dtype=np.float32)
    intensity = np.arange(4, dtype=np.float32)
    cloud = PointCloud(xyz=xyz, channels={"intensity": intensity})
    assert not cloud.xyz.flags.writeable
    assert not cloud.channels["intensity"].flags.writeable
    assert xyz.flags.writeable
    assert intensity.flags.writeable
    xyz[0, 0] = 5.0  # a view: the cloud sees the caller's later writes, but cannot write itself
    assert cloud.xyz[0, 0] == 5.0
    with pytest.raises(ValueError, match="read-only"):
        cloud.xyz[0, 0] = 1.0
    with pytest.raises(TypeError):
        cloud.channels["ring"] = intensity  # type: ignore[index]
    with pytest.raises(dataclasses.FrozenInstanceError):
        cloud.xyz = xyz  # type: ignore[misc]
    assert len(cloud) == cloud.num_points == 4


@pytest.mark.parametrize(
    ("xyz", "channels", "match"),
    [
        (np.zeros((4, 3), dtype=np.float64), {}, "dtype float64 is not accepted"),
        (np.zeros((4, 4), dtype=np.float32), {}, r"shape \(4, 4\) does not match \(N, 3\)"),
        (np.zeros((4, 3), dtype=np.float32), {"i": np.zeros(5)}, r"shape \(5,\) does not match"),
        (
            np.zeros((4, 3), dtype=np.float32),
            {"s": np.zeros(4, dtype=[("a", "f4")])},
            "structured arrays are not allowed",
        ),
    ],
)
def test_point_cloud_rejects_bad_arrays(xyz: np.ndarray, channels: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        PointCloud(xyz=xyz, channels=channels)


def test_read_only_xyz_is_taken_as_it_is() -> None:
    xyz = np.zeros((2, 3), dtype=np.float32)
    xyz.flags.writeable = False
    assert PointCloud(xyz=xyz).xyz is xyz


def test_image_encodings() -> None:
    Image(pixels=np.zeros((2, 3, 3), dtype=np.uint8), encoding="rgb8")
    Image(pixels=np.zeros((2, 3), dtype=np.uint16), encoding="mono16")
    with pytest.raises(ValueError, match="encoding 'yuv422'"):
        Image(pixels=np.zeros((2, 3, 2), dtype=np.uint8), encoding="yuv422")
    with pytest.raises(ValueError, match="dtype"):
        Image(pixels=np.zeros((2, 3), dtype=np.uint8), encoding="mono16")
    with pytest.raises(ValueError, match="shape"):
        Image(pixels=np.zeros((2, 3), dtype=np.uint8), encoding="rgb8")


def test_objects_validate() -> None:
    box = Box3D(center=[1, 2, 3], size=[4, 2, 1.5], yaw_rad=0.5)
    assert box.center.dtype == np.float64
    assert not box.center.flags.writeable
    with pytest.raises(ValueError, match="non-negative"):
        Box3D(center=[0, 0, 0], size=[-1, 1, 1])
    with pytest.raises(ValueError, match="finite"):
        Box3D(center=[0, 0, 0], size=[1, 1, 1], yaw_rad=float("nan"))
    obj = DetectedObject(object_class=ObjectClass.VEHICLE, box=box, num_lidar_points=12)
    assert obj.visible is None
    assert obj.num_lidar_points == 12
    with pytest.raises(ValueError, match="confidence"):
        DetectedObject(box=box, confidence=1.5)
    with pytest.raises(ValueError, match="num_lidar_points"):
        DetectedObject(box=box, num_lidar_points=-1)
    with pytest.raises(ValueError, match="bbox_2d"):
        DetectedObject(box=box, bbox_2d=(1.0, 2.0, 3.0))  # type: ignore[arg-type]


def test_vehicle_types_validate() -> None:
    state = VehicleState(stamp_ns=5, position=[1e6, 2e6, 0.0])
    assert state.position.dtype == np.float64
    assert state.position[0] == 1e6
    PlannedPath(stamp_ns=0, waypoints=np.array([[0, 0, 0, 0.0], [1, 0, 0, 0.5]]))
    with pytest.raises(ValueError, match="must not decrease"):
        PlannedPath(stamp_ns=0, waypoints=np.array([[0, 0, 0, 1.0], [1, 0, 0, 0.5]]))
    with pytest.raises(ValueError, match=r"throttle must lie in \[0, 1\]"):
        ControlCommands(throttle=1.5)


def test_imu_transform_and_frame() -> None:
    imu = Imu(linear_acceleration=[0, 0, 9.81], angular_velocity=[0, 0, 0.1])
    assert np.all(np.isnan(imu.orientation))
    t = Transform(parent_frame="base_link", child_frame="lidar", rotation=[0, 0, 0, 2.0])
    np.testing.assert_array_equal(t.rotation, [0, 0, 0, 1.0])  # normalised
    with pytest.raises(ValueError, match="non-zero quaternion"):
        Transform(parent_frame="a", child_frame="b", rotation=[0, 0, 0, 0])
    cloud = PointCloud(xyz=np.zeros((1, 3), dtype=np.float32))
    sample = SensorData(sensor_id="lidar", sensor_type=SensorType.LIDAR, stamp_ns=1, data=cloud)
    frame = Frame(stamp_ns=1, index=0, sensors={"lidar": sample})
    assert frame.sensors["lidar"].data is cloud
    with pytest.raises(
        ValueError, match=r"a CAMERA sensor carries Image or a payload class .* got PointCloud"
    ):
        SensorData(sensor_id="cam", sensor_type=SensorType.CAMERA, stamp_ns=1, data=cloud)


def test_an_extension_payload_is_carried_by_the_sensor_types_it_names() -> None:
    @dataclass(frozen=True)
    class RadarPoints:
        sensor_types: ClassVar[frozenset[SensorType]] = frozenset({SensorType.RADAR})
        range_m: np.ndarray

    points = RadarPoints(range_m=np.array([1.0, 2.0]))
    sample = SensorData(sensor_id="radar", sensor_type=SensorType.RADAR, stamp_ns=1, data=points)
    assert sample.data is points
    assert isinstance(points, ExtensionPayload)
    with pytest.raises(ValueError, match="a LIDAR sensor carries PointCloud or a payload class"):
        SensorData(sensor_id="lidar", sensor_type=SensorType.LIDAR, stamp_ns=1, data=points)


def test_planned_path_time_check_is_np_diffs_on_special_values() -> None:
    """A path is refused exactly when ``np.diff(t) < 0`` somewhere (NaN, ±inf, ±0.0 included)."""
    values = [0.0, -0.0, 1.0, -1.0, np.inf, -np.inf, np.nan, 5e-324, -5e-324, 1e308, -1e308]
    for a in values:
        for b in values:
            wp = np.array([[0, 0, 0, a], [1, 0, 0, b]], dtype=np.float64)
            with np.errstate(all="ignore"):  # inf - inf, 1e308 - -1e308
                refused = bool(np.any(np.diff(wp[:, 3]) < 0))
            try:
                PlannedPath(stamp_ns=0, waypoints=wp)
            except ValueError:
                assert refused, (a, b)
            else:
                assert not refused, (a, b)
