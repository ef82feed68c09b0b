"""PointCloud2 fast path: exact against rosbags' full deserialisation on random layouts."""

from __future__ import annotations

import dataclasses
import mmap
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from redrive.errors import UnsupportedMessageError
from redrive.io.base import LogMessage
from redrive.io.ros.decoders import PointCloud2Decoder, read_cloud_layout
from redrive.io.ros.decoders.pointcloud2_batch import VIEW_SHARE
from redrive.types import PointCloud
from tests.io._decoder_helpers import deserializer, header, log_message

TYPE = "sensor_msgs/msg/PointCloud2"
CODES = {1: "b", 2: "B", 3: "h", 4: "H", 5: "i", 6: "I", 7: "f", 8: "d"}
NUMPY = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def _no_deserialize(message: LogMessage) -> object:
    raise AssertionError("the PointCloud2 fast path must not deserialise")


def _field(name: str, offset: int, datatype: int, count: int = 1) -> dict[str, Any]:
    return {"name": name, "offset": offset, "datatype": datatype, "count": count}


def _cloud_message(
    ros_version: int,
    *,
    fields: list[dict[str, Any]],
    data: bytes,
    width: int,
    height: int = 1,
    point_step: int,
    row_step: int | None = None,
    is_bigendian: bool = False,
    little_endian: bool = True,
    stamp_ns: int = 1_600_000_000_123_456_789,
    raw_wrapper: Any = bytes,
) -> LogMessage:
    msg = log_message(
        ros_version,
        TYPE,
        little_endian=little_endian,
        header=header(ros_version, stamp_ns, "lidar_top"),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=is_bigendian,
        point_step=point_step,
        row_step=width * point_step if row_step is None else row_step,
        data=np.frombuffer(data, dtype=np.uint8),
        is_dense=False,
    )
    if raw_wrapper is bytes:
        return msg
    return LogMessage(
        topic=msg.topic,
        msgtype=msg.msgtype,
        log_time_ns=msg.log_time_ns,
        encoding=msg.encoding,
        raw=raw_wrapper(msg.raw),
    )


def _reference(message: LogMessage) -> tuple[np.ndarray, dict[str, np.ndarray], Any]:
    """Per-point struct.unpack over rosbags' fully deserialised message."""
    msg: Any = deserializer()(message)
    data = bytes(msg.data)
    order = ">" if msg.is_bigendian else "<"
    columns: dict[str, list[Any]] = {}
    kinds: dict[str, int] = {}
    for f in msg.fields:
        count = max(int(f.count), 1)
        size = struct.calcsize(CODES[f.datatype])
        for i in range(count):
            name = f.name if count == 1 else f"{f.name}_{i}"
            kinds[name] = f.datatype
            columns[name] = [
                struct.unpack_from(
                    order + CODES[f.datatype],
                    data,
                    r * msg.row_step + c * msg.point_step + f.offset + i * size,
                )[0]
                for r in range(msg.height)
                for c in range(msg.width)
            ]
    n = msg.width * msg.height
    with np.errstate(over="ignore", invalid="ignore"):
        xyz = np.zeros((n, 3), dtype=np.float32)
        for j, axis in enumerate("xyz"):
            xyz[:, j] = np.array(columns[axis], dtype=NUMPY[kinds[axis]]).astype(np.float32)
    channels = {
        k: np.array(v, dtype=NUMPY[kinds[k]])
        for k, v in columns.items()
        if k not in ("x", "y", "z")
    }
    return xyz, channels, msg


