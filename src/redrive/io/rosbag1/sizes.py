"""The ``size`` field of a ROS 1 bag's chunk headers: what each chunk says it holds uncompressed.

rosbag writes there the size of the chunk's uncompressed records, and C++ rosbag allocates that
much before it decompresses, so a chunk header claiming 0xFFFFFF00 bytes is damage even when the
chunk's data read whole (issue 37).  rosbags does not keep the field; :func:`chunk_sizes` reads
it for every chunk of an indexed bag at open (the sequential walk reads it from the headers it
parses, :class:`~redrive.io.rosbag1.scan.BagWalk`).
"""

from __future__ import annotations

import os
from typing import Any

from redrive.io.damage import LogDamage
from redrive.io.rosbag1.records import U32, DamageError, declared_size, parse_header, size_lie

__all__ = ["chunk_sizes", "decompressed_lie"]

#: bytes read at a chunk's position to parse its header (a chunk header is ~ 40 bytes)
_HEAD_READ = 256


def _fields(fd: int, pos: int) -> dict[str, bytes] | None:
    head = os.pread(fd, _HEAD_READ, pos)
    try:
        return parse_header(head, 0, len(head))[0]
    except DamageError:  # a header longer than the read: read it whole
        length = U32.unpack_from(head, 0)[0] if len(head) >= 4 else 0
        try:
            return parse_header(os.pread(fd, 4 + length, pos), 0, 4 + length)[0]
        except DamageError:
            return None  # rosbags read it: left to the reading


def chunk_sizes(
    fd: int, chunks: dict[int, Any], names: dict[Any, str], budget: int
) -> tuple[dict[int, int | None], list[LogDamage]]:
    """The declared uncompressed size of each chunk (``chunks``: rosbags' position → chunk
    header; ``names``: its decompressor → compression name), and the damage found at open: an
    uncompressed chunk whose data are another size, a chunk without the field, a compressed one
    declaring more than ``budget`` (0 messages lost: the data are what is read).  A compressed
    chunk's size is checked again when it is decompressed (:func:`decompressed_lie`)."""
    declared: dict[int, int | None] = {}
    found: list[LogDamage] = []
    for pos, header in chunks.items():
        fields = _fields(fd, pos)
        if fields is None:
            continue
        size = declared[pos] = declared_size(fields)
        name = names.get(header.decompressor, "none")
        if name == "none" or size is None:
            why = size_lie(name, size, header.datasize)
        elif size > budget:
            why = (
                f"header declares {size} bytes uncompressed, over the budget of {budget}: the "
                "size field is damaged or the chunk a decompression bomb; it is decompressed "
                "only up to the budget (what is over it is damage of its own)"
            )
        else:
            continue
        if why is not None:
            found.append(_damage(name, why, pos, header))
    return declared, found


def decompressed_lie(
    name: str, declared: int | None, actual: int, *, pos: int, header: Any
) -> LogDamage | None:
    """The damage of a chunk that decompressed to ``actual`` bytes, another size than its header
    says (None when they agree)."""
    why = size_lie(name, declared, actual)
    return None if why is None else _damage(name, why, pos, header)


def _damage(name: str, why: str, pos: int, header: Any) -> LogDamage:
    return LogDamage(
        what=f"the {name} chunk's {why}",
        start_byte=pos,
        stop_byte=header.datapos + header.datasize,
        messages_lost=0,
    )
