"""Small logs for the damage tests, written with the real writers, and ways to damage them."""

from __future__ import annotations

import struct
from pathlib import Path

from mcap.writer import CompressionType, Writer

T0_NS = 1_700_000_000_000_000_000
COMPRESSIONS = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}


def cdr_string(text: str) -> bytes:
    """A std_msgs/msg/String in CDR (little endian)."""
    raw = text.encode() + b"\0"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(raw)) + raw


def write_string_mcap(
    path: Path,
    *,
    messages: int = 300,
    compression: str = "zstd",
    chunked: bool = True,
    chunk_size: int = 2048,
) -> list[tuple[str, int, bytes]]:
    """An MCAP of ``messages`` std_msgs/String on two topics (a few per chunk); returns
    (topic, log time, bytes) of each message in file order."""
    out: list[tuple[str, int, bytes]] = []
    with path.open("wb") as fh:
        writer = Writer(
            fh,
            chunk_size=chunk_size,
            compression=COMPRESSIONS[compression],
            use_chunking=chunked,
        )
        writer.start(profile="ros2", library="redrive tests")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        topics = {t: writer.register_channel(t, "cdr", schema) for t in ("/a", "/b")}
        for i in range(messages):
            topic = "/a" if i % 3 else "/b"
            data = cdr_string(f"message {i} " + "x" * (i % 50))
            t = T0_NS + i * 10_000_000
            writer.add_message(topics[topic], t, data, t, sequence=i)
            out.append((topic, t, data))
        writer.finish()
    return out


def write_string_bag(path: Path, *, messages: int = 200, compression: str = "lz4") -> None:
    """A ROS 1 bag of ``messages`` std_msgs/String on two topics in many small chunks, written
    with rosbags (``compression``: ``bz2``, ``lz4`` or ``none``)."""
    from rosbags.rosbag1 import Writer as BagWriter
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    string = store.types["std_msgs/msg/String"]
    writer = BagWriter(path)
    writer.chunk_threshold = 1024
    if compression != "none":
        writer.set_compression(BagWriter.CompressionFormat[compression.upper()])
    with writer:
        conns = {
            t: writer.add_connection(t, "std_msgs/msg/String", typestore=store)
            for t in ("/a", "/b")
        }
        for i in range(messages):
            data = store.serialize_ros1(
                string(data=f"message {i} " + "x" * (i % 50)), string.__msgtype__
            )
            writer.write(conns["/a" if i % 3 else "/b"], T0_NS + i * 10_000_000, data)
