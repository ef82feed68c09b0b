"""McapWriter: every data-model value round-trips through a real MCAP file; writes are atomic."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader

from redrive.errors import LogError, UnsupportedMessageError
from redrive.io import open_log
from redrive.io.mcap.writer import McapWriter
from redrive.io.ros.decoders import decode
from redrive.io.ros.decoders.base import Decoded
from redrive.types import (
    Box3D,
    DetectedObject,
    Frame,
    GnssFix,
    Image,
    Imu,
    ObjectClass,
    PointCloud,
    SensorData,
    SensorType,
    Transform,
    VehicleState,
)

RNG = np.random.default_rng(7)


def _cloud() -> PointCloud:
    n = 257
    return PointCloud(
        xyz=RNG.normal(size=(n, 3)).astype(np.float32),
        channels={
            "intensity": RNG.random(n, dtype=np.float32),
            "ring": RNG.integers(0, 64, n).astype(np.uint16),
            "t_offset_ns": RNG.integers(0, 100_000_000, n).astype(np.int64),
            "range": RNG.random(n),
            "flag": RNG.integers(-3, 3, n).astype(np.int8),
        },
    )


def _objects() -> tuple[DetectedObject, ...]:
    return (
        DetectedObject(
            object_id=4,
            object_class=ObjectClass.VEHICLE,
            confidence=0.25,
            box=Box3D(
                center=np.array([10.5, -2.0, 0.3]), size=np.array([4.2, 1.8, 1.5]), yaw_rad=2.9
            ),
        ),
        DetectedObject(
            object_id=-1,
            object_class=ObjectClass.PEDESTRIAN,
            box=Box3D(
                center=np.array([1.0, 2.0, 3.0]),
                size=np.array([0.5, 0.6, 1.8]),
                yaw_rad=-math.pi / 3,
            ),
        ),
    )


def _values() -> dict[str, tuple[object, str]]:
    """topic → (value, frame_id)"""
    return {
        "/cloud": (_cloud(), "lidar"),
        "/rgb": (
            Image(pixels=RNG.integers(0, 256, (5, 7, 3)).astype(np.uint8), encoding="rgb8"),
            "cam",
        ),
        "/depth": (
            Image(pixels=RNG.integers(0, 65536, (4, 3)).astype(np.uint16), encoding="mono16"),
            "cam",
        ),
        "/imu": (
            Imu(
                linear_acceleration=np.array([0.1, 0.2, 9.8]),
                angular_velocity=np.array([0.01, -0.02, 0.3]),
                orientation=np.array([0.0, 0.0, math.sin(0.2), math.cos(0.2)]),
            ),
            "imu",
        ),
        "/imu_raw": (
            Imu(linear_acceleration=np.array([0.0, 0.0, 9.8]), angular_velocity=np.zeros(3)),
            "imu",
        ),
        "/fix": (
            GnssFix(
                latitude_deg=42.3758,
                longitude_deg=-71.1474,
                altitude_m=12.5,
                position_covariance_m2=np.diag([1.0, 2.0, 3.0]),
                status=2,
            ),
            "gps",
        ),
        "/fix_nocov": (GnssFix(latitude_deg=1.0, longitude_deg=2.0, altitude_m=3.0), "gps"),
        "/objects": (_objects(), "base_link"),
        "/tf": (
            (
                Transform(
                    parent_frame="map",
                    child_frame="base_link",
                    translation=np.array([1.0, 2.0, 3.0]),
                    rotation=np.array([0.1, 0.2, 0.3, 0.9]),
                    stamp_ns=1_500_000_001,
                ),
            ),
            "",
        ),
    }


def _read_back(path: Path) -> dict[str, Decoded]:
    with open_log(path) as log:
        return {m.topic: decode(m, log.deserialize) for m in log.messages()}


def _assert_same(topic: str, got: Any, want: Any) -> None:
    if isinstance(want, PointCloud):
        np.testing.assert_array_equal(got.xyz, want.xyz)
        assert set(got.channels) == set(want.channels)
        for name, values in want.channels.items():
            np.testing.assert_array_equal(got.channels[name], values)
        assert got.channels["t_offset_ns"].dtype == np.int32  # int64 narrowed when it fits
        assert got.channels["ring"].dtype == np.uint16
    elif isinstance(want, Image):
        assert got.encoding == want.encoding
        np.testing.assert_array_equal(got.pixels, want.pixels)
        assert got.pixels.dtype == want.pixels.dtype
    elif isinstance(want, Imu):
        np.testing.assert_array_equal(got.linear_acceleration, want.linear_acceleration)
        np.testing.assert_array_equal(got.angular_velocity, want.angular_velocity)
        np.testing.assert_array_equal(got.orientation, want.orientation)  # NaN == NaN here
    elif isinstance(want, GnssFix):
        assert (got.latitude_deg, got.longitude_deg, got.altitude_m, got.status) == (
            want.latitude_deg,
            want.longitude_deg,
            want.altitude_m,
            want.status,
        )
        np.testing.assert_array_equal(got.position_covariance_m2, want.position_covariance_m2)
    elif topic == "/objects":
        assert len(got) == len(want)
        for g, w in zip(got, want, strict=True):
            assert (g.object_id, g.object_class, g.confidence) == (
                w.object_id,
                w.object_class,
                w.confidence,
            )
            np.testing.assert_array_equal(g.box.center, w.box.center)
            np.testing.assert_array_equal(g.box.size, w.box.size)
            assert abs(g.box.yaw_rad - w.box.yaw_rad) < 1e-12
    elif topic == "/tf":
        (g,), (w,) = got, want
        assert (g.parent_frame, g.child_frame, g.stamp_ns) == (
            w.parent_frame,
            w.child_frame,
            w.stamp_ns,
        )
        np.testing.assert_array_equal(g.translation, w.translation)
        np.testing.assert_allclose(g.rotation, w.rotation, atol=1e-15)
    else:  # pragma: no cover
        raise AssertionError(topic)


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_values_round_trip(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "out.mcap"
    values = _values()
    with McapWriter(path, compression=compression) as out:  # type: ignore[arg-type]
        for i, (topic, (value, frame_id)) in enumerate(values.items()):
            out.write(topic, 1_000 + i, value, frame_id=frame_id, stamp_ns=2_000_000_000 + i)
        assert out.topics["/cloud"] == "sensor_msgs/msg/PointCloud2"
    got = _read_back(path)
    assert set(got) == set(values)
    for i, (topic, (value, frame_id)) in enumerate(values.items()):
        if topic != "/tf":
            assert got[topic].frame_id == frame_id
            assert got[topic].stamp_ns == 2_000_000_000 + i
        _assert_same(topic, got[topic].value, value)


def test_odometry_round_trip(tmp_path: Path) -> None:
    state = VehicleState(
        stamp_ns=123_456_789_000,
        frame_id="odom",
        position=np.array([100.25, -50.5, 1.0]),
        velocity=np.array([3.0, 4.0, 0.0]),
        heading_rad=0.9,
        yaw_rate_rad_s=-0.05,
    )
    path = tmp_path / "odom.mcap"
    with McapWriter(path) as out:
        out.write("/odom", 5, state)  # frame and stamp from the state
    got = _read_back(path)["/odom"]
    assert (got.stamp_ns, got.frame_id) == (state.stamp_ns, "odom")
    value = got.value
    assert isinstance(value, VehicleState)
    np.testing.assert_array_equal(value.position, state.position)
    np.testing.assert_allclose(value.velocity, state.velocity, atol=1e-12)
    assert value.heading_rad == pytest.approx(0.9, abs=1e-12)
    assert value.yaw_rate_rad_s == pytest.approx(-0.05, abs=1e-15)


def test_schemas_are_standard_ros2(tmp_path: Path) -> None:
    """An independent ROS 2 reader (mcap-ros2-support) parses every schema and message."""
    decoder = pytest.importorskip("mcap_ros2.decoder")
    path = tmp_path / "out.mcap"
    with McapWriter(path) as out:
        for topic, (value, frame_id) in _values().items():
            out.write(topic, 1, value, frame_id=frame_id)
    with path.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[decoder.DecoderFactory()])
        header = reader.get_header()
        assert header.profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        decoded = {c.topic: m for _, c, _, m in reader.iter_decoded_messages()}
    objects = decoded["/objects"]
    assert [d.results[0].hypothesis.class_id for d in objects.detections] == [
        "vehicle",
        "pedestrian",
    ]
    assert [d.id for d in objects.detections] == ["4", "-1"]
    assert objects.detections[0].results[0].hypothesis.score == 0.25
    assert [f.name for f in decoded["/cloud"].fields] == [
        "x",
        "y",
        "z",
        "intensity",
        "ring",
        "t_offset_ns",
        "range",
        "flag",
    ]
    assert decoded["/imu_raw"].orientation_covariance[0] == -1.0


def test_write_frame(tmp_path: Path) -> None:
    cloud = _cloud()
    frame = Frame(
        stamp_ns=10_000,
        index=0,
        sensors={
            "lidar_top": SensorData(
                sensor_id="lidar_top",
                sensor_type=SensorType.LIDAR,
                stamp_ns=9_000,
                frame_id="lidar",
                data=cloud,
            ),
        },
        vehicle_state=VehicleState(stamp_ns=9_500, frame_id="map"),
        ground_truth=_objects(),
    )
    path = tmp_path / "frame.mcap"
    with McapWriter(path) as out:
        out.write_frame(frame, topics={"lidar_top": "/points"})
    got = _read_back(path)
    assert set(got) == {"/points", "/odom", "/ground_truth"}
    assert (got["/points"].stamp_ns, got["/points"].frame_id) == (9_000, "lidar")
    assert (got["/ground_truth"].stamp_ns, got["/ground_truth"].frame_id) == (10_000, "base_link")
    assert got["/odom"].stamp_ns == 9_500


def test_failure_leaves_no_file(tmp_path: Path) -> None:
    path = tmp_path / "out.mcap"
    path.write_bytes(b"old contents")

    def fail_midway() -> None:
        with McapWriter(path) as out:
            out.write("/cloud", 1, _cloud())
            raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        fail_midway()
    assert path.read_bytes() == b"old contents"
    assert [p.name for p in tmp_path.iterdir()] == ["out.mcap"]
    with (
        pytest.raises(UnsupportedMessageError, match="no standard ROS 2 message"),
        McapWriter(tmp_path / "b.mcap") as out,
    ):
        out.write("/x", 1, "not a value")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.mcap"]


def test_topic_type_conflict_and_closed_writer(tmp_path: Path) -> None:
    out = McapWriter(tmp_path / "c.mcap")
    out.write("/a", 1, _cloud())
    with pytest.raises(LogError, match="already carries sensor_msgs/msg/PointCloud2"):
        out.write("/a", 2, _objects())
    out.close()
    out.close()
    with pytest.raises(LogError, match="closed"):
        out.write("/a", 3, _cloud())
    with open_log(tmp_path / "c.mcap") as log:
        assert log.message_count == 1


def test_unwritable_directory(tmp_path: Path) -> None:
    with pytest.raises(LogError, match="cannot create a file"):
        McapWriter(tmp_path / "missing" / "x.mcap")


def test_write_raw_unknown_type(tmp_path: Path) -> None:
    with McapWriter(tmp_path / "r.mcap") as out:
        with pytest.raises(UnsupportedMessageError, match="no definition of foo_msgs/msg/Bar"):
            out.write_raw("/bar", "foo_msgs/msg/Bar", 1, b"\x00\x01\x00\x00")
        out.write_raw(
            "/s",
            "std_msgs/msg/String",
            1,
            out.typestore.serialize_cdr(
                out.typestore.types["std_msgs/msg/String"](data="hi"), "std_msgs/msg/String"
            ),
            publish_time_ns=7,
        )
    with open_log(tmp_path / "r.mcap") as log:
        (message,) = log.messages()
        assert log.deserialize(message).data == "hi"  # type: ignore[attr-defined]


def test_ground_truth_round_trip_with_velocity_points_and_visibility(tmp_path: Path) -> None:
    """Ground truth (objects with LiDAR point counts / visibility) keeps every field, and an
    independent ROS 2 reader parses the shipped GroundTruthObjectArray schema."""
    objects = tuple(
        dataclasses.replace(
            obj, velocity=np.array([v, -1.5, 0.25]), num_lidar_points=n, visible=vis
        )
        for obj, v, n, vis in zip(_objects(), (7.0, 0.5), (312, None), (True, False), strict=True)
    )
    path = tmp_path / "gt.mcap"
    with McapWriter(path) as out:
        out.write("/ground_truth/objects", 9, objects, frame_id="base_link", stamp_ns=9)
        assert out.topics["/ground_truth/objects"] == "redrive_msgs/msg/GroundTruthObjectArray"
    got = _read_back(path)["/ground_truth/objects"]
    assert got.frame_id == "base_link"
    for g, w in zip(got.value, objects, strict=True):
        assert (g.object_id, g.object_class) == (w.object_id, w.object_class)
        assert (g.num_lidar_points, g.visible) == (w.num_lidar_points, w.visible)
        np.testing.assert_array_equal(g.velocity, w.velocity)
        np.testing.assert_array_equal(g.box.center, w.box.center)
    decoder = pytest.importorskip("mcap_ros2.decoder")
    with path.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[decoder.DecoderFactory()])
        (msg,) = [m for _, _, _, m in reader.iter_decoded_messages()]
    assert list(msg.num_lidar_points) == [312, -1]
    assert list(msg.visible) == [1, 0]
    assert msg.velocities[0].x == 7.0


def test_zstd_level_changes_the_bytes_not_what_reads_back(tmp_path: Path) -> None:
    """``zstd_level`` reaches the compressor (level 1 and 19 give different chunks) and any
    level reads back the same values (closed-loop ``sensors.mcap`` is written at level 1)."""
    rng = np.random.default_rng(3)
    image = Image(
        pixels=np.repeat(rng.integers(0, 8, size=(64, 256, 1), dtype=np.uint8), 3, axis=2),
        encoding="rgb8",
    )
    sizes = {}
    for level in (1, 19):
        path = tmp_path / f"level{level}.mcap"
        with McapWriter(path, zstd_level=level) as out:
            for i in range(4):
                out.write("/image", 1_000 + i, image, frame_id="camera")
        sizes[level] = path.stat().st_size
        got = _read_back(path)
        np.testing.assert_array_equal(got["/image"].value.pixels, image.pixels)  # type: ignore[union-attr]
    assert sizes[1] != sizes[19]
