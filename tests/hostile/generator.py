"""A seeded generator of hostile inputs (issue 37): damaged, lying and extreme logs made from a
short ``redrive synth`` recording and from real ROS 1 bags, plus files that are not logs at all.

``make_hostile(base_mcap, real_bag, out_dir, seed)`` writes every input to ``out_dir`` and returns
their paths by name; the same seed and sources give byte-identical files.  Each input is described
in :data:`DESCRIPTIONS`.
"""

from __future__ import annotations

import os
import random
import struct
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

MCAP_MAGIC = b"\x89MCAP0\r\n"
BAG_MAGIC = b"#ROSBAG V2.0\n"
_CHUNK_OPCODE = 0x06

DESCRIPTIONS: dict[str, str] = {
    "truncated_a.mcap": "the synth log cut at a random offset in its first half",
    "truncated_b.mcap": "the synth log cut at a random offset in its second half",
    "byte_flips.mcap": "the synth log with 24 random bytes flipped",
    "truncated.bag": "a real ROS 1 bag cut at a random offset",
    "byte_flips.bag": "a real ROS 1 bag with 24 random bytes flipped",
    "huge_record_length.mcap": "the first chunk record declares a length of 2^62 bytes",
    "chunk_lies_size.mcap": "a chunk declares 2^40 uncompressed bytes and a records length past "
    "its end",
    "huge_record_length.bag": "the first chunk record of a bag declares 4 GiB of data",
    "chunk_lies_size.bag": "a bag chunk's header says it holds 0xFFFFFF00 uncompressed bytes",
    "lying_cloud.mcap": "PointCloud2 whose point_step, row_step and width x height do not match "
    "the data length (each message lies another way)",
    "lying_image.mcap": "Images whose step x height is larger than the data (and a zero step)",
    "nan_everywhere.mcap": "NaN and inf in every float field of the clouds, odometry, IMU and tf",
    "time_backwards.mcap": "log and header times decrease message by message",
    "duplicate_timestamps.mcap": "every message of the log at one and the same time",
    "zero_bytes.mcap": "an empty file",
    "zero_bytes.bag": "an empty file named .bag",
    "magic_only.mcap": "only the MCAP magic",
    "directory.mcap": "a directory named x.mcap (with a file inside)",
    "fifo.mcap": "a named pipe",
    "deep_msgdef.bag": "a bag connection whose message definition nests 400 levels deep",
    "recursive_msgdef.bag": "a bag connection whose message type contains itself",
}


# --------------------------------------------------------------------------- byte-level damage


def _truncate(src: bytes, rng: random.Random, lo: float, hi: float) -> bytes:
    return src[: rng.randrange(int(len(src) * lo), int(len(src) * hi))]


def _flip(src: bytes, rng: random.Random, count: int = 24) -> bytes:
    out = bytearray(src)
    for _ in range(count):
        at = rng.randrange(len(out))
        out[at] ^= 1 << rng.randrange(8)
    return bytes(out)


def _mcap_records(data: bytes) -> Iterator[tuple[int, int, int]]:
    """(offset, opcode, length) of each top-level record of an intact MCAP."""
    pos = len(MCAP_MAGIC)
    while pos + 9 <= len(data):
        opcode = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        yield pos, opcode, length
        pos += 9 + length


def _first_chunk(data: bytes) -> tuple[int, int]:
    for offset, opcode, length in _mcap_records(data):
        if opcode == _CHUNK_OPCODE:
            return offset, length
    raise ValueError("no chunk in the MCAP")


def _huge_mcap_record(src: bytes) -> bytes:
    offset, _ = _first_chunk(src)
    out = bytearray(src)
    struct.pack_into("<Q", out, offset + 1, 1 << 62)
    return bytes(out)


def _lying_mcap_chunk(src: bytes) -> bytes:
    offset, length = _first_chunk(src)
    out = bytearray(src)
    body = offset + 9
    struct.pack_into("<Q", out, body + 16, 1 << 40)  # uncompressed_size
    (clen,) = struct.unpack_from("<I", out, body + 28)
    records_len_at = body + 32 + clen
    struct.pack_into("<Q", out, records_len_at, length * 4)  # records: past the record's end
    return bytes(out)


def _bag_records(data: bytes) -> Iterator[tuple[int, dict[str, bytes], int, int]]:
    """(offset, header fields, data offset, data length) of each record of an intact bag."""
    pos = len(BAG_MAGIC)
    while pos + 4 <= len(data):
        (hlen,) = struct.unpack_from("<I", data, pos)
        fields: dict[str, bytes] = {}
        at = pos + 4
        while at < pos + 4 + hlen:
            (flen,) = struct.unpack_from("<I", data, at)
            name, _, value = data[at + 4 : at + 4 + flen].partition(b"=")
            fields[name.decode()] = value
            at += 4 + flen
        (dlen,) = struct.unpack_from("<I", data, at)
        yield pos, fields, at + 4, dlen
        pos = at + 4 + dlen