@st.composite
def cloud_layouts(draw: st.DrawFn) -> dict[str, Any]:
    specs: list[tuple[str, int, int]] = [
        (axis, draw(st.sampled_from([7, 7, 8, 1, 2, 3, 4, 5, 6])), 1) for axis in "xyz"
    ]
    extra = draw(
        st.lists(
            st.sampled_from(["intensity", "ring", "t", "rgb", "label"]), max_size=4, unique=True
        )
    )
    for name in extra:
        specs.append((name, draw(st.integers(1, 8)), draw(st.sampled_from([1, 1, 1, 0, 2, 3]))))
    specs = draw(st.permutations(specs))
    fields, offset = [], 0
    for name, datatype, count in specs:
        offset += draw(st.integers(0, 3))
        fields.append(_field(name, offset, datatype, count))
        offset += int(NUMPY[datatype][1]) * max(count, 1)
    point_step = offset + draw(st.integers(0, 5))
    width = draw(st.integers(0, 7))
    height = draw(st.integers(1, 3))
    row_pad = draw(st.sampled_from([0, 0, 0, 1, 3, 8]))
    row_step = width * point_step + row_pad
    size = row_step * height
    data = bytearray(draw(st.binary(min_size=size, max_size=size)))
    big = draw(st.booleans())
    nan_rows = draw(st.lists(st.integers(0, max(width * height - 1, 0)), max_size=3))
    for p in nan_rows if width else []:
        r, c = divmod(p, width)
        for f in fields:
            if f["datatype"] in (7, 8):
                code = (">" if big else "<") + CODES[f["datatype"]]
                struct.pack_into(
                    code, data, r * row_step + c * point_step + f["offset"], float("nan")
                )
    return {
        "fields": fields,
        "data": bytes(data),
        "width": width,
        "height": height,
        "point_step": point_step,
        "row_step": row_step,
        "is_bigendian": big,
        "ros_version": draw(st.sampled_from([1, 2])),
        "little_endian": draw(st.booleans()),
    }


# One decoder across all examples: its layout cache sees hundreds of different field lists in a
# row and must never hand one cloud's layout to another.
_SHARED_DECODER = PointCloud2Decoder()


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(layout=cloud_layouts(), shared=st.booleans())
def test_random_layouts_match_full_deserialisation(layout: dict[str, Any], shared: bool) -> None:
    ros_version = layout.pop("ros_version")
    message = _cloud_message(ros_version, **layout)
    expected_xyz, expected_channels, msg = _reference(message)
    decoder = _SHARED_DECODER if shared else PointCloud2Decoder()
    decoded = decoder.decode(message, _no_deserialize)
    cloud = decoded.value
    assert decoded.frame_id == "lidar_top"
    assert decoded.stamp_ns == 1_600_000_000_123_456_789
    assert cloud.xyz.dtype == np.float32
    _pins_only_its_own_bytes(cloud, message)
    np.testing.assert_array_equal(cloud.xyz, expected_xyz)
    assert set(cloud.channels) == set(expected_channels)
    for name, values in expected_channels.items():
        got = cloud.channels[name]
        assert got.dtype == values.dtype.newbyteorder("="), name
        assert got.dtype.isnative
        np.testing.assert_array_equal(got, values, err_msg=name)
    # Whichever path decoded it, the cloud meets the data model's checks as it is.
    assert not cloud.xyz.flags.writeable
    assert all(not values.flags.writeable for values in cloud.channels.values())
    checked = PointCloud(xyz=cloud.xyz, channels=dict(cloud.channels))
    assert checked.xyz is cloud.xyz
    assert all(checked.channels[k] is v for k, v in cloud.channels.items())
    layout_read = read_cloud_layout(message.raw, message.encoding)
    assert (layout_read.width, layout_read.height) == (msg.width, msg.height)
    assert layout_read.point_step == msg.point_step
    assert layout_read.row_step == msg.row_step
    assert layout_read.is_bigendian == bool(msg.is_bigendian)


def _root(values: Any) -> Any:
    """The object at the end of an array's ``base`` chain (what keeps its memory alive),
    through a memoryview to what it views."""
    while isinstance(values, np.ndarray) and values.base is not None:
        values = values.base
    return values.obj if isinstance(values, memoryview) else values


