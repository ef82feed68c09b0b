"""Decompression bombs and extreme logs for the budget tests, written record by record with the
mcap library's records (the writer cannot write a chunk it did not fill itself)."""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

import zstandard
from isal.isal_zlib import crc32
from mcap.records import Channel, ChunkIndex, DataEnd, Footer, Header, Message, Schema, Statistics
from rosbags.typesys import Stores, get_typestore

from redrive.io.mcap.records import record_bytes, summary_section
from redrive.io.mcap.scan import MAGIC

T0_NS = 1_700_000_000_000_000_000
_PIECE = 16 << 20


def imu_messages(n: int) -> list[bytes]:
    """``n`` sensor_msgs/msg/Imu in CDR, angular velocity z = 0, 1, …"""
    store = get_typestore(Stores.ROS2_HUMBLE)
    imu = store.types["sensor_msgs/msg/Imu"]
    header = store.types["std_msgs/msg/Header"]
    stamp = store.types["builtin_interfaces/msg/Time"]
    quat = store.types["geometry_msgs/msg/Quaternion"]
    vec = store.types["geometry_msgs/msg/Vector3"]
    import numpy as np

    out = []
    for i in range(n):
        msg = imu(
            header=header(stamp=stamp(sec=1_700_000_000, nanosec=i * 10_000_000), frame_id="imu"),
            orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9),
            angular_velocity=vec(x=0.0, y=0.0, z=float(i)),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vec(x=0.0, y=0.0, z=9.81),
            linear_acceleration_covariance=np.zeros(9),
        )
        out.append(bytes(store.serialize_cdr(msg, imu.__msgtype__)))
    return out


def _pieces(records: list[bytes], zeros: int) -> Iterator[bytes]:
    yield from records
    done = 0
    block = bytes(_PIECE)
    while done < zeros:
        n = min(_PIECE, zeros - done)
        yield block[:n]
        done += n


def write_bomb_mcap(
    path: Path,
    *,
    zeros: int,
    messages: int = 10,
    declared: int | None = None,
    summary: bool = True,
) -> int:
    """An MCAP whose one zstd chunk holds ``messages`` Imu messages on ``/imu`` and then
    ``zeros`` zero bytes (a few KB compressed for gigabytes); the chunk declares its true size
    unless ``declared`` says otherwise (a chunk that lies). Returns the file's size."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    text, _ = store.generate_msgdef("sensor_msgs/msg/Imu", ros_version=2)
    schema = Schema(id=1, name="sensor_msgs/msg/Imu", encoding="ros2msg", data=text.encode())
    channel = Channel(id=1, schema_id=1, topic="/imu", message_encoding="cdr", metadata={})
    records, offsets, at = [], [], 0
    for i, data in enumerate(imu_messages(messages)):
        t = T0_NS + i * 10_000_000
        record = record_bytes(
            Message(channel_id=1, sequence=i, log_time=t, publish_time=t, data=data)
        )
        records.append(record)
        offsets += [t, at]
        at += len(record)
    size = at + zeros
    crc = 0
    compressor = zstandard.ZstdCompressor(level=1).compressobj(size=size)
    body = bytearray()
    for piece in _pieces(records, zeros):
        crc = crc32(piece, crc)
        body += compressor.compress(piece)
    body += compressor.flush()
    usize = size if declared is None else declared
    name = b"zstd"
    start, end = T0_NS, T0_NS + (messages - 1) * 10_000_000
    chunk = (
        struct.pack("<BQ", 0x06, 8 + 8 + 8 + 4 + 4 + len(name) + 8 + len(body))
        + struct.pack("<QQQI", start, end, usize, crc)
        + struct.pack("<I", len(name))
        + name
        + struct.pack("<Q", len(body))
        + bytes(body)
    )
    index = struct.pack("<BQHI", 0x07, 6 + 8 * len(offsets), 1, 8 * len(offsets))
    index += struct.pack(f"<{len(offsets)}Q", *offsets)
    head = (
        MAGIC
        + record_bytes(Header(profile="ros2", library="redrive tests"))
        + record_bytes(schema)
        + record_bytes(channel)
    )
    chunk_start = len(head)
    data = head + chunk + index + record_bytes(DataEnd(data_section_crc=0))
    if summary:
        data += summary_section(
            len(data),
            schemas=[schema],
            channels=[channel],
            statistics=Statistics(
                message_count=messages,
                schema_count=1,
                channel_count=1,
                attachment_count=0,
                metadata_count=0,
                chunk_count=1,
                message_start_time=start,
                message_end_time=end,
                channel_message_counts={1: messages},
            ),
            chunk_indexes=[
                ChunkIndex(
                    message_start_time=start,
                    message_end_time=end,
                    chunk_start_offset=chunk_start,
                    chunk_length=len(chunk),
                    message_index_offsets={1: chunk_start + len(chunk)},
                    message_index_length=len(index),
                    compression="zstd",
                    compressed_size=len(body),
                    uncompressed_size=usize,
                )
            ],
        )
    else:
        data += record_bytes(Footer(summary_start=0, summary_offset_start=0, summary_crc=0))
        data += MAGIC
    path.write_bytes(data)
    return len(data)