def _first_bag_chunk(src: bytes) -> tuple[int, dict[str, bytes], int]:
    for offset, fields, data_at, _ in _bag_records(src):
        if fields.get("op") == b"\x05":
            return offset, fields, data_at
    raise ValueError("no chunk in the bag")


def _huge_bag_record(src: bytes) -> bytes:
    _, _, data_at = _first_bag_chunk(src)
    out = bytearray(src)
    struct.pack_into("<I", out, data_at - 4, 0xFFFFFFFF)
    return bytes(out)


def _lying_bag_chunk(src: bytes, size: int = 0xFFFFFF00) -> bytes:
    """``src`` with the ``size`` field of its first chunk's header set to ``size``."""
    offset, _, data_at = _first_bag_chunk(src)
    out = bytearray(src)
    at = offset + 4
    while at < data_at - 4:
        (flen,) = struct.unpack_from("<I", out, at)
        if bytes(out[at + 4 : at + 9]) == b"size=":
            struct.pack_into("<I", out, at + 9, size)
            return bytes(out)
        at += 4 + flen
    raise ValueError("the chunk has no size field")


def lying_bag_chunk(src: bytes, *, size: int = 0xFFFFFF00) -> bytes:
    """A bag's bytes with its first chunk's header claiming ``size`` uncompressed bytes."""
    return _lying_bag_chunk(src, size)


def unindexed_bag(src: bytes) -> bytes:
    """A bag's bytes with its header's ``index_pos`` zeroed: readers must walk its records."""
    at = src.index(b"index_pos=", 0, 4096) + len(b"index_pos=")
    return src[:at] + bytes(8) + src[at + 8 :]


def first_bag_chunk_size(src: bytes) -> tuple[int, int]:
    """(declared uncompressed size, position) of a bag's first chunk."""
    offset, fields, _ = _first_bag_chunk(src)
    return struct.unpack("<I", fields["size"])[0], offset


# --------------------------------------------------------------------------- message-level lies

Mutator = Callable[[str, Any, int, random.Random], Any]


