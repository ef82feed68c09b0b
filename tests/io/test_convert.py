"""convert_log: KITTI / ROS 1 / MCAP → MCAP or ROS 1 bag, read back with open_log + decoders."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.errors import LogError
from redrive.io import open_log
from redrive.io.convert import convert_log
from redrive.io.datasets.kitti import (
    TOPIC_CAMERA_INFO,
    TOPIC_IMAGE_2,
    TOPIC_LABEL_2,
    TOPIC_TF_STATIC,
    TOPIC_VELODYNE,
    KittiReader,
)
from redrive.io.ros.decoders import decode
from redrive.io.ros.decoders.base import Decoded
from redrive.types import CameraInfo, DetectedObject, Image, PointCloud, Transform

pytestmark = pytest.mark.shared_data


def _kitti_values(kitti_dir: Path) -> dict[tuple[str, int], Decoded]:
    with KittiReader(kitti_dir) as reader:
        return {
            (m.topic, m.log_time_ns): m.payload
            for m in reader.messages()
            if isinstance(m.payload, Decoded)
        }


def _decoded(path: Path) -> dict[tuple[str, int], Decoded]:
    with open_log(path) as log:
        return {(m.topic, m.log_time_ns): decode(m, log.deserialize) for m in log.messages()}


def _assert_kitti_equal(got: Decoded, want: Decoded) -> None:
    assert (got.stamp_ns, got.frame_id) == (want.stamp_ns, want.frame_id)
    g, w = got.value, want.value
    if isinstance(w, PointCloud):
        assert isinstance(g, PointCloud)
        assert g.xyz.dtype == np.float32
        np.testing.assert_array_equal(g.xyz, w.xyz)
        assert set(g.channels) == {"intensity"}
        np.testing.assert_array_equal(g.channels["intensity"], w.channels["intensity"])
    elif isinstance(w, Image):
        assert isinstance(g, Image)
        assert g.encoding == w.encoding == "rgb8"
        np.testing.assert_array_equal(g.pixels, w.pixels)
    elif isinstance(w, CameraInfo):
        assert isinstance(g, CameraInfo)
        assert (g.width, g.height, g.distortion_model) == (w.width, w.height, w.distortion_model)
        for name in ("k", "d", "r", "p"):
            np.testing.assert_array_equal(getattr(g, name), getattr(w, name), err_msg=name)
    else:
        assert isinstance(g, tuple)
        assert isinstance(w, tuple)
        assert len(g) == len(w)
        for a, b in zip(g, w, strict=True):
            if isinstance(b, DetectedObject):
                assert isinstance(a, DetectedObject)
                assert (a.object_id, a.object_class, a.confidence) == (
                    b.object_id,
                    b.object_class,
                    b.confidence,
                )
                np.testing.assert_allclose(a.box.center, b.box.center, rtol=0, atol=1e-9)
                np.testing.assert_allclose(a.box.size, b.box.size, rtol=0, atol=1e-9)
                assert abs(math.remainder(a.box.yaw_rad - b.box.yaw_rad, math.tau)) < 1e-9
            else:
                assert isinstance(a, Transform)
                assert isinstance(b, Transform)
                assert (a.parent_frame, a.child_frame, a.stamp_ns) == (
                    b.parent_frame,
                    b.child_frame,
                    0,
                )
                np.testing.assert_array_equal(a.translation, b.translation)
                np.testing.assert_allclose(a.rotation, b.rotation, atol=1e-15)


@pytest.mark.parametrize("suffix", [".mcap", ".bag"])
def test_kitti_round_trip(kitti_dir: Path, tmp_path: Path, suffix: str) -> None:
    """Acceptance: KITTI → file → open_log + decoders gives the same clouds, images and boxes."""
    out = tmp_path / f"kitti{suffix}"
    calls: list[tuple[int, int]] = []
    stats = convert_log(kitti_dir, out, progress=lambda done, total: calls.append((done, total)))
    assert stats.messages_written == 15
    assert stats.output_format == ("mcap" if suffix == ".mcap" else "ros1")
    assert stats.topics == {
        TOPIC_TF_STATIC: "tf2_msgs/msg/TFMessage",
        TOPIC_VELODYNE: "sensor_msgs/msg/PointCloud2",
        TOPIC_IMAGE_2: "sensor_msgs/msg/Image",
        TOPIC_CAMERA_INFO: "sensor_msgs/msg/CameraInfo",
        TOPIC_LABEL_2: "vision_msgs/msg/Detection3DArray",
    }
    assert calls == [(15, 15)]
    want = _kitti_values(kitti_dir)
    got = _decoded(out)
    assert set(got) == set(want)
    for key, value in want.items():
        _assert_kitti_equal(got[key], value)
    assert [p.name for p in tmp_path.iterdir()] == [out.name]


def _same_message(a: Any, b: Any, where: str = "") -> None:
    """Field-by-field equality of two rosbags messages (ROS 1 ``Header.seq`` aside)."""
    if dataclasses.is_dataclass(a):
        names_a = {f.name for f in dataclasses.fields(a)} - {"seq"}
        names_b = {f.name for f in dataclasses.fields(b)} - {"seq"}
        assert names_a == names_b, where
        for name in sorted(names_a):
            _same_message(getattr(a, name), getattr(b, name), f"{where}.{name}")
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b, err_msg=where)
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same_message(x, y, f"{where}[{i}]")
    else:
        assert a == b, where


def _all_messages(path: Path) -> list[tuple[str, int, Any]]:
    with open_log(path) as log:
        return [(m.topic, m.log_time_ns, log.deserialize(m)) for m in log.messages()]


def test_ros1_to_mcap_to_ros1_keeps_every_field(shared_data: Path, tmp_path: Path) -> None:
    src = shared_data / "rosbag1_recorded_here" / "kitti_3frames_rosbag_record_lz4.bag"
    if not src.is_file():
        pytest.skip("the recorded KITTI bag is not in ../shared/data")
    mcap = tmp_path / "k.mcap"
    bag = tmp_path / "k.bag"
    assert convert_log(src, mcap).messages_written == 9
    assert convert_log(mcap, bag, compression="bz2").messages_written == 9
    original = _all_messages(src)
    for path in (mcap, bag):
        converted = _all_messages(path)
        assert [(t, n) for t, n, _ in converted] == [(t, n) for t, n, _ in original]
        for (topic, _, a), (_, _, b) in zip(original, converted, strict=True):
            _same_message(a, b, topic)
    with open_log(mcap) as log:
        assert log.format == "mcap"
        cloud = next(
            decode(m, log.deserialize) for m in log.messages(topics=["/kitti/velo/pointcloud"])
        )
    with KittiReader(shared_data / "kitti_object") as kitti:
        first = next(m.payload for m in kitti.messages(topics=[TOPIC_VELODYNE]))
    assert isinstance(cloud.value, PointCloud)
    assert isinstance(first, Decoded)
    assert isinstance(first.value, PointCloud)
    np.testing.assert_array_equal(cloud.value.xyz, first.value.xyz)


def test_legacy_tf_and_filters(shared_data: Path, tmp_path: Path) -> None:
    src = shared_data / "rosbag_fixtures" / "rosbagjs_turtlesim_lz4.bag"
    if not src.is_file():
        pytest.skip("rosbag fixtures are not in ../shared/data")
    with open_log(src) as log:
        start = log.start_ns
        tf_type = log.topics["/tf"].msgtype
        expected = sum(
            1
            for _ in log.messages(
                topics=["/tf", "/turtle1/pose"],
                start_ns=start + 1_000_000_000,
                stop_ns=start + 3_000_000_000,
            )
        )
    assert tf_type == "tf/msg/tfMessage"
    out = tmp_path / "t.mcap"
    stats = convert_log(
        src,
        out,
        topics=["/tf", "/turtle1/pose"],
        start_ns=start + 1_000_000_000,
        stop_ns=start + 3_000_000_000,
    )
    assert stats.messages_written == expected > 0
    assert stats.topics == {"/tf": "tf2_msgs/msg/TFMessage", "/turtle1/pose": "turtlesim/msg/Pose"}
    with open_log(out) as log:
        assert set(log.topics) == {"/tf", "/turtle1/pose"}
        assert log.start_ns >= start + 1_000_000_000
        assert log.end_ns < start + 3_000_000_000
        tf = next(decode(m, log.deserialize) for m in log.messages(topics=["/tf"]))
    assert isinstance(tf.value, tuple)
    assert tf.value


def test_bad_output_and_input(kitti_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(LogError, match=r"must end in \.mcap"):
        convert_log(kitti_dir, tmp_path / "x.db3")
    with pytest.raises(LogError, match="no such file"):
        convert_log(tmp_path / "missing.bag", tmp_path / "y.mcap")
    assert list(tmp_path.iterdir()) == []