def _pins_only_its_own_bytes(cloud: PointCloud, message: LogMessage) -> None:
    """xyz and the channels are read-only and hold the message's own ``bytes`` or a copy of
    the point bytes — never a view of a reader's buffer."""
    for values in (cloud.xyz, *cloud.channels.values()):
        assert not values.flags.writeable
        root = _root(values)
        if root is not message.raw:
            assert isinstance(root, bytes | np.ndarray), type(root)
            assert not np.shares_memory(values, np.frombuffer(message.raw, np.uint8))


def _padded_points(n: int) -> tuple[np.ndarray, list[Any]]:
    points = np.zeros(
        n,
        dtype=[
            ("x", "<f4"),
            ("y", "<f4"),
            ("z", "<f4"),
            ("pad", "<f4"),
            ("intensity", "<f4"),
            ("ring", "<u2"),
            ("pad2", "V2"),
        ],
    )
    points["x"] = np.arange(n)
    points["y"] = -np.arange(n)
    points["z"] = 0.5
    points["intensity"] = np.arange(n) * 2
    points["ring"] = np.arange(n) % 64
    fields = [
        _field("x", 0, 7),
        _field("y", 4, 7),
        _field("z", 8, 7),
        _field("intensity", 16, 7),
        _field("ring", 20, 4),
    ]
    return points, fields


def test_a_message_s_own_bytes_are_viewed_strided() -> None:
    """A message that is its own ``bytes`` (ROS 2 CDR: the points 4-aligned) is not copied:
    xyz and the channels are strided views of it."""
    n = 1000
    points, fields = _padded_points(n)
    message = _cloud_message(2, fields=fields, data=points.tobytes(), width=n, point_step=24)
    assert type(message.raw) is bytes
    cloud = PointCloud2Decoder().decode(message, _no_deserialize).value
    raw_array = np.frombuffer(message.raw, dtype=np.uint8)
    for values in (cloud.xyz, *cloud.channels.values()):
        assert np.shares_memory(values, raw_array)
        assert not values.flags.writeable
    assert cloud.xyz.strides == (24, 4)
    assert not cloud.xyz.flags.c_contiguous
    np.testing.assert_array_equal(cloud.xyz[:, 0], np.arange(n, dtype=np.float32))
    np.testing.assert_array_equal(cloud.xyz[:, 1], -np.arange(n, dtype=np.float32))
    np.testing.assert_array_equal(cloud.channels["ring"], np.arange(n) % 64)


