"""MCAP records read by hand, so that a damaged file yields everything that is still intact.

The ``mcap`` library stops at the first bad byte (``struct.error``, ``ZstdError``, ``EndOfFile``)
and cannot go on.  :class:`McapScan` walks the records of the file from the start instead
(what ``mcap recover`` does): a chunk that does not decompress, fails its CRC or holds a
malformed record is skipped — its byte range and, from the message index records that follow
it, the number of messages it held are reported as a :class:`~redrive.io.damage.LogDamage` —
and reading resumes at the next record that parses (a *resync*: the next chunk of a chunked
file, the next plausible record of an unchunked one).  :func:`read_chunk` serves the indexed
reader in :mod:`redrive.io.mcap.reader` with the same checks (damaged chunks' remains:
:mod:`redrive.io.mcap.salvage`).

The file is read through a read-only memory map: an uncompressed chunk's messages are views of it.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field

import lz4.frame
import zstandard
from isal.isal_zlib import crc32  # zlib's CRC-32, several times faster (as records.py)

from redrive.io.limits import max_chunk_bytes, over_budget, stream_pieces

__all__ = [
    "MAGIC",
    "ChunkHead",
    "McapAttachment",
    "McapChannel",
    "McapMetadata",
    "McapSchema",
    "Message",
    "RecordError",
    "ScanEvent",
    "chunk_head",
    "message_index_count",
    "read_chunk",
]

MAGIC = b"\x89MCAP0\r\n"

OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_MESSAGE_INDEX = 0x07
OP_ATTACHMENT = 0x09
OP_METADATA = 0x0C
OP_DATA_END = 0x0F

_OPLEN = struct.Struct("<BQ")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_MESSAGE = struct.Struct("<HIQQ")
_CHUNK = struct.Struct("<QQQI")
_CHANNEL = struct.Struct("<HH")
_COMPRESSIONS = ("", "zstd", "lz4")
_KINDS = {
    OP_HEADER: "a header",
    OP_SCHEMA: "a schema",
    OP_CHANNEL: "a channel",
    OP_MESSAGE: "a message",
    OP_CHUNK: "a chunk",
    OP_MESSAGE_INDEX: "a message index",
    OP_METADATA: "a metadata",
    OP_ATTACHMENT: "an attachment",
}
_ANY_OP = re.compile(rb"[\x01-\x0f]")
_CHUNK_OP = re.compile(rb"[\x06\x0f]")
_DECOMPRESS_ERRORS = (zstandard.ZstdError, RuntimeError, ValueError, OSError, EOFError, MemoryError)


class RecordError(Exception):
    """Internal: the bytes at a position are not the record they should be (never escapes a
    reader: readers turn it into a LogDamage or a LogDamagedError)."""


@dataclass(frozen=True, slots=True)
class McapSchema:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True, slots=True)
class McapChannel:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class McapMetadata:
    name: str
    metadata: Mapping[str, str]


@dataclass(frozen=True, slots=True)
class McapAttachment:
    log_time: int
    create_time: int
    name: str
    media_type: str
    data: bytes


#: A message is (channel id, sequence, log time ns, publish time ns, data).
Message = tuple[int, int, int, int, memoryview]
#: What :meth:`McapScan.events` yields: ("message", Message), ("schema", McapSchema),
#: ("channel", McapChannel), ("metadata", McapMetadata), ("attachment", McapAttachment) or
#: ("damage", LogDamage).
ScanEvent = tuple[str, object]


def _string(buf: memoryview, pos: int, end: int) -> tuple[str, int]:
    if pos + 4 > end:
        raise RecordError("a string length runs past the record")
    (n,) = _U32.unpack_from(buf, pos)
    pos += 4
    if pos + n > end:
        raise RecordError("a string runs past the record")
    try:
        return str(buf[pos : pos + n], "utf-8"), pos + n
    except UnicodeDecodeError as err:
        raise RecordError("a string is not UTF-8") from err


def _string_map(buf: memoryview, pos: int, end: int) -> tuple[dict[str, str], int]:
    if pos + 4 > end:
        raise RecordError("a map length runs past the record")
    (n,) = _U32.unpack_from(buf, pos)
    pos += 4
    stop = pos + n
    if stop > end:
        raise RecordError("a map runs past the record")
    out: dict[str, str] = {}
    while pos < stop:
        key, pos = _string(buf, pos, stop)
        out[key], pos = _string(buf, pos, stop)
    return out, stop


def _schema(buf: memoryview, pos: int, end: int) -> McapSchema:
    if pos + 2 > end:
        raise RecordError("a schema record is too short")
    (sid,) = _U16.unpack_from(buf, pos)
    name, pos = _string(buf, pos + 2, end)
    encoding, pos = _string(buf, pos, end)
    if pos + 4 > end:
        raise RecordError("a schema's data length runs past the record")
    (n,) = _U32.unpack_from(buf, pos)
    if pos + 4 + n > end:
        raise RecordError("a schema's data runs past the record")
    return McapSchema(sid, name, encoding, bytes(buf[pos + 4 : pos + 4 + n]))


def _channel(buf: memoryview, pos: int, end: int) -> McapChannel:
    if pos + 4 > end:
        raise RecordError("a channel record is too short")
    cid, sid = _CHANNEL.unpack_from(buf, pos)
    topic, pos = _string(buf, pos + 4, end)
    encoding, pos = _string(buf, pos, end)
    meta, pos = _string_map(buf, pos, end)
    return McapChannel(cid, sid, topic, encoding, meta)


@dataclass(frozen=True, slots=True)
class ChunkHead:
    """A chunk record's fields; ``data_start``/``data_stop`` bound its compressed records."""

    pos: int
    stop: int
    start_time: int
    end_time: int
    uncompressed_size: int
    crc: int
    compression: str
    data_start: int
    data_stop: int