def _rewrite_mcap(
    src: Path,
    dst: Path,
    mutate: Mutator | None,
    rng: random.Random,
    *,
    times: Callable[[int, int], int] | None = None,
) -> None:
    """Copy ``src`` to ``dst`` message by message; messages of the standard ROS 2 types go through
    ``mutate(typename, message, index, rng)`` (deserialised and serialised again with rosbags),
    and ``times(index, log_time)`` gives each message its new log time."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    with src.open("rb") as fin, dst.open("wb") as fout:
        writer = Writer(fout, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
        writer.start(profile="ros2", library="redrive hostile tests")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for index, (schema, channel, message) in enumerate(make_reader(fin).iter_messages()):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic,
                    channel.message_encoding,
                    schemas.get(schema.id, 0) if schema is not None else 0,
                    dict(channel.metadata),
                )
            data = message.data
            if mutate is not None and schema is not None and schema.name in store.types:
                msg = store.deserialize_cdr(data, schema.name)
                msg = mutate(schema.name, msg, index, rng)
                data = store.serialize_cdr(msg, schema.name)
            log_time = message.log_time if times is None else times(index, message.log_time)
            writer.add_message(channels[channel.id], log_time, data, log_time, message.sequence)
        writer.finish()


def _lying_cloud(name: str, msg: Any, index: int, rng: random.Random) -> Any:
    if name != "sensor_msgs/msg/PointCloud2":
        return msg
    way = index % 5
    if way == 0:
        msg.point_step = msg.point_step * 3 + 1
    elif way == 1:
        msg.row_step = msg.row_step * 7
    elif way == 2:
        msg.width, msg.height = msg.width * 1000, max(msg.height, 1) * 1000
    elif way == 3:
        msg.data = msg.data[: rng.randrange(1, max(2, len(msg.data) // 2))]
    else:
        msg.point_step, msg.row_step = 0, 0
    return msg


def _lying_image(name: str, msg: Any, index: int, rng: random.Random) -> Any:
    if name != "sensor_msgs/msg/Image":
        return msg
    way = index % 3
    if way == 0:
        msg.step = msg.step * 4
    elif way == 1:
        msg.height = msg.height * 50
    else:
        msg.step = 0
    return msg


def _nan_array(values: np.ndarray, rng: random.Random) -> np.ndarray:
    out = values.copy()
    specials = np.array([np.nan, np.inf, -np.inf], dtype=out.dtype)
    for i in range(out.size):
        out.flat[i] = specials[rng.randrange(3)]
    return out


def _nan_cloud_data(msg: Any, rng: random.Random) -> None:
    """Every float32 field of every point NaN or ±inf."""
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8).copy()
    step = msg.point_step
    n = len(data) // step if step else 0
    for field in msg.fields:
        if field.datatype != 7:  # FLOAT32
            continue
        view = data[: n * step].reshape(n, step)[:, field.offset : field.offset + 4]
        values = np.ascontiguousarray(view).view(np.float32).reshape(n)
        values[:] = np.where(
            np.arange(n) % 3 == 0, np.nan, np.where(np.arange(n) % 3 == 1, np.inf, -np.inf)
        )
        view[:] = values.view(np.uint8).reshape(n, 4)
    msg.data = data


def _nan_floats(obj: Any, rng: random.Random, depth: int = 0) -> None:
    """Set every float field of a rosbags message (recursively) to NaN or ±inf."""
    if depth > 8:
        return
    for field in getattr(obj, "__dataclass_fields__", {}):
        value = getattr(obj, field)
        if isinstance(value, float):
            setattr(obj, field, [np.nan, np.inf, -np.inf][rng.randrange(3)])
        elif isinstance(value, np.ndarray) and value.dtype.kind == "f":
            setattr(obj, field, _nan_array(value, rng))
        elif isinstance(value, list):
            for item in value:
                _nan_floats(item, rng, depth + 1)
        elif hasattr(value, "__dataclass_fields__"):
            _nan_floats(value, rng, depth + 1)


def _nan_everywhere(name: str, msg: Any, index: int, rng: random.Random) -> Any:
    if name == "sensor_msgs/msg/PointCloud2":
        _nan_cloud_data(msg, rng)
    elif name in (
        "nav_msgs/msg/Odometry",
        "sensor_msgs/msg/Imu",
        "tf2_msgs/msg/TFMessage",
        "sensor_msgs/msg/NavSatFix",
        "sensor_msgs/msg/LaserScan",
    ):
        _nan_floats(msg, rng)
    return msg


def _backwards(name: str, msg: Any, index: int, rng: random.Random) -> Any:
    header = getattr(msg, "header", None)
    if header is not None:
        header.stamp.sec = max(0, 1_800_000_000 - index)
    return msg


# --------------------------------------------------------------------------- message definitions


def _write_bag_with_msgdef(dst: Path, msgtype: str, msgdef: str) -> None:
    from rosbags.rosbag1 import Writer as BagWriter

    dst.unlink(missing_ok=True)
    writer = BagWriter(dst)
    with writer:
        conn = writer.add_connection("/hostile", msgtype, msgdef=msgdef, md5sum="0" * 32)
        for i in range(5):
            writer.write(conn, 1_700_000_000_000_000_000 + i * 10_000_000, b"\x00" * 64)


def _deep_msgdef(levels: int = 400) -> str:
    parts = ["deep/L1 next"]
    for i in range(1, levels):
        parts.append("=" * 80)
        parts.append(f"MSG: deep/L{i}")
        parts.append(f"int32 v\ndeep/L{i + 1} next")
    parts.append("=" * 80)
    parts.append(f"MSG: deep/L{levels}")
    parts.append("int32 v")
    return "\n".join(parts) + "\n"


_RECURSIVE_MSGDEF = (
    "int32 v\nrec/Node child\nrec/Node[] children\n"
    + "=" * 80
    + "\nMSG: rec/Node\nint32 v\nrec/Node child\nrec/Node[] children\n"
)


# --------------------------------------------------------------------------- the set


def make_hostile(base_mcap: Path, real_bag: Path, out_dir: Path, seed: int = 37) -> dict[str, Path]:
    """Write every hostile input of :data:`DESCRIPTIONS` to ``out_dir``; returns name → path.

    ``base_mcap``: a short, intact ``redrive synth`` log (chunked, zstd); ``real_bag``: an
    intact ROS 1 bag with chunks (a copy of a real log)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = random.Random(seed)
    mcap = base_mcap.read_bytes()
    bag = real_bag.read_bytes()
    paths: dict[str, Path] = {}

    def put(name: str, data: bytes) -> None:
        path = out_dir / name
        path.write_bytes(data)
        paths[name] = path

    put("truncated_a.mcap", _truncate(mcap, rng, 0.05, 0.5))
    put("truncated_b.mcap", _truncate(mcap, rng, 0.5, 0.99))
    put("byte_flips.mcap", _flip(mcap, rng))
    put("truncated.bag", _truncate(bag, rng, 0.1, 0.95))
    put("byte_flips.bag", _flip(bag, rng))
    put("huge_record_length.mcap", _huge_mcap_record(mcap))
    put("chunk_lies_size.mcap", _lying_mcap_chunk(mcap))
    put("huge_record_length.bag", _huge_bag_record(bag))
    put("chunk_lies_size.bag", _lying_bag_chunk(bag))

    for name, mutate in (
        ("lying_cloud.mcap", _lying_cloud),
        ("lying_image.mcap", _lying_image),
        ("nan_everywhere.mcap", _nan_everywhere),
    ):
        _rewrite_mcap(base_mcap, out_dir / name, mutate, random.Random(rng.random()))
        paths[name] = out_dir / name
    _rewrite_mcap(
        base_mcap,
        out_dir / "time_backwards.mcap",
        _backwards,
        random.Random(rng.random()),
        times=lambda i, _t: 1_800_000_000_000_000_000 - i * 1_000_000,
    )
    paths["time_backwards.mcap"] = out_dir / "time_backwards.mcap"
    _rewrite_mcap(
        base_mcap,
        out_dir / "duplicate_timestamps.mcap",
        None,
        rng,
        times=lambda _i, _t: 1_700_000_000_000_000_000,
    )
    paths["duplicate_timestamps.mcap"] = out_dir / "duplicate_timestamps.mcap"

    put("zero_bytes.mcap", b"")
    put("zero_bytes.bag", b"")
    put("magic_only.mcap", MCAP_MAGIC)
    directory = out_dir / "directory.mcap"
    directory.mkdir(exist_ok=True)
    (directory / "inside.txt").write_text("not a log\n")
    paths["directory.mcap"] = directory
    fifo = out_dir / "fifo.mcap"
    if not fifo.exists():
        os.mkfifo(fifo)
    paths["fifo.mcap"] = fifo

    _write_bag_with_msgdef(out_dir / "deep_msgdef.bag", "deep/msg/L0", _deep_msgdef())
    paths["deep_msgdef.bag"] = out_dir / "deep_msgdef.bag"
    _write_bag_with_msgdef(out_dir / "recursive_msgdef.bag", "rec/msg/Node", _RECURSIVE_MSGDEF)
    paths["recursive_msgdef.bag"] = out_dir / "recursive_msgdef.bag"
    assert set(paths) == set(DESCRIPTIONS)
    return paths


