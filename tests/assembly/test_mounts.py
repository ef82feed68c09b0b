"""Sensor mounts through the tf tree: leading slashes, chains, dynamic-only mounts (issue 14.1).

Before the tf buffer was used the Sensor Dispatcher looked a mount up as one
``("base_link", frame_id)`` hop among transforms stamped 0: each log below gave (0, 0, 0).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from redrive.algorithms.reference.detector import ClusterDetector
from redrive.assembly.frames import FrameAssembler
from redrive.assembly.mounts import mount_tf_topics
from redrive.io import open_log
from redrive.io.mcap.writer import McapWriter
from redrive.io.ros.decoders import decode
from redrive.types import PointCloud, SensorType, Transform

T0 = 1_700_000_000_000_000_000
PERIOD_NS = 100_000_000
CLOUD = PointCloud(xyz=np.array([[5.0, 0.0, 0.0], [6.0, 1.0, 0.5]], dtype=np.float32))


def _tf(parent: str, child: str, xyz: tuple[float, float, float], stamp_ns: int = 0) -> Transform:
    return Transform(parent_frame=parent, child_frame=child, translation=xyz, stamp_ns=stamp_ns)


def _write(
    path: Path,
    *,
    frame_id: str,
    static: tuple[Transform, ...] = (),
    dynamic: tuple[Transform, ...] = (),
    frames: int = 5,
) -> Path:
    with McapWriter(path) as out:
        for i in range(frames):
            stamp = T0 + i * PERIOD_NS
            if i == 0 and static:
                out.write("/tf_static", stamp, static)
            if dynamic:
                moved = tuple(
                    _tf(t.parent_frame, t.child_frame, tuple(t.translation), stamp_ns=stamp)
                    for t in dynamic
                )
                out.write("/tf", stamp, moved)
            out.write("/points", stamp, CLOUD, frame_id=frame_id, stamp_ns=stamp)
    return path


def _locations(path: Path) -> list[tuple[float, float, float]]:
    with open_log(path) as log:
        frames = list(FrameAssembler(log).frames())
    assert frames
    return [f.sensors["points"].sensor_location for f in frames]


@pytest.mark.parametrize(
    ("frame_id", "parent", "child"),
    [
        ("/velodyne", "base_link", "velodyne"),
        ("/velodyne", "/base_link", "/velodyne"),
        ("velodyne", "/base_link", "/velodyne"),
    ],
)
def test_a_leading_slash_does_not_hide_the_mount(
    tmp_path: Path, frame_id: str, parent: str, child: str
) -> None:
    log = _write(
        tmp_path / "slash.mcap", frame_id=frame_id, static=(_tf(parent, child, (1.0, 0.0, 1.8)),)
    )
    for loc in _locations(log):
        assert loc == pytest.approx((1.0, 0.0, 1.8))


def test_a_three_link_chain_adds_up(tmp_path: Path) -> None:
    chain = (
        _tf("base_link", "roof", (0.5, 0.0, 1.5)),
        _tf("roof", "mount", (0.25, 0.0, 0.2)),
        _tf("mount", "velodyne", (0.25, 0.0, 0.1)),
    )
    log = _write(tmp_path / "chain.mcap", frame_id="velodyne", static=chain)
    for loc in _locations(log):
        assert loc == pytest.approx((1.0, 0.0, 1.8))


def test_a_mount_only_on_dynamic_tf_is_found(tmp_path: Path) -> None:
    # /tf_static places some other frame; the LiDAR's mount comes on /tf only.
    log = _write(
        tmp_path / "dynamic.mcap",
        frame_id="velodyne",
        static=(_tf("base_link", "imu_link", (0.0, 0.0, 0.3)),),
        dynamic=(_tf("base_link", "velodyne", (1.0, 0.0, 1.8)),),
    )
    with open_log(log) as reader:
        assert mount_tf_topics(
            reader, tf_topics=["/tf", "/tf_static"], sensor_topics=["/points"]
        ) == ["/tf", "/tf_static"]
    for loc in _locations(log):
        assert loc == pytest.approx((1.0, 0.0, 1.8))


def test_dynamic_tf_is_not_read_when_static_mounts_place_every_sensor(tmp_path: Path) -> None:
    log = _write(
        tmp_path / "static.mcap",
        frame_id="velodyne",
        static=(_tf("base_link", "velodyne", (1.0, 0.0, 1.8)),),
        dynamic=(_tf("odom", "base_link", (3.0, 0.0, 0.0)),),
    )
    with open_log(log) as reader:
        assert mount_tf_topics(
            reader, tf_topics=["/tf", "/tf_static"], sensor_topics=["/points"]
        ) == ["/tf_static"]


def test_an_unknown_mount_is_the_origin(tmp_path: Path) -> None:
    log = _write(tmp_path / "none.mcap", frame_id="velodyne")
    assert set(_locations(log)) == {(0.0, 0.0, 0.0)}


def _rewrite_lidar_frame(src: Path, dst: Path, *, lidar_topic: str, lidar_frame: str) -> None:
    """Copy a synthetic log with its LiDAR frame renamed ``/velodyne`` and mounted through a
    three-link chain that adds up to the original mount."""
    with open_log(src) as log, McapWriter(dst) as out:
        for message in log.messages():
            if message.topic not in ("/tf_static", lidar_topic):
                out.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
                continue
            value = decode(message, log.deserialize)
            if message.topic == "/tf_static":
                assert isinstance(value.value, tuple)
                kept = []
                for tf in value.value:
                    assert isinstance(tf, Transform)
                    if tf.child_frame.lstrip("/") == lidar_frame:
                        x, y, z = (float(v) for v in tf.translation)
                        kept += [
                            _tf("/base_link", "/roof", (x / 2, y, z - 0.5)),
                            _tf("/roof", "/bracket", (x / 4, 0.0, 0.25)),
                            Transform(
                                parent_frame="/bracket",
                                child_frame="/velodyne",
                                translation=(x / 4, 0.0, 0.25),
                                rotation=tf.rotation,
                            ),
                        ]
                    else:
                        kept.append(tf)
                out.write(message.topic, message.log_time_ns, tuple(kept))
            else:
                out.write(
                    message.topic,
                    message.log_time_ns,
                    value.value,
                    frame_id="/velodyne",
                    stamp_ns=value.stamp_ns,
                )


def test_the_reference_detector_reports_base_link_boxes_through_a_chain(
    demo_log: Path, tmp_path: Path
) -> None:
    with open_log(demo_log) as log:
        assembler = FrameAssembler(log)
        lidar = next(s for s in assembler.sensor_map.sensors if s.sensor_type is SensorType.LIDAR)
        first = next(assembler.frames())
    lidar_frame = first.sensors[lidar.sensor_id].frame_id.lstrip("/")
    original_location = first.sensors[lidar.sensor_id].sensor_location
    assert any(original_location)  # the rig mounts its LiDAR above base_link
    renamed = tmp_path / "chain.mcap"
    _rewrite_lidar_frame(demo_log, renamed, lidar_topic=lidar.topic, lidar_frame=lidar_frame)

    def detections(path: Path) -> list[list[tuple[float, float, float]]]:
        detector = ClusterDetector()
        detector.configure({})
        detector.bind({lidar.sensor_id: SensorType.LIDAR})
        out = []
        with open_log(path) as log:
            for i, frame in enumerate(FrameAssembler(log).frames()):
                if i >= 5:
                    break
                assert frame.sensors[lidar.sensor_id].sensor_location == pytest.approx(
                    original_location
                )
                boxes = detector.step(frame, {})
                out.append([tuple(np.round(o.box.center, 6)) for o in boxes])
        return out

    expected = detections(demo_log)
    assert any(expected)
    assert detections(renamed) == expected