@pytest.mark.parametrize("ros_version", [1, 2])
def test_a_small_part_of_a_reader_s_chunk_is_copied_once(ros_version: int) -> None:
    """A message that is a small part of a larger immutable buffer (a ROS 1 chunk of other
    topics' messages): the point bytes are copied once, xyz and the channels are strided views
    of that copy, and nothing keeps the chunk alive."""
    n = 1000
    points, fields = _padded_points(n)
    other = bytes(range(256)) * (2 * n * 24 // 256)  # other topics' bytes: 2x the cloud's
    message = _cloud_message(
        ros_version,
        fields=fields,
        data=points.tobytes(),
        width=n,
        point_step=24,
        raw_wrapper=lambda b: memoryview(b"chunk before" + b + other)[12 : 12 + len(b)],
    )
    chunk = message.raw.obj
    cloud = PointCloud2Decoder().decode(message, _no_deserialize).value
    roots = {id(_root(values)) for values in (cloud.xyz, *cloud.channels.values())}
    assert len(roots) == 1  # one copy for xyz and every channel
    root = _root(cloud.xyz)
    assert root is not chunk
    assert len(memoryview(root).cast("B")) == n * 24
    assert cloud.xyz.strides == (24, 4)
    _pins_only_its_own_bytes(cloud, message)
    np.testing.assert_array_equal(cloud.xyz[:, 0], np.arange(n, dtype=np.float32))
    np.testing.assert_array_equal(cloud.channels["intensity"], np.arange(n) * 2)


@pytest.mark.parametrize("ros_version", [1, 2])
@pytest.mark.parametrize("shift", [0, 1, 3])  # the points' alignment in the chunk
def test_a_cloud_that_fills_most_of_a_private_chunk_views_it(ros_version: int, shift: int) -> None:
    """A message whose points are at least VIEW_SHARE of the immutable ``bytes`` it lies in
    (a ROS 1 chunk read into its own buffer, holding mostly this cloud): xyz and the channels
    are read-only strided views of that buffer (which the cloud then pins: at most
    1 / VIEW_SHARE times its own point bytes), at whatever alignment, with the same values."""
    n = 1000
    points, fields = _padded_points(n)
    head = b"c" * (12 + shift)
    message = _cloud_message(
        ros_version,
        fields=fields,
        data=points.tobytes(),
        width=n,
        point_step=24,
        raw_wrapper=lambda b: memoryview(head + b + b"chunk after")[len(head) : len(head) + len(b)],
    )
    chunk = message.raw.obj
    assert type(chunk) is bytes
    cloud = PointCloud2Decoder().decode(message, _no_deserialize).value
    for values in (cloud.xyz, *cloud.channels.values()):
        assert _root(values) is chunk
        assert not values.flags.writeable
    assert n * 24 >= len(chunk) * VIEW_SHARE
    assert cloud.xyz.strides == (24, 4)
    np.testing.assert_array_equal(cloud.xyz[:, 0], np.arange(n, dtype=np.float32))
    np.testing.assert_array_equal(cloud.xyz[:, 1], -np.arange(n, dtype=np.float32))
    np.testing.assert_array_equal(cloud.xyz[:, 2], np.float32(0.5))
    np.testing.assert_array_equal(cloud.channels["intensity"], np.arange(n) * 2)
    np.testing.assert_array_equal(cloud.channels["ring"], np.arange(n) % 64)


def test_a_cloud_in_a_read_only_file_map_is_copied(tmp_path: Path) -> None:
    """A message in a read-only map of a file is copied however much of the map it fills:
    a cloud never pins a file map (the file may be cut or rewritten after it is closed)."""
    n = 1000
    points, fields = _padded_points(n)
    plain = _cloud_message(1, fields=fields, data=points.tobytes(), width=n, point_step=24)
    path = tmp_path / "message.bin"
    path.write_bytes(plain.raw)
    with path.open("rb") as fh:
        mapped = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    message = dataclasses.replace(plain, raw=memoryview(mapped))
    cloud = PointCloud2Decoder().decode(message, _no_deserialize).value
    root = _root(cloud.xyz)
    assert root is not mapped
    assert isinstance(root, bytes)
    assert len(root) == n * 24
    del message
    mapped.close()
    np.testing.assert_array_equal(cloud.xyz[:, 0], np.arange(n, dtype=np.float32))


def test_layout_cache_sees_a_changed_layout_on_the_same_topic() -> None:
    decoder = PointCloud2Decoder()
    xyzi = np.array([(1.0, 2.0, 3.0, 7.0)], dtype="<f4").tobytes()
    fields_i = [_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 7), _field("intensity", 12, 7)]
    fields_r = [_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 7), _field("ring", 12, 6)]
    for _ in range(3):
        for fields, name in ((fields_i, "intensity"), (fields_r, "ring")):
            message = _cloud_message(2, fields=fields, data=xyzi, width=1, point_step=16)
            cloud = decoder.decode(message, _no_deserialize).value
            assert set(cloud.channels) == {name}
            np.testing.assert_array_equal(cloud.xyz, [[1.0, 2.0, 3.0]])
    # the same layout with a longer frame id shifts every offset: still read right
    message = log_message(
        1,
        TYPE,
        header=header(1, 5, "a_much_longer_frame_id"),
        height=1,
        width=1,
        fields=fields_i,
        is_bigendian=False,
        point_step=16,
        row_step=16,
        data=np.frombuffer(xyzi, dtype=np.uint8),
        is_dense=True,
    )
    decoded = decoder.decode(message, _no_deserialize)
    assert decoded.frame_id == "a_much_longer_frame_id"
    assert decoded.value.channels["intensity"][0] == 7.0


