"""Smoke tests of the read benchmark: it runs on tiny logs and reports sane fields.

Timings are never asserted (a benchmark is not a timed unit test); only that numbers exist, are
positive and that both sides read the same messages.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_typestore

from redrive.benchmarks.passes import PassResult, peak_rss_bytes, redrive_pass
from redrive.benchmarks.read import bench_read, warm_page_cache
from redrive.benchmarks.synth_log import point_dtype, write_synthetic_bag
from redrive.errors import LogError
from redrive.io import open_log
from redrive.io.ros.decoders import decode
from redrive.types import PointCloud

_POINTS = 2_000


@pytest.fixture(scope="module")
def tiny_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bench") / "tiny.bag"
    write_synthetic_bag(out, size_bytes=4 * 32 * _POINTS, points=_POINTS)
    return out


def _check_side(side: Any) -> None:
    for name in ("median_loop_s", "best_loop_s", "msgs_per_s", "mb_per_s", "best_mb_per_s"):
        value = getattr(side, name)
        assert math.isfinite(value)
        assert value > 0, name
    assert side.best_loop_s <= side.median_loop_s
    assert side.median_open_s >= 0
    assert side.peak_rss_bytes >= side.rss_start_bytes > 0


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


def test_synthetic_bag_refuses_to_overwrite(tiny_bag: Path) -> None:
    with pytest.raises(LogError, match="cannot create"):
        write_synthetic_bag(tiny_bag, size_bytes=1000, points=10)


def test_bench_read_reports_sane_fields(tiny_bag: Path) -> None:
    notes: list[str] = []
    result = bench_read(tiny_bag, repeats=2, progress=notes.append)
    assert result.log_format == "ros1"
    assert result.topics == ("/velodyne_points",)
    assert result.messages == 4
    assert result.points == 4 * _POINTS
    assert result.payload_bytes > 4 * 32 * _POINTS
    assert result.warmed
    assert len(result.raw_passes) == len(result.redrive_passes) == 2
    assert [p.kind for p in result.raw_passes] == ["raw", "raw"]
    _check_side(result.raw)
    _check_side(result.redrive)
    assert result.ratio > 0
    assert result.best_ratio > 0
    data = json.loads(json.dumps(result.to_json()))
    assert data["messages"] == 4
    assert data["page_cache_warmed"] is True
    assert len(data["passes"]) == 4
    assert data["raw"]["mb_per_s"] > 0
    assert notes[0] == "warming the page cache"


def test_bench_read_rejects_unknown_topic(tiny_bag: Path) -> None:
    with pytest.raises(LogError, match="not a PointCloud2 topic"):
        bench_read(tiny_bag, topics=["/nope"], repeats=1)


def test_redrive_pass_in_process(tiny_bag: Path) -> None:
    result = redrive_pass(tiny_bag, ["/velodyne_points"])
    assert isinstance(result, PassResult)
    assert (result.messages, result.points) == (4, 4 * _POINTS)
    assert result.peak_rss_bytes == peak_rss_bytes() or result.peak_rss_bytes > 0


def test_warm_page_cache_reads_every_byte(tiny_bag: Path) -> None:
    assert warm_page_cache(tiny_bag) == tiny_bag.stat().st_size


def _write_ros2_bag(path: Path, *, messages: int, points: int) -> None:
    store = get_typestore(Stores.ROS2_HUMBLE)
    t: Any = store.types
    fields = [
        t["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=7, count=1)
        for n, o in (("x", 0), ("y", 4), ("z", 8), ("intensity", 12))
    ]
    msgtype = "sensor_msgs/msg/PointCloud2"
    with Ros2Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/points", msgtype, typestore=store)
        for i in range(messages):
            data = np.arange(points * 4, dtype=np.float32) + i
            header = t["std_msgs/msg/Header"](
                stamp=t["builtin_interfaces/msg/Time"](sec=1, nanosec=i), frame_id="lidar"
            )
            cloud = t[msgtype](
                header=header,
                height=1,
                width=points,
                fields=fields,
                is_bigendian=False,
                point_step=16,
                row_step=16 * points,
                data=data.view(np.uint8),
                is_dense=True,
            )
            writer.write(conn, 1_000_000_000 + i, store.serialize_cdr(cloud, msgtype))


def test_bench_read_ros2_and_mcap(tmp_path: Path) -> None:
    bag = tmp_path / "ros2bag"
    _write_ros2_bag(bag, messages=3, points=100)
    ros2 = bench_read(bag, repeats=1, warm=False)
    assert (ros2.log_format, ros2.messages, ros2.points) == ("ros2", 3, 300)
    assert not ros2.warmed
    (mcap_file,) = bag.glob("*.mcap")
    mcap = bench_read(mcap_file, repeats=1)
    assert (mcap.log_format, mcap.messages, mcap.points) == ("mcap", 3, 300)
    assert mcap.payload_bytes == ros2.payload_bytes
