"""RecordingThread: a sensor-level run's sensors.mcap written on its own thread is the file
written in place; the writer's errors reach the frame loop."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from redrive.closedloop.sensors import RecordingThread
from redrive.errors import RedriveError, SimulationError
from redrive.io.mcap.writer import McapWriter
from redrive.types import Image, PointCloud, VehicleState


def _messages() -> list[tuple[str, int, object]]:
    rng = np.random.default_rng(3)
    out: list[tuple[str, int, object]] = []
    for k in range(40):
        stamp = 1_000_000_000 + k * 100_000_000
        xyz = rng.normal(size=(5000, 3)).astype(np.float32)
        cloud = PointCloud(xyz=xyz, channels={"intensity": rng.random(5000, dtype=np.float32)})
        pixels = rng.integers(0, 255, size=(48, 64, 3), dtype=np.uint8)
        state = VehicleState(
            position=np.array([k, 0.0, 0.0]),
            velocity=np.array([10.0, 0.0, 0.0]),
            acceleration=np.zeros(3),
            heading_rad=0.1 * k,
            yaw_rate_rad_s=0.0,
            stamp_ns=stamp,
            frame_id="map",
        )
        out += [
            ("/lidar_top", stamp, cloud),
            ("/camera/image_raw", stamp, Image(pixels=pixels, encoding="rgb8")),
            ("/ground_truth/ego_state", stamp, state),
        ]
    return out


def test_the_file_is_the_one_written_in_place(tmp_path: Path) -> None:
    # small chunks: many compressions happen on the thread while messages keep coming
    direct = McapWriter(tmp_path / "direct.mcap", chunk_size_bytes=64 * 1024)
    threaded = McapWriter(tmp_path / "threaded.mcap", chunk_size_bytes=64 * 1024)
    recorder = RecordingThread(threaded, max_pending=4)
    raw = direct.typestore.serialize_cdr(
        direct.typestore.types["std_msgs/msg/String"](data="scan"), "std_msgs/msg/String"
    )
    for topic, stamp, value in _messages():
        direct.write(topic, stamp, value, frame_id="f")
        recorder.write(topic, stamp, value, frame_id="f")
    direct.write_raw("/raw", "std_msgs/msg/String", 5, raw)
    recorder.write_raw("/raw", "std_msgs/msg/String", 5, memoryview(raw))
    recorder.stop()
    direct.close()
    threaded.close()
    data = (tmp_path / "threaded.mcap").read_bytes()
    assert len(data) > 1_000_000
    assert data == (tmp_path / "direct.mcap").read_bytes()


def test_a_writer_error_reaches_the_frame_loop(tmp_path: Path) -> None:
    writer = McapWriter(tmp_path / "a.mcap")
    recorder = RecordingThread(writer)
    recorder.write("/x", 1, Image(pixels=np.zeros((2, 2, 3), np.uint8), encoding="rgb8"))
    cloud = PointCloud(xyz=np.zeros((1, 3), np.float32), channels={})
    recorder.write("/x", 2, cloud)  # /x already carries sensor_msgs/msg/Image
    with pytest.raises(RedriveError, match="already carries"):
        recorder.stop()
    with pytest.raises(RedriveError, match="already carries"):
        recorder.write("/y", 3, cloud)
    writer.abort()


def test_no_message_after_stop(tmp_path: Path) -> None:
    writer = McapWriter(tmp_path / "a.mcap")
    recorder = RecordingThread(writer)
    recorder.stop()
    with pytest.raises(SimulationError, match="the recording was stopped"):
        recorder.write("/x", 1, PointCloud(xyz=np.zeros((1, 3), np.float32), channels={}))
    writer.close()
