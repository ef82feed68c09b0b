"""The synthetic ROS 1 bag of ``python -m benchmarks read-synth`` holds decodable LiDAR sweeps
of the layout and compression asked for, and is never written over an existing file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.synth_log import point_dtype, write_synthetic_bag
from redrive.errors import LogError
from redrive.io import open_log
from redrive.io.ros.decoders import decode
from redrive.types import PointCloud


def test_synthetic_bag_holds_velodyne_sweeps(tmp_path: Path) -> None:
    calls: list[tuple[int, int]] = []
    out = tmp_path / "s.bag"
    result = write_synthetic_bag(
        out, size_bytes=3 * 32 * 500, points=500, progress=lambda d, t: calls.append((d, t))
    )
    assert result.messages == 3
    assert calls[-1] == (3, 3)
    assert result.file_bytes == out.stat().st_size > result.payload_bytes
    with open_log(out) as log:
        info = log.topics[result.topic]
        assert (info.msgtype, info.count) == ("sensor_msgs/msg/PointCloud2", 3)
        clouds = [decode(m, log.deserialize) for m in log.messages()]
    cloud = clouds[1].value
    assert isinstance(cloud, PointCloud)
    assert cloud.xyz.shape == (500, 3)
    assert set(cloud.channels) == {"intensity", "ring", "time"}
    assert cloud.channels["ring"].dtype == np.uint16
    assert cloud.channels["time"].dtype == np.float64
    assert np.isfinite(cloud.xyz).all()
    assert float(np.linalg.norm(cloud.xyz, axis=1).min()) > 0.5
    assert clouds[1].stamp_ns - clouds[0].stamp_ns == 100_000_000
    assert point_dtype("velodyne").itemsize == 32
    assert point_dtype("xyzi").itemsize == 16


@pytest.mark.parametrize("compression", ["lz4", "bz2"])
def test_synthetic_bag_compressed(tmp_path: Path, compression: Any) -> None:
    out = tmp_path / "c.bag"
    result = write_synthetic_bag(
        out, size_bytes=2 * 16 * 300, points=300, layout="xyzi", compression=compression
    )
    with open_log(out) as log:
        n = sum(decode(m, log.deserialize).value.xyz.shape[0] for m in log.messages())  # type: ignore[union-attr]
    assert n == result.messages * 300


def test_synthetic_bag_refuses_to_overwrite(tmp_path: Path) -> None:
    tiny_bag = tmp_path / "tiny.bag"
    write_synthetic_bag(tiny_bag, size_bytes=4 * 32 * 100, points=100)
    with pytest.raises(LogError, match="cannot create"):
        write_synthetic_bag(tiny_bag, size_bytes=1000, points=10)