# --------------------------------------------------------------------------- non-finite points


def inject_non_finite(
    src: Path, dst: Path, *, topic: str, keep_every: int = 3
) -> list[tuple[int, int]]:
    """Copy the ROS 1 bag ``src`` to ``dst`` with the PointCloud2 messages of ``topic`` given
    NaN, +inf or -inf (in turn, in x, y or z) in every point but each ``keep_every``-th; returns
    (points, non-finite points) of each cloud written, in order."""
    from rosbags.rosbag1 import Reader as BagReader
    from rosbags.rosbag1 import Writer as BagWriter
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    dst.unlink(missing_ok=True)
    counts: list[tuple[int, int]] = []
    with BagReader(src) as reader, BagWriter(dst) as writer:
        conns = {
            c.id: writer.add_connection(c.topic, c.msgtype, typestore=store)
            for c in reader.connections
        }
        for conn, t, raw in reader.messages():
            data = raw
            if conn.topic == topic:
                msg = store.deserialize_ros1(raw, conn.msgtype)
                counts.append(_spoil_points(msg, keep_every))
                data = store.serialize_ros1(msg, conn.msgtype)
            writer.write(conns[conn.id], t, data)
    return counts


def _spoil_points(msg: Any, keep_every: int) -> tuple[int, int]:
    step = msg.point_step
    n = msg.width * msg.height
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8).copy()
    rows = data[: n * step].reshape(n, step)
    offsets = {f.name: f.offset for f in msg.fields if f.name in ("x", "y", "z")}
    spoiled = np.flatnonzero(np.arange(n) % keep_every != 0)
    specials = np.array([np.nan, np.inf, -np.inf], dtype=np.float32)
    for k, axis in enumerate(("x", "y", "z")):
        picked = spoiled[spoiled % 3 == k]
        at = offsets[axis]
        values = specials[picked % 3].view(np.uint8).reshape(-1, 4)
        rows[picked, at : at + 4] = values
    msg.data = data
    return n, len(spoiled)
