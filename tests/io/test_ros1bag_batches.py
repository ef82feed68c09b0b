"""The indexed ROS 1 reader's chunk-at-once path and the PointCloud2 batch decode.

The reader finds and checks the messages of a chunk together and links those of one connection
as a :class:`~redrive.io.base.MessageBatch`; the PointCloud2 decoder then decodes a batch's
clouds with a few array operations.  Bags written with rosbags' writer must read back as
rosbags reads them (order, times, bytes), every cloud must equal the one-message decode and the
source values, and a record that is not what the index says must still be reported at that
message with every message before it read.
"""

from __future__ import annotations

import dataclasses
import gc
import mmap
import struct
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Reader as Bag1Reader
from rosbags.rosbag1 import Writer as Bag1Writer

import redrive.io.ros.decoders.pointcloud2_batch as pb
from redrive.errors import LogTruncatedError
from redrive.io import open_log
from redrive.io.ros.decoders import decode
from redrive.io.ros.decoders.pointcloud2 import PointCloud2Decoder
from redrive.types import PointCloud
from tests.io._decoder_helpers import header, make, serialize, store

TYPE = "sensor_msgs/msg/PointCloud2"
T0 = 1_700_000_000_000_000_000
POINT = np.dtype(
    [
        ("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("_pad", "V4"),
        ("intensity", "<f4"), ("ring", "<u2"), ("_pad2", "V2"), ("time", "<f8"),
    ]
)  # fmt: skip
FIELDS = [
    {"name": name, "offset": POINT.fields[name][1], "datatype": code, "count": 1}  # type: ignore[index]
    for name, code in (("x", 7), ("y", 7), ("z", 7), ("intensity", 7), ("ring", 4), ("time", 8))
]


def _points(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    points = np.zeros(n, dtype=POINT)
    for name in ("x", "y", "z", "intensity"):
        points[name] = rng.normal(0, 20, n)
    points["x"][::5] = np.nan
    points["ring"] = rng.integers(0, 64, n)
    points["time"] = rng.uniform(0, 0.1, n)
    return points


def _cloud(points: np.ndarray, stamp_ns: int) -> bytes:
    msg = make(
        store(1),
        TYPE,
        header=header(1, stamp_ns, "lidar"),
        height=1,
        width=len(points),
        fields=FIELDS,
        is_bigendian=False,
        point_step=POINT.itemsize,
        row_step=len(points) * POINT.itemsize,
        data=np.frombuffer(points.tobytes(), dtype=np.uint8),
        is_dense=False,
    )
    return serialize(1, msg, TYPE)


def _write(
    path: Path, *, compression: str = "none", count: int = 60, mixed: bool = True
) -> dict[tuple[str, int], np.ndarray]:
    """/regular: 40-point clouds; when ``mixed``, between them /varied: clouds of 5-40 points,
    /unstamped: stamp 0, /text: std_msgs/String.  Small chunks of many messages.  Returns the
    points of every cloud by (topic, log time)."""
    string = store(1).types["std_msgs/msg/String"]
    writer = Bag1Writer(path)
    writer.chunk_threshold = 48 * 1024
    if compression != "none":
        writer.set_compression(Bag1Writer.CompressionFormat[compression.upper()])
    sent: dict[tuple[str, int], np.ndarray] = {}
    with writer:
        conns = {
            topic: writer.add_connection(topic, TYPE, typestore=store(1))
            for topic in ("/regular", "/varied", "/unstamped")
        }
        text = writer.add_connection("/text", "std_msgs/msg/String", typestore=store(1))
        for i in range(count):
            t = T0 + i * 10_000_000
            for k, (topic, n) in enumerate(
                (("/regular", 40), ("/varied", 5 + (i * 7) % 36), ("/unstamped", 12))
            ):
                if topic != "/regular" and (i % 2 or not mixed):
                    continue
                points = _points(n, seed=i * 3 + k)
                stamp = 0 if topic == "/unstamped" else t - 5_000_000
                writer.write(conns[topic], t + k, _cloud(points, stamp))
                sent[topic, t + k] = points
            if i % 5 == 0 and mixed:
                writer.write(
                    text,
                    t + 3,
                    bytes(store(1).serialize_ros1(string(data=f"m{i}"), string.__msgtype__)),
                )
    return sent


def _rosbags_messages(path: Path, **kw: int) -> list[tuple[str, int, bytes]]:
    with Bag1Reader(path) as reader:
        return [(c.topic, t, bytes(d)) for c, t, d in reader.messages(**kw)]


def _root(values: object) -> object:
    """What keeps an array's memory alive: the end of its ``base`` chain, through a
    memoryview to what it views."""
    while isinstance(values, np.ndarray) and values.base is not None:
        values = values.base
    return values.obj if isinstance(values, memoryview) else values


def _same_cloud(a: PointCloud, b: PointCloud, *, batch_size: int = 1) -> None:
    """Equal values; ``a``'s arrays are read-only views of immutable bytes: a copy of point
    bytes of at most GROUP_BYTES (or of one cloud), or a reader's private chunk that the
    ``batch_size`` clouds of its batch fill to at least VIEW_SHARE — never a file map."""
    assert a.xyz.dtype == b.xyz.dtype == np.float32
    assert a.xyz.shape == b.xyz.shape
    assert not a.xyz.flags.writeable
    own = len(a) * POINT.itemsize
    for values in (a.xyz, *a.channels.values()):
        root = _root(values)
        assert isinstance(root, bytes | np.ndarray), type(root)
        size = len(memoryview(root).cast("B"))
        assert size <= max(pb.GROUP_BYTES, own, own * batch_size / pb.VIEW_SHARE)
    np.testing.assert_array_equal(a.xyz, b.xyz)
    assert list(a.channels) == list(b.channels)
    for name, values in a.channels.items():
        assert values.dtype == b.channels[name].dtype
        assert not values.flags.writeable
        np.testing.assert_array_equal(values, b.channels[name])


@pytest.mark.parametrize(
    ("compression", "mixed", "group_bytes"),
    [
        ("none", True, pb.GROUP_BYTES),
        ("lz4", True, pb.GROUP_BYTES),
        ("none", False, pb.GROUP_BYTES),
        ("none", False, 3 * 40 * POINT.itemsize),  # groups of 3 /regular clouds and a rest
        ("none", True, 1),  # every cloud copied alone into its own bytes
    ],
)
def test_chunks_read_together_give_rosbags_messages_and_equal_clouds(
    tmp_path: Path, compression: str, mixed: bool, group_bytes: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Mixed: /regular's clouds lie between other topics' messages (gathered); alone: at a
    fixed distance (one strided view).  Their point bytes are copied in groups of at most
    ``group_bytes``."""
    monkeypatch.setattr(pb, "GROUP_BYTES", group_bytes)
    path = tmp_path / "clouds.bag"
    sent = _write(path, compression=compression, mixed=mixed)
    alone = PointCloud2Decoder()
    batched = 0
    with open_log(path) as log:
        messages = list(log.messages())
        got = [(m.topic, m.log_time_ns, bytes(m.raw)) for m in messages]
        assert got == _rosbags_messages(path)
        for message in messages:
            if message.topic == "/text":
                continue
            decoded = decode(message, log.deserialize)
            plain = dataclasses.replace(message)  # drops the batch link: decoded on its own
            assert plain.batch is None
            single = alone.decode(plain, log.deserialize)
            assert (decoded.stamp_ns, decoded.frame_id) == (single.stamp_ns, single.frame_id)
            assert isinstance(decoded.value, PointCloud)
            assert isinstance(single.value, PointCloud)
            assert message.batch is not None
            _same_cloud(decoded.value, single.value, batch_size=len(message.batch[0]))
            points = sent[message.topic, message.log_time_ns]
            xyz = np.stack([points[a] for a in "xyz"], axis=1)
            np.testing.assert_array_equal(decoded.value.xyz, xyz)
            np.testing.assert_array_equal(decoded.value.channels["time"], points["time"])
            if message.topic == "/unstamped":
                assert decoded.stamp_ns == message.log_time_ns
            assert message.batch is not None
            batch, index = message.batch
            (done,) = batch.memo.values()  # the registry's PointCloud2 decoder's results
            batched += done[index] is not None
    # The /regular clouds are decoded together (the others are not of one size).
    assert batched >= 60


def test_time_ranges_and_topics_read_together_are_rosbags_ones(tmp_path: Path) -> None:
    path = tmp_path / "clouds.bag"
    _write(path)
    start, stop = T0 + 95_000_000, T0 + 433_000_001
    with open_log(path) as log:
        got = [
            (m.topic, m.log_time_ns, bytes(m.raw))
            for m in log.messages(topics=["/regular", "/text"], start_ns=start, stop_ns=stop)
        ]
    want = [
        m for m in _rosbags_messages(path, start=start, stop=stop) if m[0] in ("/regular", "/text")
    ]
    assert got == want
    assert len(got) > 30


def _damage_record(path: Path, field: bytes, *, nth: int = 9) -> int:
    """Change the ``field`` (``time`` or ``conn``) value in the record header of the
    ``nth`` (from 0) /regular message of the second chunk holding at least 14 of them; returns
    that message's index among the /regular messages."""
    with Bag1Reader(path) as reader:
        conn = next(c for c in reader.connections if c.topic == "/regular")
        entries = reader.indexes[conn.id]
        per_chunk: dict[int, list[int]] = {}
        for i, entry in enumerate(entries):
            per_chunk.setdefault(entry.chunk_pos, []).append(i)
        which = [rows for rows in per_chunk.values() if len(rows) >= 14][1][nth]
        entry = entries[which]
        chunk = reader.chunks[entry.chunk_pos]
    at = chunk.datapos + entry.offset
    with path.open("r+b") as fh:
        fh.seek(at)
        (size,) = struct.unpack("<I", fh.read(4))
        head = fh.read(size)
        value = head.index(field + b"=") + len(field) + 1
        fh.seek(at + 4 + value)
        fh.write(b"\x7f\x7f\x7f\x7f")
    return which


@pytest.mark.parametrize("field", [b"time", b"conn"])
def test_a_record_that_is_not_the_index_s_is_damage_at_that_message(
    tmp_path: Path, field: bytes
) -> None:
    path = tmp_path / "clouds.bag"
    _write(path)
    intact = _rosbags_messages(path)
    regular = [m for m in intact if m[0] == "/regular"]
    # In a chunk large enough to be checked at once first (12 messages or more).
    k = _damage_record(path, field)
    with open_log(path, strict=False) as log:
        got = [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages(topics=["/regular"])]
        report = log.damage_report
    assert len(report) == 1
    assert "another message" in report[0].what
    # Every message before the damaged one is read; the rest of its chunk is lost, then reading
    # goes on with the next chunk.
    assert got[:k] == regular[:k]
    assert set(got) < set(regular)
    assert got[k] != regular[k]
    lost = [m for m in regular if m not in got]
    assert lost[0] == regular[k]
    assert len(lost) >= 5
    read: list[bytes] = []

    def read_all() -> None:
        with open_log(path) as log:
            read.extend(bytes(message.raw) for message in log.messages(topics=["/regular"]))

    with pytest.raises(LogTruncatedError, match="another message"):
        read_all()
    assert read == [m[2] for m in regular[:k]]


@pytest.mark.parametrize("mixed", [True, False])
def test_a_chunk_whose_first_message_is_damaged_is_reported_and_skipped(
    tmp_path: Path, mixed: bool
) -> None:
    """No message of the chunk can be read: strict reading raises LogTruncatedError after the
    chunks before it (it raised an IndexError from the batch build before branch h-read6),
    lenient reading reports the chunk and goes on with the next one."""
    path = tmp_path / "clouds.bag"
    _write(path, mixed=mixed, count=120)
    regular = [m for m in _rosbags_messages(path) if m[0] == "/regular"]
    k = _damage_record(path, b"time", nth=0)
    with open_log(path, strict=False) as log:
        got = [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages(topics=["/regular"])]
        report = log.damage_report
    assert len(report) == 1
    assert "another message" in report[0].what
    assert got[:k] == regular[:k]
    lost = [m for m in regular if m not in got]
    assert lost[0] == regular[k]
    assert len(lost) >= 14
    assert got[k:] == [m for m in regular[k:] if m not in lost]
    assert len(got) > k
    read: list[bytes] = []
    with pytest.raises(LogTruncatedError, match="another message"), open_log(path) as log:
        read.extend(bytes(message.raw) for message in log.messages(topics=["/regular"]))
    assert read == [m[2] for m in regular[:k]]


def test_clouds_of_a_damaged_bag_read_together_equal_the_one_message_decode(
    tmp_path: Path,
) -> None:
    """The chunk with a damaged record is read up to it; every cloud read, before and after,
    decodes (together with its chunk's) to the one-message decode and the values written."""
    path = tmp_path / "clouds.bag"
    sent = _write(path)
    k = _damage_record(path, b"time")
    alone = PointCloud2Decoder()
    together = 0
    with open_log(path, strict=False) as log:
        messages = list(log.messages(topics=["/regular", "/varied", "/unstamped"]))
        assert len(log.damage_report) == 1
        for message in messages:
            decoded = decode(message, log.deserialize)
            single = alone.decode(dataclasses.replace(message), log.deserialize)
            assert (decoded.stamp_ns, decoded.frame_id) == (single.stamp_ns, single.frame_id)
            assert isinstance(decoded.value, PointCloud)
            assert isinstance(single.value, PointCloud)
            assert message.batch is not None
            _same_cloud(decoded.value, single.value, batch_size=len(message.batch[0]))
            points = sent[message.topic, message.log_time_ns]
            np.testing.assert_array_equal(
                decoded.value.xyz, np.stack([points[a] for a in "xyz"], axis=1)
            )
            for name in ("intensity", "ring", "time"):
                np.testing.assert_array_equal(decoded.value.channels[name], points[name])
            assert message.batch is not None
            batch, index = message.batch
            together += batch.memo[next(iter(batch.memo))][index] is not None
    regular = [m for m in messages if m.topic == "/regular"]
    assert k < len(regular) < 60
    assert together >= len(regular) - 14  # the chunks after the damage are read together too


@pytest.mark.parametrize("compression", ["none", "lz4"])
def test_clouds_outlive_their_reader_and_their_file(tmp_path: Path, compression: str) -> None:
    """Clouds that view their chunk's buffer keep it, not the file: after the reader is
    closed and the bag truncated and deleted, every kept cloud still has the values written."""
    path = tmp_path / "clouds.bag"
    sent = _write(path, compression=compression, mixed=False)
    kept: list[tuple[tuple[str, int], PointCloud]] = []
    viewed = 0
    with open_log(path) as log:
        for message in log.messages():
            cloud = decode(message, log.deserialize).value
            assert isinstance(cloud, PointCloud)
            kept.append(((message.topic, message.log_time_ns), cloud))
            chunk = message.raw.obj
            viewed += _root(cloud.xyz) is chunk and type(chunk) is bytes
    assert viewed >= 50  # the /regular clouds fill their chunks: views of them
    with path.open("r+b") as fh:
        fh.truncate(0)
    path.unlink()
    gc.collect()
    assert len(kept) == len(sent) == 60
    for key, cloud in kept:
        points = sent[key]
        np.testing.assert_array_equal(cloud.xyz, np.stack([points[a] for a in "xyz"], axis=1))
        for name in ("intensity", "ring", "time"):
            np.testing.assert_array_equal(cloud.channels[name], points[name])


def _write_sparse(path: Path) -> dict[tuple[str, int], np.ndarray]:
    """/big: 2,000-point clouds; /small: a 40-point cloud before each, in chunks of ≈ 512 KiB
    (8 of each a chunk, a /big message last): /small's point bytes are 2 % of every chunk."""
    writer = Bag1Writer(path)
    writer.chunk_threshold = 512 * 1024
    sent: dict[tuple[str, int], np.ndarray] = {}
    with writer:
        conns = {t: writer.add_connection(t, TYPE, typestore=store(1)) for t in ("/big", "/small")}
        for i in range(40):
            for k, (topic, n) in enumerate((("/small", 40), ("/big", 2000))):
                t = T0 + i * 10_000_000 + k
                points = _points(n, seed=i * 2 + k)
                writer.write(conns[topic], t, _cloud(points, t))
                sent[topic, t] = points
    return sent


@pytest.mark.parametrize("topics", [["/small"], ["/small", "/big"]])
def test_a_sparse_selection_copies_its_clouds_rather_than_pin_the_chunk(
    tmp_path: Path, topics: list[str]
) -> None:
    """A topic whose clouds are a small part of their chunks (one small topic among a large
    one) is copied out (at most GROUP_BYTES a copy), never pins the chunk; the topic that
    fills the chunks views it.  Values are the ones written either way."""
    path = tmp_path / "sparse.bag"
    sent = _write_sparse(path)
    roots: dict[str, list[tuple[object, object]]] = {"/big": [], "/small": []}
    with open_log(path) as log:
        for message in log.messages(topics=topics):
            assert message.batch is not None
            cloud = decode(message, log.deserialize).value
            assert isinstance(cloud, PointCloud)
            points = sent[message.topic, message.log_time_ns]
            np.testing.assert_array_equal(cloud.xyz, np.stack([points[a] for a in "xyz"], axis=1))
            np.testing.assert_array_equal(cloud.channels["time"], points["time"])
            for values in (cloud.xyz, *cloud.channels.values()):
                roots[message.topic].append((_root(values), message.raw.obj))
    assert len(roots["/small"]) == 40 * 4
    for root, chunk in roots["/small"]:
        assert root is not chunk
        assert len(memoryview(root).cast("B")) <= pb.GROUP_BYTES  # type: ignore[arg-type]
    if "/big" in topics:
        assert len(roots["/big"]) == 40 * 4
        assert all(root is chunk and type(chunk) is bytes for root, chunk in roots["/big"])


def test_only_chunks_read_for_clouds_are_read_into_bytes(tmp_path: Path) -> None:
    """An uncompressed chunk is read into its own ``bytes`` when it holds selected PointCloud2
    messages; a selection without clouds reads the same chunks through the file map."""
    path = tmp_path / "clouds.bag"
    _write(path)
    with open_log(path) as log:
        text = list(log.messages(topics=["/text"]))
        clouds = list(log.messages(topics=["/regular", "/text"]))
        assert text
        assert clouds
        assert all(isinstance(m.raw.obj, mmap.mmap) for m in text)
        assert all(type(m.raw.obj) is bytes for m in clouds)
        assert [bytes(m.raw) for m in text] == [bytes(m.raw) for m in clouds if m.topic == "/text"]


def test_clouds_of_a_chunk_larger_than_view_max_bytes_are_copied(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Clouds that fill a chunk together but are each a small part of it view it only while it
    is at most VIEW_MAX_BYTES: one cloud kept must not pin a chunk of any size a recorder
    chose.  Past that they are copied (values equal)."""
    path = tmp_path / "clouds.bag"
    sent = _write(path, mixed=False)
    monkeypatch.setattr(pb, "VIEW_MAX_BYTES", 8 * 1024)  # the bag's chunks are ≈ 48 KiB
    with open_log(path) as log:
        for message in log.messages():
            cloud = decode(message, log.deserialize).value
            assert isinstance(cloud, PointCloud)
            assert _root(cloud.xyz) is not message.raw.obj
            size = len(memoryview(_root(cloud.xyz)).cast("B"))  # type: ignore[arg-type]
            assert size <= pb.GROUP_BYTES
            points = sent[message.topic, message.log_time_ns]
            np.testing.assert_array_equal(cloud.xyz, np.stack([points[a] for a in "xyz"], axis=1))
