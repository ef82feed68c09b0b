"""What a damaged MCAP chunk still holds: the failure paths of :mod:`redrive.io.mcap.scan`.

- :func:`decoded_prefix`: a chunk that does not decompress is fed to a streaming decoder, and
  the whole records of what it returned before it failed are read.
- :func:`repaired_chunk_head`: a chunk whose record length (or records length) is damaged, but
  which is intact by the other length and its CRC.

Nothing here runs while a log is intact.
"""

from __future__ import annotations

from typing import Any

import lz4.frame
import zstandard

from redrive.io.limits import max_chunk_bytes
from redrive.io.mcap.scan import (
    _CHUNK,
    _COMPRESSIONS,
    _U64,
    OP_CHUNK,
    ChunkHead,
    Message,
    RecordError,
    _chunk_records,
    _string,
    read_chunk,
)

__all__ = ["decoded_prefix", "repaired_chunk_head"]

#: Compressed bytes fed to a streaming decoder at a time when a chunk failed to decompress: the
#: output of the calls before the one that fails is kept.
_STREAM_STEP = 1024


def decoded_prefix(
    raw: memoryview, head: ChunkHead, err: BaseException
) -> tuple[list[Message], list[object], str]:
    """The whole records at the start of a chunk that does not decompress: its bytes are fed to a
    streaming decoder a little at a time, and what it returned before it failed is read (a zstd /
    lz4 block is decoded whole or not at all, so that output comes from the blocks before the
    damaged one). The chunk's CRC covers all of it, so the records' own framing is what is
    trusted. Only runs once the one-shot decompression failed."""
    decoder: Any = (
        zstandard.ZstdDecompressor().decompressobj()
        if head.compression == "zstd"
        else lz4.frame.LZ4FrameDecompressor()
    )
    out = bytearray()
    for at in range(0, len(raw), _STREAM_STEP):
        try:
            out += decoder.decompress(bytes(raw[at : at + _STREAM_STEP]))
        except (zstandard.ZstdError, RuntimeError, ValueError, OSError, EOFError, MemoryError):
            break
        if len(out) >= head.uncompressed_size or getattr(decoder, "eof", False):
            break
    messages, others, _, _ = _chunk_records(memoryview(bytes(out[: head.uncompressed_size])))
    why = f"the {head.compression} chunk does not decompress ({err})"
    if messages or others:
        why += (
            f"; {len(messages)} whole messages of its first {len(out)} decompressed bytes were "
            "read, the rest of it is lost"
        )
    return messages, others, why


def repaired_chunk_head(buf: memoryview, pos: int, size: int) -> ChunkHead | None:
    """The chunk at ``pos`` whose record length (or records length) is damaged, when the other
    length gives a chunk that decompresses to its recorded size and passes its CRC (so it is
    intact but for that length); None otherwise. Only runs once the chunk's framing failed."""
    head_end = pos + 9 + _CHUNK.size
    if head_end + 4 > size or buf[pos] != OP_CHUNK:
        return None
    start_time, end_time, usize, crc = _CHUNK.unpack_from(buf, pos + 9)
    try:
        compression, at = _string(buf, head_end, size)
    except RecordError:
        return None
    if (
        compression not in _COMPRESSIONS
        or usize > max_chunk_bytes(None)
        or at + 8 > size
        or crc == 0
    ):
        return None
    (records,) = _U64.unpack_from(buf, at)
    (length,) = _U64.unpack_from(buf, pos + 1)
    for stop in (at + 8 + records, pos + 9 + length):
        if not at + 8 <= stop <= size:
            continue
        head = ChunkHead(pos, stop, start_time, end_time, usize, crc, compression, at + 8, stop)
        if read_chunk(buf, head)[2] is None:
            return head
    return None