def test_mutable_reader_buffer_is_copied() -> None:
    data = np.array([(1.0, 2.0, 3.0, 7.0)], dtype="<f4").tobytes()
    fields = [_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 7), _field("intensity", 12, 7)]
    message = _cloud_message(
        2,
        fields=fields,
        data=data,
        width=1,
        point_step=16,
        raw_wrapper=lambda b: memoryview(bytearray(b)),
    )
    cloud = PointCloud2Decoder().decode(message, _no_deserialize).value
    assert isinstance(message.raw, memoryview)
    message.raw[:] = b"\xff" * len(message.raw)  # the reader reuses its buffer
    assert cloud.channels["intensity"][0] == 7.0
    np.testing.assert_array_equal(cloud.xyz, [[1.0, 2.0, 3.0]])


def test_big_endian_cdr_and_big_endian_points() -> None:
    data = np.array(
        [(1.5, -2.5, 3.25, 9)], dtype=[("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("ring", ">u2")]
    ).tobytes()
    fields = [_field("x", 0, 8), _field("y", 8, 8), _field("z", 16, 8), _field("ring", 24, 4)]
    message = _cloud_message(
        2, fields=fields, data=data, width=1, point_step=26, is_bigendian=True, little_endian=False
    )
    assert bytes(message.raw[:4]) == b"\x00\x00\x00\x00"
    cloud = PointCloud2Decoder().decode(message, _no_deserialize).value
    np.testing.assert_array_equal(cloud.xyz, np.array([[1.5, -2.5, 3.25]], dtype=np.float32))
    assert cloud.channels["ring"].dtype == np.dtype("=u2")
    assert int(cloud.channels["ring"][0]) == 9


def test_organised_cloud_with_nans_keeps_every_point() -> None:
    grid = np.full((4, 5, 3), np.nan, dtype="<f4")
    grid[1, 2] = (1.0, 2.0, 3.0)
    fields = [_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 7)]
    message = _cloud_message(
        1, fields=fields, data=grid.tobytes(), width=5, height=4, point_step=12
    )
    cloud = PointCloud2Decoder().decode(message, _no_deserialize).value
    assert cloud.num_points == 20
    assert np.isnan(cloud.xyz).all(axis=1).sum() == 19
    np.testing.assert_array_equal(cloud.xyz[7], [1.0, 2.0, 3.0])


def test_count_field_is_expanded() -> None:
    data = struct.pack("<fff3B", 1.0, 2.0, 3.0, 10, 20, 30)
    fields = [_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 7), _field("rgb", 12, 2, 3)]
    message = _cloud_message(2, fields=fields, data=data, width=1, point_step=15)
    cloud = PointCloud2Decoder().decode(message, _no_deserialize).value
    assert [int(cloud.channels[f"rgb_{i}"][0]) for i in range(3)] == [10, 20, 30]


@pytest.mark.parametrize(
    ("fields", "point_step", "data", "match"),
    [
        ([_field("x", 0, 7), _field("y", 4, 7)], 8, b"\0" * 8, "no z field"),
        ([_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 9)], 12, b"\0" * 12, "datatype 9"),
        (
            [_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 7)],
            12,
            b"\0" * 11,
            "data holds 11 bytes",
        ),
        ([_field("x", 0, 7, 2), _field("y", 8, 7), _field("z", 12, 7)], 16, b"\0" * 16, "count 2"),
        ([_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 8)], 12, b"\0" * 12, "does not fit"),
        (
            [_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 7), _field("y", 8, 7)],
            12,
            b"\0" * 12,
            "repeated",
        ),
    ],
)
def test_bad_layouts_are_rejected_clearly(
    fields: list[dict[str, Any]], point_step: int, data: bytes, match: str
) -> None:
    message = _cloud_message(1, fields=fields, data=data, width=1, point_step=point_step)
    with pytest.raises(UnsupportedMessageError, match=match) as info:
        PointCloud2Decoder().decode(message, _no_deserialize)
    assert "'/topic'" in str(info.value)


