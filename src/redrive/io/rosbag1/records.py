"""The record layer of a ROS 1 bag (format 2.0): record headers, data spans, op codes, chunk
decompression — what :class:`redrive.io.rosbag1.reader.Ros1BagReader` parses by hand to read damaged
bags and to find messages without building a header dict per message."""

from __future__ import annotations

import bz2
import mmap
import struct
from collections.abc import Mapping

import lz4.frame

__all__ = [
    "DECOMPRESSORS",
    "MAGIC",
    "OP_CHUNK",
    "OP_CONNECTION",
    "OP_MSGDATA",
    "TIME",
    "U32",
    "Buf",
    "DamageError",
    "data_span",
    "declared_size",
    "decode_time",
    "decompress_prefix",
    "op_of",
    "parse_header",
    "record_op",
    "size_lie",
]

OP_MSGDATA = 0x02
OP_CHUNK = 0x05
OP_CONNECTION = 0x07
MAGIC = b"#ROSBAG V2.0\n"
U32 = struct.Struct("<I")
TIME = struct.Struct("<II")

#: the chunk compressions of ROS 1 bags (chunks are decompressed against the budget of
#: :func:`redrive.io.limits.decompress_bounded`).
DECOMPRESSORS = ("none", "bz2", "lz4")


#: what the record functions read: file bytes, a view of them, or a map of the file.
Buf = bytes | memoryview | mmap.mmap


def decompress_prefix(compression: str, data: bytes, limit: int) -> bytes:
    """Decompress as much of a cut-off chunk as its bytes allow, at most ``limit`` bytes."""
    if compression == "none":
        return data
    if compression == "bz2":
        return bz2.BZ2Decompressor().decompress(data, max_length=limit)
    if compression == "lz4":
        out: bytes = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit)
        return out
    raise KeyError(compression)


class DamageError(Exception):
    """Internal: the bytes at ``offset`` are not a valid record."""

    def __init__(self, offset: int, reason: str) -> None:
        super().__init__(f"byte {offset}: {reason}")
        self.offset = offset
        self.reason = reason


def parse_header(buf: Buf, pos: int, end: int) -> tuple[dict[str, bytes], int]:
    """Parse one record header at ``pos``; returns its fields and the position after it."""
    if pos + 4 > end:
        raise DamageError(pos, "record header length is cut off")
    (size,) = U32.unpack_from(buf, pos)
    pos += 4
    stop = pos + size
    if stop > end:
        raise DamageError(pos - 4, f"record header of {size} bytes runs past the end")
    fields: dict[str, bytes] = {}
    while pos < stop:
        if pos + 4 > stop:
            raise DamageError(pos, "header field length is cut off")
        (flen,) = U32.unpack_from(buf, pos)
        pos += 4
        field = bytes(buf[pos : pos + flen])
        pos += flen
        key, sep, value = field.partition(b"=")
        if not sep or pos > stop:
            raise DamageError(pos, "header field is malformed")
        fields[key.decode("ascii", "replace")] = value
    return fields, stop


def record_op(buf: Buf, pos: int, end: int) -> tuple[int, int]:
    """The ``op`` of the record whose header starts at ``pos`` (-1 when it has none), and the
    position after the header.

    :func:`parse_header` + :func:`op_of` without building the field dict — the indexed reader runs
    this for every message — with the same checks and errors: a header or field that is cut off
    or has no ``=`` is damage; the last ``op`` field counts, and it must hold one byte.
    """
    if pos + 4 > end:
        raise DamageError(pos, "record header length is cut off")
    (size,) = U32.unpack_from(buf, pos)
    pos += 4
    stop = pos + size
    if stop > end:
        raise DamageError(pos - 4, f"record header of {size} bytes runs past the end")
    head = bytes(buf[pos:stop])
    op = -1
    at = 0
    while at < size:
        if at + 4 > size:
            raise DamageError(pos + at, "header field length is cut off")
        (flen,) = U32.unpack_from(head, at)
        at += 4
        field_end = at + flen
        sep = head.find(b"=", at, field_end)
        if sep < 0 or field_end > size:
            raise DamageError(pos + field_end, "header field is malformed")
        if sep == at + 2 and head.startswith(b"op", at):
            op = head[sep + 1] if field_end == sep + 2 else -1
        at = field_end
    return op, stop


def data_span(buf: Buf, pos: int, end: int) -> tuple[int, int]:
    """(start, stop) of the data block that follows a header at ``pos``."""
    if pos + 4 > end:
        raise DamageError(pos, "record data length is cut off")
    (size,) = U32.unpack_from(buf, pos)
    if pos + 4 + size > end:
        raise DamageError(pos, f"record data of {size} bytes runs past the end")
    return pos + 4, pos + 4 + size


def op_of(fields: Mapping[str, bytes], offset: int) -> int:
    value = fields.get("op")
    if value is None or len(value) != 1:
        raise DamageError(offset, "record has no op field")
    return value[0]


def decode_time(value: bytes) -> int:
    """A bag time field (uint32 secs, uint32 nsecs) as int ns."""
    secs, nsecs = TIME.unpack(value)
    return int(secs) * 1_000_000_000 + int(nsecs)


def size_lie(compression: str, declared: int | None, actual: int) -> str | None:
    """Why a chunk whose header's ``size`` field says ``declared`` bytes uncompressed, and whose
    data hold (or decompress to) ``actual`` bytes, is damaged; None when they agree.

    rosbag writes the size of the chunk's uncompressed records there (C++ rosbag allocates that
    much before it decompresses); a field that is missing or says another size is damage even
    when the data read whole."""
    if declared is None:
        return "has no size field in its header; its messages were read from its data"
    if declared == actual:
        return None
    data = "its data are" if compression == "none" else "its data decompress to"
    return (
        f"header says it holds {declared} bytes uncompressed, but {data} {actual} bytes: the "
        "size field is damaged; its messages were read from the data"
    )


def declared_size(fields: Mapping[str, bytes]) -> int | None:
    """The ``size`` field of a chunk record's header (None when missing or not 4 bytes)."""
    value = fields.get("size", b"")
    return U32.unpack(value)[0] if len(value) == 4 else None
