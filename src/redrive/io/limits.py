"""The read budget: how many bytes one chunk of a log may expand to in memory.

A chunk's header records its uncompressed size, and a compressed chunk of a few kilobytes can
declare (or, lying, hold) gigabytes: a *decompression bomb*. Readers decompress a chunk only up to
this budget; a chunk that declares more is read as a stream for the whole records at its start,
and the rest is reported as damage (:mod:`redrive.io.damage`) like any other, the rest of the log
read. One record (a message) lies inside one chunk, so the budget bounds records too.

The default, :data:`DEFAULT_MAX_CHUNK_BYTES` (256 MiB), is far above what recorders write (the
MCAP writers' chunks are 1–4 MiB, rosbag's 768 KiB; a message bigger than the chunk size gets a
chunk of its own, so a 100 MB point cloud is a 100 MB chunk). Raise it with the reader keyword
``max_chunk_bytes`` or the environment variable :data:`MAX_CHUNK_ENV`
(``REDRIVE_MAX_CHUNK_BYTES=1G redrive info big.mcap``); docs/damaged_logs.md, "Limits".
"""

from __future__ import annotations

import bz2
import os
from collections.abc import Iterator

import lz4.frame
import zstandard

from redrive.errors import LogError

__all__ = [
    "DEFAULT_MAX_CHUNK_BYTES",
    "MAX_CHUNK_ENV",
    "decompress_bounded",
    "max_chunk_bytes",
    "over_budget",
    "stream_pieces",
]

DEFAULT_MAX_CHUNK_BYTES = 256 << 20
MAX_CHUNK_ENV = "REDRIVE_MAX_CHUNK_BYTES"
_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
_PIECE = 4 << 20


def max_chunk_bytes(value: int | None = None) -> int:
    """The chunk budget: ``value`` when given, else :data:`MAX_CHUNK_ENV` (bytes, or with a
    suffix K, M, G or T: ``512M``), else :data:`DEFAULT_MAX_CHUNK_BYTES`.

    Raises:
        LogError: the variable is not a positive size.
    """
    if value is not None:
        return value
    text = os.environ.get(MAX_CHUNK_ENV, "").strip()
    if not text:
        return DEFAULT_MAX_CHUNK_BYTES
    number, unit = text.upper().removesuffix("B").removesuffix("I"), ""
    if number[-1:] in _UNITS:
        number, unit = number[:-1], number[-1]
    try:
        size = int(float(number) * _UNITS[unit])
    except ValueError:
        size = 0
    if size <= 0:
        msg = f"{MAX_CHUNK_ENV}={text!r} is not a size in bytes (e.g. 268435456, 512M or 2G)"
        raise LogError(msg)
    return size


def over_budget(declared: int, budget: int) -> str:
    """The words for a chunk that declares ``declared`` bytes uncompressed, over ``budget``."""
    return (
        f"the chunk declares {declared} bytes uncompressed, over the budget of {budget} "
        f"(raise it with {MAX_CHUNK_ENV} or max_chunk_bytes=)"
    )


def stream_pieces(compression: str, raw: bytes | memoryview, limit: int) -> Iterator[bytes]:
    """The decompressed bytes of ``raw`` in pieces of a few MiB, at most ``limit`` of them in
    all (a stream: memory holds one piece at a time, and a cut-off input yields what its whole
    blocks hold). ``compression``: ``zstd``, ``lz4``, ``bz2``, or ``""``/``none``.

    Raises:
        KeyError: an unknown compression.
        zstandard.ZstdError, RuntimeError, OSError, ValueError, EOFError: the bytes do not
            decompress (after the pieces before the fault).
    """
    done = 0
    if compression in ("", "none"):
        view = memoryview(raw)[:limit]
        for at in range(0, len(view), _PIECE):
            yield bytes(view[at : at + _PIECE])
        return
    if compression == "zstd":
        reader = zstandard.ZstdDecompressor().stream_reader(bytes(raw), read_across_frames=True)
        while done < limit and (piece := reader.read(min(_PIECE, limit - done))):
            done += len(piece)
            yield piece
        return
    decompressor: lz4.frame.LZ4FrameDecompressor | bz2.BZ2Decompressor
    if compression == "lz4":
        decompressor = lz4.frame.LZ4FrameDecompressor()
    elif compression == "bz2":
        decompressor = bz2.BZ2Decompressor()
    else:
        raise KeyError(compression)
    data = bytes(raw)
    while done < limit:
        if decompressor.eof:
            return
        piece = decompressor.decompress(data, max_length=min(_PIECE, limit - done))
        data = b""
        if not piece:
            return
        done += len(piece)
        yield piece


def decompress_bounded(compression: str, data: bytes, limit: int) -> bytes:
    """The whole of ``data`` decompressed (a ROS 1 bag's chunk: ``bz2``, ``lz4`` or ``none``),
    never more than ``limit`` bytes of it in memory.

    Raises:
        KeyError: an unknown compression.
        ValueError: it expands past ``limit`` (:func:`over_budget` says so).
        EOFError: the data end before the end of the compressed stream.
        OSError, RuntimeError: the bytes do not decompress.
    """
    if compression == "none":
        return data
    decompressor: lz4.frame.LZ4FrameDecompressor | bz2.BZ2Decompressor
    if compression == "bz2":
        decompressor = bz2.BZ2Decompressor()
    elif compression == "lz4":
        decompressor = lz4.frame.LZ4FrameDecompressor()
    else:
        raise KeyError(compression)
    out: bytes = decompressor.decompress(data, max_length=limit + 1)
    if len(out) > limit:
        msg = f"it expands past {limit} bytes, the budget (raise it with {MAX_CHUNK_ENV})"
        raise ValueError(msg)
    if not decompressor.eof:
        msg = "the compressed data end before the end of their stream"
        raise EOFError(msg)
    return out
