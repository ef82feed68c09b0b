"""Unusual PointCloud2 layouts written into real logs by rosbags' writers decode exactly.

Each case is a numpy structured array (padding, extra and repeated-count fields, big-endian
points, float64 or int16 coordinates, NaNs, organised clouds with padded rows); it is serialised
with rosbags, written with ``rosbags.rosbag1.Writer`` (uncompressed — the mapped zero-copy path —
and lz4) and ``rosbags.rosbag2.Writer`` (sqlite3 and mcap storage), read back with ``open_log``
and decoded; xyz and every channel must equal the source values bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Bag1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Bag2Writer

from redrive.io import open_log
from redrive.io.ros.decoders import decode
from redrive.types import PointCloud
from tests.io._decoder_helpers import header, make, serialize, store

TYPE = "sensor_msgs/msg/PointCloud2"
_DATATYPE = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}


@dataclass(frozen=True)
class Case:
    """One cloud: points (H*W structured, any byte order), grid shape and row padding."""

    name: str
    points: np.ndarray  # (H, W) structured; members starting with "_" are padding, not fields
    row_pad_bytes: int = 0
    counts: tuple[tuple[str, int], ...] = ()  # fields with count > 1: (name, count)

    def fields(self) -> list[dict[str, Any]]:
        out = []
        dtype = self.points.dtype
        assert dtype.names is not None
        counts = dict(self.counts)
        for name in dtype.names:
            if name.startswith("_"):
                continue
            sub, offset = dtype.fields[name][:2]  # type: ignore[index]
            base = sub.base if sub.shape else sub
            code = base.str[1:]
            count = counts.get(name, 1)
            out.append(
                {"name": name, "offset": offset, "datatype": _DATATYPE[code], "count": count}
            )
        return out

    def data(self) -> bytes:
        height = self.points.shape[0]
        rows = [self.points[r].tobytes() + b"\xee" * self.row_pad_bytes for r in range(height)]
        return b"".join(rows)

    def expected(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        flat = self.points.reshape(-1)
        xyz = np.stack([flat[a].astype(np.float32) for a in "xyz"], axis=1)
        channels: dict[str, np.ndarray] = {}
        for field in self.fields():
            name, count = field["name"], field["count"]
            if name in "xyz":
                continue
            values = flat[name]
            if count == 1:
                channels[name] = values.astype(values.dtype.newbyteorder("="))
            else:
                for i in range(count):
                    col = values[:, i]
                    channels[f"{name}_{i}"] = col.astype(col.dtype.newbyteorder("="))
        return xyz, channels


def _cases() -> list[Case]:
    rng = np.random.default_rng(7)
    n = 257
    velodyne = np.zeros(
        (1, n),
        dtype=[
            ("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("_pad", "V4"),
            ("intensity", "<f4"), ("ring", "<u2"), ("_pad2", "V2"), ("time", "<f8"),
        ],
    )  # fmt: skip
    for axis in "xyz":
        velodyne[axis] = rng.normal(0, 30, (1, n))
    velodyne["x"][0, ::7] = np.nan  # is_dense = false: NaN returns are kept
    velodyne["intensity"] = rng.uniform(0, 255, (1, n))
    velodyne["ring"] = np.arange(n) % 32
    velodyne["time"] = np.linspace(0, 0.1, n)

    big = np.zeros(
        (1, 40),
        dtype=[("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("rgb", ">u4"), ("normal", ">f4", (3,))],
    )
    for axis in "xyz":
        big[axis] = rng.normal(0, 5, (1, 40))
    big["rgb"] = rng.integers(0, 2**32, (1, 40), dtype=np.uint64).astype(np.uint32)
    big["normal"] = rng.normal(0, 1, (1, 40, 3))

    organised = np.zeros(
        (4, 16), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("range", "<u4")]
    )
    for axis in "xyz":
        organised[axis] = rng.normal(0, 10, (4, 16))
    organised["z"][1, :] = np.nan
    organised["range"] = rng.integers(0, 10**6, (4, 16))

    ints = np.zeros((1, 30), dtype=[("z", "<i2"), ("y", "<i2"), ("x", "<i2"), ("flags", "u1")])
    for axis in "xyz":
        ints[axis] = rng.integers(-3000, 3000, (1, 30))
    ints["flags"] = rng.integers(0, 255, (1, 30))

    return [
        Case("velodyne_padding_nan", velodyne),
        Case("big_endian_f64_count3", big, counts=(("normal", 3),)),
        Case("organised_padded_rows", organised, row_pad_bytes=12),
        Case("int16_reordered_xyz", ints),
    ]


CASES = _cases()


def _serialised(case: Case, ros_version: int, stamp_ns: int) -> bytes:
    height, width = case.points.shape
    point_step = case.points.dtype.itemsize
    big = case.points.dtype["x"].byteorder == ">"
    msg = make(
        store(ros_version),  # type: ignore[arg-type]
        TYPE,
        header=header(ros_version, stamp_ns, "lidar"),  # type: ignore[arg-type]
        height=height,
        width=width,
        fields=case.fields(),
        is_bigendian=big,
        point_step=point_step,
        row_step=width * point_step + case.row_pad_bytes,
        data=np.frombuffer(case.data(), dtype=np.uint8),
        is_dense=False,
    )
    return serialize(ros_version, msg, TYPE)  # type: ignore[arg-type]


def _write(kind: str, path: Path) -> Path:
    stamps = [1_700_000_000_000_000_000 + i * 100_000_000 for i in range(len(CASES))]
    if kind.startswith("ros1"):
        path = path / "clouds.bag"
        writer1 = Bag1Writer(path)
        if kind == "ros1-lz4":
            writer1.set_compression(Bag1Writer.CompressionFormat.LZ4)
        with writer1:
            conns = [writer1.add_connection(f"/{c.name}", TYPE, typestore=store(1)) for c in CASES]
            for conn, case, stamp in zip(conns, CASES, stamps, strict=True):
                # twice each, so a cached layout is used on the second message
                writer1.write(conn, stamp, _serialised(case, 1, stamp))
                writer1.write(conn, stamp + 1, _serialised(case, 1, stamp))
        return path
    path = path / "clouds"
    plugin = StoragePlugin.MCAP if kind == "ros2-mcap" else StoragePlugin.SQLITE3
    with Bag2Writer(path, version=8, storage_plugin=plugin) as writer2:
        conns = [writer2.add_connection(f"/{c.name}", TYPE, typestore=store(2)) for c in CASES]
        for conn, case, stamp in zip(conns, CASES, stamps, strict=True):
            writer2.write(conn, stamp, _serialised(case, 2, stamp))
            writer2.write(conn, stamp + 1, _serialised(case, 2, stamp))
    return path


@pytest.mark.parametrize("kind", ["ros1", "ros1-lz4", "ros2-sqlite3", "ros2-mcap"])
def test_unusual_layouts_in_real_logs_decode_exactly(tmp_path: Path, kind: str) -> None:
    path = _write(kind, tmp_path)
    by_topic = {f"/{c.name}": c for c in CASES}
    seen: dict[str, int] = {}
    with open_log(path) as log:
        for message in log.messages():
            case = by_topic[message.topic]
            decoded = decode(message, log.deserialize)
            cloud = decoded.value
            assert isinstance(cloud, PointCloud)
            assert decoded.frame_id == "lidar"
            xyz, channels = case.expected()
            np.testing.assert_array_equal(cloud.xyz, xyz, err_msg=case.name)
            assert set(cloud.channels) == set(channels), case.name
            for name, values in channels.items():
                got = cloud.channels[name]
                assert got.dtype == values.dtype, (case.name, name)
                np.testing.assert_array_equal(got, values, err_msg=f"{case.name}.{name}")
            seen[message.topic] = seen.get(message.topic, 0) + 1
    assert seen == dict.fromkeys(by_topic, 2)


def test_mapped_bag_messages_outlive_the_reader(tmp_path: Path) -> None:
    """An uncompressed bag is read from a file map; clouds stay valid after the log is closed."""
    path = _write("ros1", tmp_path)
    with open_log(path) as log:
        clouds = [decode(m, log.deserialize).value for m in log.messages()]
    xyz, channels = CASES[0].expected()
    assert isinstance(clouds[0], PointCloud)
    np.testing.assert_array_equal(clouds[0].xyz, xyz)
    np.testing.assert_array_equal(clouds[0].channels["time"], channels["time"])
    assert not clouds[0].channels["intensity"].flags.writeable