def test_truncated_and_non_cdr_bytes_are_rejected() -> None:
    fields = [_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 7)]
    message = _cloud_message(2, fields=fields, data=b"\0" * 12, width=1, point_step=12)
    cut = LogMessage(topic="/c", msgtype=TYPE, log_time_ns=0, encoding="cdr", raw=message.raw[:30])
    with pytest.raises(UnsupportedMessageError, match=r"truncated|overruns"):
        PointCloud2Decoder().decode(cut, _no_deserialize)
    xcdr = LogMessage(
        topic="/c",
        msgtype=TYPE,
        log_time_ns=0,
        encoding="cdr",
        raw=b"\x00\x07\x00\x00" + bytes(message.raw[4:]),
    )
    with pytest.raises(UnsupportedMessageError, match="not plain CDR"):
        PointCloud2Decoder().decode(xcdr, _no_deserialize)


def test_zero_stamp_falls_back_to_log_time() -> None:
    fields = [_field("x", 0, 7), _field("y", 4, 7), _field("z", 8, 7)]
    message = _cloud_message(2, fields=fields, data=b"", width=0, point_step=12, stamp_ns=0)
    decoded = PointCloud2Decoder().decode(message, _no_deserialize)
    assert decoded.stamp_ns == message.log_time_ns
    assert decoded.value.num_points == 0


@pytest.mark.parametrize("ros_version", [1, 2])
@pytest.mark.parametrize("raw_wrapper", [bytes, lambda b: memoryview(bytearray(b))])
def test_fast_and_general_paths_give_the_same_cloud(ros_version: int, raw_wrapper: Any) -> None:
    """A driver's layout (native, x/y/z adjacent float32) read from immutable bytes takes the
    fast path, from a reusable buffer the general one; the clouds are equal member for member."""
    n = 300
    points = np.zeros(
        n,
        dtype={
            "names": ["x", "y", "z", "intensity", "ring", "time"],
            "formats": ["<f4", "<f4", "<f4", "<f4", "<u2", "<f8"],
            "offsets": [0, 4, 8, 12, 16, 24],
            "itemsize": 32,
        },
    )
    rng = np.random.default_rng(3)
    for name in ("x", "y", "z", "intensity"):
        points[name] = rng.normal(size=n)
    points["x"][5] = np.nan
    points["ring"] = np.arange(n) % 32
    points["time"] = np.arange(n) * 1e-5
    fields = [
        _field("x", 0, 7),
        _field("y", 4, 7),
        _field("z", 8, 7),
        _field("intensity", 12, 7),
        _field("ring", 16, 4),
        _field("time", 24, 8),
    ]
    message = _cloud_message(
        ros_version,
        fields=fields,
        data=points.tobytes(),
        width=n,
        point_step=32,
        raw_wrapper=raw_wrapper,
    )
    decoder = PointCloud2Decoder()
    clouds = [decoder.decode(message, _no_deserialize) for _ in range(2)]  # miss, then cached
    expected_xyz, expected_channels, _ = _reference(message)
    for decoded in clouds:
        cloud = decoded.value
        assert decoded.frame_id == "lidar_top"
        assert cloud.xyz.shape == (n, 3)
        _pins_only_its_own_bytes(cloud, message)
        assert not cloud.xyz.flags.writeable
        np.testing.assert_array_equal(cloud.xyz, expected_xyz)
        assert list(cloud.channels) == ["intensity", "ring", "time"]
        for name, values in expected_channels.items():
            assert cloud.channels[name].dtype == values.dtype
            assert not cloud.channels[name].flags.writeable
            np.testing.assert_array_equal(cloud.channels[name], values)