def chunk_head(buf: memoryview, pos: int, size: int) -> ChunkHead:
    """The chunk record at ``pos`` (its opcode byte), checked for consistency.

    Raises:
        RecordError: it is not a whole, well-formed chunk record.
    """
    if pos + 9 + 40 > size:
        raise RecordError("the file ends inside a chunk record")
    op, length = _OPLEN.unpack_from(buf, pos)
    if op != OP_CHUNK:
        raise RecordError(f"expected a chunk record, found opcode {op:#04x}")
    stop = pos + 9 + length
    if stop > size:
        raise RecordError(f"a chunk record of {length} bytes runs past the end of the file")
    start_time, end_time, usize, crc = _CHUNK.unpack_from(buf, pos + 9)
    compression, at = _string(buf, pos + 9 + _CHUNK.size, stop)
    if compression not in _COMPRESSIONS:
        raise RecordError(f"a chunk record with compression {compression!r} of {usize} bytes")
    if at + 8 > stop:
        raise RecordError("a chunk's records length runs past the record")
    (n,) = _U64.unpack_from(buf, at)
    if at + 8 + n != stop:
        raise RecordError("a chunk's records length does not match the record length")
    return ChunkHead(pos, stop, start_time, end_time, usize, crc, compression, at + 8, stop)


def read_chunk(
    buf: memoryview, head: ChunkHead, budget: int | None = None
) -> tuple[list[Message], list[object], str | None]:
    """The messages and schema/channel records of a chunk, and why it stopped early (None when
    the whole chunk was read).

    A chunk that does not decompress or fails its CRC yields nothing (the reason says why); one
    whose CRC is not recorded and that holds a malformed record yields the records before it.
    Nothing is decompressed past the size the chunk declares; a chunk declaring more than
    ``budget`` bytes (:func:`~redrive.io.limits.max_chunk_bytes`) yields the whole records at
    its start, streamed up to the budget (:func:`chunk_prefix`), and says so.
    """
    raw = buf[head.data_start : head.data_stop]
    usize = head.uncompressed_size
    limit = max_chunk_bytes(budget)
    if usize > limit:
        messages, others, why = chunk_prefix(raw, head.compression, limit)
        return (
            messages,
            others,
            f"{over_budget(usize, limit)}: the {len(messages)} messages at its start were read "
            f"(its CRC unchecked){f', up to {why}' if why else ''}",
        )
    try:
        if head.compression == "zstd":
            declared = zstandard.frame_content_size(raw)
            if declared not in (-1, usize):  # decompress() would allocate what the frame says
                messages, others, _ = chunk_prefix(raw, "zstd", usize)
                return (
                    messages,
                    others,
                    f"the zstd frame declares {declared} bytes, the chunk {usize}: the "
                    f"{len(messages)} whole messages in its first {usize} bytes were read",
                )
            data: bytes | memoryview = zstandard.ZstdDecompressor().decompress(
                raw, max_output_size=max(usize, 1)
            )
        elif head.compression == "lz4":
            data = lz4.frame.LZ4FrameDecompressor().decompress(raw, max_length=usize + 1)
        else:
            data = raw
    except _DECOMPRESS_ERRORS as err:
        from redrive.io.mcap.salvage import decoded_prefix  # the failure path only

        return decoded_prefix(raw, head, err)
    if len(data) != head.uncompressed_size:
        why = f"it decompresses to {len(data)} bytes, not the {head.uncompressed_size} it records"
        if head.compression:  # damaged compressed bytes: keep the whole messages decoded first
            from redrive.io.mcap.salvage import decoded_prefix  # the failure path only

            return decoded_prefix(raw, head, ValueError(why))
        return [], [], f"the chunk: {why}"
    if head.crc != 0 and crc32(data) != head.crc:
        return [], [], "the chunk fails its CRC check (its bytes changed)"
    messages, others, pos, why = _chunk_records(memoryview(data))
    if why is not None:
        return messages, others, f"a record at offset {pos} of the chunk is malformed ({why})"
    return messages, others, None


