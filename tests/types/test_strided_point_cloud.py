"""A ``PointCloud`` whose xyz is a strided view (what the PointCloud2 decoder gives) through
every consumer of ``PointCloud.xyz``: each gives what it gives for a C-contiguous copy."""

from __future__ import annotations

import math
import pickle
import uuid
from pathlib import Path

import numpy as np
import numpy.typing as npt

from redrive.algorithms.reference.detector import ClusterDetector
from redrive.interop.foxglove_msgs import point_cloud
from redrive.io import open_log
from redrive.io.mcap.writer import McapWriter
from redrive.io.ros.decoders import decode
from redrive.transport import Reader, Writer
from redrive.types import PointCloud, SensorData, SensorType

#: A Velodyne-like point: x, y, z, pad, intensity f32, ring u16, pad, time f64 (32 bytes).
POINT = np.dtype(
    [
        ("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("_pad", "V4"),
        ("intensity", "<f4"), ("ring", "<u2"), ("_pad2", "V2"), ("time", "<f8"),
    ]
)  # fmt: skip
SENSOR = (1.2, 0.0, 1.9)


def _scene() -> npt.NDArray[np.float64]:
    """Ground around a 4.5 × 1.8 × 1.5 m box's two faces that face the sensor, sensor frame."""
    c = np.arange(-30.0, 30.0, 0.5)
    gx, gy = np.meshgrid(c, c, indexing="ij")
    ground = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    inside = (np.abs(ground[:, 0] - 15.0) < 2.25) & (np.abs(ground[:, 1] - 5.0) < 0.9)
    zs = np.arange(0.2, 1.5 + 1e-9, 0.15)
    faces = []
    for xs, ys in ((np.full(19, 12.75), np.linspace(4.1, 5.9, 19)),
                   (np.linspace(12.75, 17.25, 46), np.full(46, 4.1))):  # fmt: skip
        xy = np.repeat(np.stack([xs, ys], axis=1), zs.size, axis=0)
        faces.append(np.column_stack([xy, np.tile(zs, xs.size)]))
    base = np.concatenate([ground[~inside], *faces])
    return base - np.asarray(SENSOR)


def _strided(points_sensor: npt.NDArray[np.float64]) -> PointCloud:
    """The cloud as the decoder makes it: read-only strided views of one bytes object."""
    n = len(points_sensor)
    packed = np.zeros(n, dtype=POINT)
    for i, axis in enumerate("xyz"):
        packed[axis] = points_sensor[:, i]
    packed["intensity"] = np.arange(n) % 97
    packed["ring"] = np.arange(n) % 32
    packed["time"] = np.linspace(0.0, 0.1, n)
    raw = packed.tobytes()
    xyz = np.ndarray((n, 3), np.float32, raw, 0, (POINT.itemsize, 4))
    channels = {
        name: np.ndarray((n,), POINT.fields[name][0], raw, POINT.fields[name][1], (32,))  # type: ignore[index]
        for name in ("intensity", "ring", "time")
    }
    cloud = PointCloud(xyz=xyz, channels=channels)
    assert not cloud.xyz.flags.c_contiguous
    assert not cloud.xyz.flags.writeable
    return cloud


def _contiguous(cloud: PointCloud) -> PointCloud:
    copy = PointCloud(
        xyz=np.ascontiguousarray(cloud.xyz),
        channels={k: np.ascontiguousarray(v) for k, v in cloud.channels.items()},
    )
    assert copy.xyz.flags.c_contiguous
    return copy


def _same(a: PointCloud, b: PointCloud) -> None:
    assert a.xyz.dtype == b.xyz.dtype == np.float32
    np.testing.assert_array_equal(a.xyz, b.xyz)
    assert list(a.channels) == list(b.channels)
    for name, values in a.channels.items():
        assert values.dtype == b.channels[name].dtype
        np.testing.assert_array_equal(values, b.channels[name])


def test_detector_gives_the_same_objects_for_a_strided_cloud() -> None:
    strided = _strided(_scene())
    det = ClusterDetector()
    det.configure({})
    det.bind({"lidar_top": SensorType.LIDAR})
    got = det.detect(strided.xyz, sensor_location=SENSOR)
    want = det.detect(_contiguous(strided).xyz, sensor_location=SENSOR)
    assert len(got) == len(want) == 1
    for a, b in zip(got, want, strict=True):
        assert (a.object_class, a.confidence, a.box.yaw_rad) == (
            b.object_class,
            b.confidence,
            b.box.yaw_rad,
        )
        np.testing.assert_array_equal(a.box.center, b.box.center)
        np.testing.assert_array_equal(a.box.size, b.box.size)
    assert math.isclose(got[0].box.center[0], 15.0, abs_tol=0.3)


def test_mcap_writer_round_trips_a_strided_cloud(tmp_path: Path) -> None:
    strided = _strided(_scene()[:500])
    path = tmp_path / "strided.mcap"
    with McapWriter(path) as out:
        out.write("/strided", 1, strided, frame_id="lidar_top", stamp_ns=5)
        out.write("/contiguous", 2, _contiguous(strided), frame_id="lidar_top", stamp_ns=5)
    with open_log(path) as log:
        back = {m.topic: decode(m, log.deserialize).value for m in log.messages()}
    assert isinstance(back["/strided"], PointCloud)
    assert isinstance(back["/contiguous"], PointCloud)
    _same(back["/strided"], strided)
    _same(back["/strided"], back["/contiguous"])


def test_transport_carries_a_strided_cloud() -> None:
    strided = _strided(_scene()[:500])
    sample = SensorData(
        sensor_id="lidar_top", sensor_type=SensorType.LIDAR, stamp_ns=3, data=strided
    )
    name = f"test.strided{uuid.uuid4().hex[:8]}"
    with Writer(name, capacity_bytes=1 << 20, slots=4) as w, Reader(name) as r:
        w.publish_sample(sample)
        got = r.read_sample(timeout_s=1.0)
    assert got is not None
    back = got[1].data
    assert isinstance(back, PointCloud)
    _same(back, strided)


def test_foxglove_point_cloud_of_a_strided_cloud() -> None:
    strided = _strided(_scene()[:500])
    got = point_cloud(strided, frame_id="lidar_top", stamp_ns=7)
    want = point_cloud(_contiguous(strided), frame_id="lidar_top", stamp_ns=7)
    assert got.encode() == want.encode()
    assert len(got.encode()) > 500 * 16


def test_a_strided_cloud_pickles_to_an_equal_read_only_cloud() -> None:
    """What a process pool or Ray worker hands back: equal values, still read-only."""
    strided = _strided(_scene()[:500])
    back = pickle.loads(pickle.dumps(strided))
    _same(back, strided)
    assert not back.xyz.flags.writeable
    assert not any(values.flags.writeable for values in back.channels.values())


def test_detector_gives_the_same_objects_for_an_unaligned_contiguous_cloud() -> None:
    """A 12-byte-a-point cloud viewing a reader's chunk: xyz C-contiguous but not 4-aligned
    (the points start wherever the message puts them).  The detector's kernels get an aligned
    copy; the objects are those of an aligned cloud."""
    points = np.ascontiguousarray(_scene(), dtype=np.float32)
    raw = b"\x00" + points.tobytes()
    xyz = np.ndarray(points.shape, np.float32, raw, 1)
    assert xyz.flags.c_contiguous
    assert not xyz.flags.aligned
    cloud = PointCloud(xyz=xyz)
    det = ClusterDetector()
    det.configure({})
    det.bind({"lidar_top": SensorType.LIDAR})
    got = det.detect(cloud.xyz, sensor_location=SENSOR)
    want = det.detect(points, sensor_location=SENSOR)
    assert len(got) == len(want) == 1
    np.testing.assert_array_equal(got[0].box.center, want[0].box.center)
    np.testing.assert_array_equal(got[0].box.size, want[0].box.size)
