"""The shared-memory channel: one writer process, up to ``max_readers`` reader processes.

>>> w = Writer("doc.example", capacity_bytes=1 << 20)            # doctest: +SKIP
>>> r = Reader("doc.example")                                     # another process
>>> w.publish(b"hello", stamp_ns=1)
>>> r.read(timeout_s=1.0).payload.tobytes()
b'hello'

* **Slots.** ``slots`` page-aligned slots of ``capacity_bytes`` each, written in place (no
  allocation per message; pages pre-touched at creation). Message ``n`` goes to the least
  recently written slot that no reader is reading.
* **Policies.** ``KEEP_LATEST`` (sensors that cannot wait): the writer never waits; a reader that
  falls more than a ring behind skips to the newest message and counts what it skipped as
  dropped. ``LOSSLESS`` (replay, recording): the writer waits (``timeout_s``) until every lossless
  reader has consumed the slot it needs — back-pressure — and fails clearly if a lossless reader
  died. A reader may observe a lossless stream as keep-latest (``Reader(policy=KEEP_LATEST)``)
  without slowing the writer.
* **Zero copy.** :meth:`Writer.loan` hands out the slot itself to fill; :meth:`Reader.view` hands
  out a read-only view of it that stays valid until the ``with`` block ends: the reader *pins*
  the slot and the writer never reuses a pinned slot. :meth:`Reader.read` copies out.
* **Torn messages.** A slot is complete when ``seq_begin == seq_end == n``; a writer killed
  mid-write leaves them different and the message is never delivered. Readers re-check the
  sequence after copying (see :mod:`redrive.transport._fence` for why this is correct on x86-64
  and AArch64).
* **Wake-ups.** Each reader has an ``eventfd`` the writer signals after every message; the
  writer has one the lossless readers signal after every message they free. The file
  descriptors are exchanged once, at attach, over a Unix socket (``SCM_RIGHTS``) in the abstract
  namespace, so readers and writer may be unrelated processes running different Python
  interpreters (the ROS 1 scraper runs under the system Python).
* **Failures.** A reader sees its writer gone (pid + start time) and raises :class:`ProducerGoneError`;
  when a new writer re-creates the stream, the next read re-attaches. A writer ignores the pins of
  dead readers and frees their entries. The writer unlinks the segment on close; a segment left
  by a killed writer is removed by the next writer of that stream or by :func:`remove_stale`.

The writer's side is :mod:`redrive.transport.writer`, the reader's :mod:`redrive.transport.reader`,
what both share (policy, messages, counters, errors, wake-ups) :mod:`redrive.transport.stream`,
the memory layout :mod:`redrive.transport.segment`; this module names them together.
"""

from __future__ import annotations

from redrive.transport.reader import Reader
from redrive.transport.stream import (
    ChannelStats,
    Message,
    Policy,
    ProducerGoneError,
    ReaderGoneError,
    ReaderStats,
)
from redrive.transport.writer import Writer

__all__ = [
    "ChannelStats",
    "Message",
    "Policy",
    "ProducerGoneError",
    "Reader",
    "ReaderGoneError",
    "ReaderStats",
    "Writer",
]
