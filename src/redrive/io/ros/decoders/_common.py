"""Small helpers shared by the decoders: stamps, error context, buffer ownership."""

from __future__ import annotations

import mmap
from typing import Any

from redrive.errors import UnsupportedMessageError
from redrive.io.base import LogMessage

__all__ = [
    "buffer_is_immutable",
    "describe",
    "header_stamp_ns",
    "quat",
    "raw_is_immutable",
    "stamp_ns_or",
    "unsupported",
    "vec3",
]


def stamp_ns_or(stamp: Any, fallback_ns: int) -> int:
    """A ``builtin_interfaces/Time`` (ROS 1 ``time`` too) as int ns; ``fallback_ns`` when zero."""
    stamp_ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return stamp_ns if stamp_ns != 0 else fallback_ns


def header_stamp_ns(header: Any, message: LogMessage) -> int:
    """The header stamp in ns; the log time when the stamp is zero."""
    return stamp_ns_or(header.stamp, message.log_time_ns)


def describe(message: LogMessage) -> str:
    """``topic (type, encoding, t=...)``: where a message came from, for error texts."""
    return (
        f"topic {message.topic!r} ({message.msgtype}, {message.encoding}, "
        f"log time {message.log_time_ns} ns)"
    )


def unsupported(message: LogMessage, what: str, advice: str) -> UnsupportedMessageError:
    """An :class:`UnsupportedMessageError` saying what, where and what to do."""
    return UnsupportedMessageError(f"{what} on {describe(message)}; {advice}")


def raw_is_immutable(message: LogMessage) -> bool:
    """True when ``message.raw`` cannot change later, so arrays may view it without a copy.

    ``bytes``, memoryviews of ``bytes`` and read-only views of a read-only file map (the ROS 1
    reader maps uncompressed chunks; the log is not written while it is read) are immutable; a
    view into a reader's reusable buffer (bytearray, writable map) is not, and arrays built on it
    must be copied.
    """
    return buffer_is_immutable(message.raw)


def buffer_is_immutable(raw: object) -> bool:
    """:func:`raw_is_immutable` of a buffer (a :class:`~redrive.io.base.MessageBatch`'s)."""
    if isinstance(raw, bytes):
        return True
    if not (isinstance(raw, memoryview) and raw.readonly):
        return False
    owner = raw.obj
    return isinstance(owner, bytes) or (isinstance(owner, mmap.mmap) and _map_is_read_only(owner))


def _map_is_read_only(owner: mmap.mmap) -> bool:
    try:
        with memoryview(owner) as probe:
            return probe.readonly
    except (ValueError, BufferError):
        return False


def vec3(value: Any) -> tuple[float, float, float]:
    """``(x, y, z)`` of a geometry_msgs Vector3 / Point."""
    return float(value.x), float(value.y), float(value.z)


def quat(value: Any) -> tuple[float, float, float, float]:
    """``(x, y, z, w)`` of a geometry_msgs Quaternion."""
    return float(value.x), float(value.y), float(value.z), float(value.w)
