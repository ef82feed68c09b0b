"""Shared-memory transport: sensor streams between processes without pipes or pickle.

One segment per stream in /dev/shm, one writer and a few readers, page-aligned slots written in
place, sequence-checked lock-free reads, eventfd wake-ups, keep-latest or lossless policies,
typed payloads for the data model. See :mod:`redrive.transport.channel` (the protocol),
:mod:`redrive.transport._fence` (why it is correct on x86-64 and AArch64) and
:mod:`redrive.transport.codec` (typed payloads).

>>> from redrive.transport import Writer, Reader, Policy
>>> with Writer("example", capacity_bytes=4 << 20, policy=Policy.LOSSLESS) as w:  # doctest: +SKIP
...     r = Reader("example")                  # usually in another process
...     w.publish(b"payload", stamp_ns=123)
...     r.read(timeout_s=1.0).payload.tobytes()
b'payload'
"""

from __future__ import annotations

from redrive.transport.channel import (
    ChannelStats,
    Message,
    Policy,
    ProducerGoneError,
    Reader,
    ReaderGoneError,
    ReaderStats,
    Writer,
)
from redrive.transport.segment import remove_stale, segment_path, stale_segments

__all__ = [
    "ChannelStats",
    "Message",
    "Policy",
    "ProducerGoneError",
    "Reader",
    "ReaderGoneError",
    "ReaderStats",
    "Writer",
    "remove_stale",
    "segment_path",
    "stale_segments",
]