def _chunk_records(
    view: memoryview,
) -> tuple[list[Message], list[object], int, str | None]:
    """The records of a chunk's decompressed bytes: messages, schemas/channels, the offset
    reached, and why it stopped early (None when every byte was read)."""
    messages: list[Message] = []
    others: list[object] = []
    pos, end = 0, len(view)
    unpack_head, unpack_msg = _OPLEN.unpack_from, _MESSAGE.unpack_from
    try:
        while pos < end:
            if pos + 9 > end:
                raise RecordError("a record header is cut off")
            op, length = unpack_head(view, pos)
            body, stop = pos + 9, pos + 9 + length
            if stop > end:
                raise RecordError(f"a record of {length} bytes runs past the chunk")
            if op == OP_MESSAGE:
                if length < _MESSAGE.size:
                    raise RecordError("a message record is too short")
                cid, seq, log_time, pub_time = unpack_msg(view, body)
                messages.append((cid, seq, log_time, pub_time, view[body + _MESSAGE.size : stop]))
            elif op == OP_SCHEMA:
                others.append(_schema(view, body, stop))
            elif op == OP_CHANNEL:
                others.append(_channel(view, body, stop))
            elif op == 0:  # no record has opcode 0: zeros (a bomb's padding, a zeroed page)
                raise RecordError("opcode 0x00 is no MCAP record (zeroed bytes)")
            pos = stop
    except RecordError as err:
        return messages, others, pos, str(err)
    return messages, others, pos, None


def chunk_prefix(
    raw: bytes | memoryview, compression: str, limit: int
) -> tuple[list[Message], list[object], str | None]:
    """The whole records at the start of a chunk's compressed bytes ``raw``, decompressed as a
    stream of at most ``limit`` bytes (a chunk over the budget, or cut off by the end of the
    file), and where they stopped (None: at the limit or the end of the bytes).

    Memory holds the records read and one piece of the stream; the first malformed record
    (zeroed bytes: opcode 0) ends the read at once.
    """
    messages: list[Message] = []
    others: list[object] = []
    rest = b""
    try:
        for piece in stream_pieces(compression, raw, limit):
            data = rest + piece
            got, more, pos, why = _chunk_records(memoryview(data))
            messages += got
            others += more
            if why is not None and _whole_at(data, pos):
                return messages, others, f"a malformed record ({why})"
            rest = data[pos:]
    except _DECOMPRESS_ERRORS as err:
        return messages, others, f"bytes that do not decompress ({err})"
    except KeyError:
        return messages, others, f"an unknown compression {compression!r}"
    return messages, others, None


def _whole_at(data: bytes, pos: int) -> bool:
    """Whether the record at ``pos`` of ``data`` is all there (so a fault in it is damage, not
    a record cut by the end of a piece)."""
    if pos + 9 > len(data):
        return False
    return bool(pos + 9 + _OPLEN.unpack_from(data, pos)[1] <= len(data))


def salvage_cut_chunk(
    buf: memoryview, pos: int, budget: int | None = None
) -> tuple[list[Message], list[object]]:
    """The whole records at the start of a chunk record at ``pos`` that the end of the file cuts
    off: what a recorder killed in the middle of writing a chunk left of it.

    The chunk's bytes up to the end of the file are decompressed as a stream (zstd and lz4
    frames give what their complete blocks hold; an uncompressed chunk is read as it is), and the
    records that are whole in them are read; the cut record is dropped. The chunk's CRC covers
    the whole chunk, so it cannot be checked: the records' own framing is what is trusted.
    Nothing when the chunk's header itself is cut, or its compression is unknown.
    """
    size = len(buf)
    head_end = pos + 9 + _CHUNK.size
    if head_end + 4 > size:
        return [], []
    usize = _CHUNK.unpack_from(buf, pos + 9)[2]
    try:
        compression, at = _string(buf, head_end, size)
    except RecordError:
        return [], []
    if compression not in _COMPRESSIONS or at + 8 > size:
        return [], []
    messages, others, _why = chunk_prefix(
        buf[at + 8 : size], compression, min(usize, max_chunk_bytes(budget))
    )
    return messages, others


def message_index_count(buf: memoryview, pos: int, size: int) -> int | None:
    """How many messages the message index record at ``pos`` lists (None if it is not one)."""
    if pos + 9 + 6 > size:
        return None
    op, length = _OPLEN.unpack_from(buf, pos)
    if op != OP_MESSAGE_INDEX or pos + 9 + length > size:
        return None
    (n,) = _U32.unpack_from(buf, pos + 9 + 2)
    if n % 16 or 6 + n != length:
        return None
    return int(n) // 16


def _attachment(buf: memoryview, pos: int, end: int) -> McapAttachment:
    if pos + 16 > end:
        raise RecordError("an attachment record is too short")
    log_time, create_time = struct.unpack_from("<QQ", buf, pos)
    name, at = _string(buf, pos + 16, end)
    media_type, at = _string(buf, at, end)
    if at + 8 > end:
        raise RecordError("an attachment's data length runs past the record")
    (n,) = _U64.unpack_from(buf, at)
    if at + 8 + n + 4 > end:
        raise RecordError("an attachment's data runs past the record")
    return McapAttachment(log_time, create_time, name, media_type, bytes(buf[at + 8 : at + 8 + n]))
