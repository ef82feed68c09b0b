"""What both ends of a shared-memory stream share: its policy, its messages, its counters, the
errors it raises, and the wake-up and attach primitives (see :mod:`redrive.transport.channel` for
the protocol).
"""

from __future__ import annotations

import contextlib
import enum
import os
import select
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import TransportError
from redrive.transport.segment import (
    R_CAPTURE_LAG,
    R_DELIVERED,
    R_DROPPED,
    R_LAG_LAST,
    R_LAG_MAX,
    R_LAG_SUM,
    R_PID,
    R_POLICY,
    R_READ_SEQ,
    R_STATE,
    R_TORN,
    W_WRITE_SEQ,
    Segment,
)

__all__ = [
    "CHECK_S",
    "LONG_WAIT_BYTES",
    "POLL_NS",
    "SPIN_NS",
    "ChannelStats",
    "Message",
    "MessageSlots",
    "Policy",
    "ProducerGoneError",
    "ReaderGoneError",
    "ReaderStats",
    "channel_stats",
    "drain",
    "new_message",
    "socket_name",
    "wait_fd",
    "yield_cpu",
]

CHECK_S = 0.05  # how often a waiting side checks that the other side is alive
#: how long a side that finds nothing to do polls shared memory before it sleeps on its eventfd:
#: a message (or a free slot) that comes within it costs no sleep, no wake-up write by the other
#: side and no context switch. After the first POLL_NS of it, each poll that finds nothing yields
#: the CPU (``sched_yield``, which returns at once when nothing else wants the core): where the
#: two sides share a core (a loaded machine) the other side runs instead of the poll — without
#: it, under load the two sides of a flat-out lossless stream each slept about once per turn of
#: the ring — while what comes within POLL_NS (the other side on its own core) is seen without
#: a system call in between
SPIN_NS = 20_000
POLL_NS = 5_000
#: a message larger than this is long to write (and to read): a side waiting for the next one (a
#: reader, after a message of that size; a writer, to write one) polls for POLL_NS only, without
#: yielding, then sleeps on its eventfd — one wake-up by the other side, a small cost against such
#: a message. A yield hands the core to another process for up to its time slice, while the
#: message (or the free slot) comes; measured on the 2-vCPU VM under load ≈ 4 (BENCHMARKS.md,
#: h-shm7): the yields made a 4 MiB stream's publisher use 108–136 µs of CPU a message against
#: 81–95 without them, and a 1 MiB one's 25–27 against 30–32 (in 3 of 4 rounds; 2 MiB: a tie)
#: Waking a sleeping reader when such a message's slot is claimed rather than when it is
#: published (to overlap its wake-up with the copy) was measured worse (h-transport): the woken
#: reader takes the writer's core mid-copy — publisher CPU 245 → 386–575 µs a 4 MiB message.
LONG_WAIT_BYTES = 2 << 20
#: what a poll calls between two looks at shared memory (see SPIN_NS)
yield_cpu = os.sched_yield


class Policy(enum.Enum):
    """What happens when a reader is slower than the writer."""

    KEEP_LATEST = 0
    LOSSLESS = 1


class ProducerGoneError(TransportError):
    """The stream's writer process exited (or was killed) and nothing is left to read."""


class ReaderGoneError(TransportError):
    """A lossless reader of the stream exited; the messages it had not read are lost to it."""


@dataclass(frozen=True, slots=True)
class Message:
    """One message.

    Attributes:
        seq: its number in the stream (1, 2, …).
        stamp_ns: the producer's stamp (capture time of the sensor sample).
        publish_ns: wall clock (``time.time_ns``) when it was published.
        kind: the producer's payload kind (see :mod:`redrive.transport.codec`).
        meta: the producer's metadata bytes (at most ``META_CAPACITY``).
        payload: uint8 (nbytes,): an owned array from :meth:`Reader.read`, a read-only view into
            shared memory from :meth:`Reader.view` (valid only inside its ``with``).
        dropped_before: messages of the stream skipped right before this one.
    """

    seq: int
    stamp_ns: int
    publish_ns: int
    kind: int
    meta: bytes
    payload: npt.NDArray[np.uint8]
    dropped_before: int = 0


class MessageSlots:
    """A :class:`Message`'s slots without its frozen ``__setattr__``: filled with plain attribute
    stores, then made a ``Message`` by ``__class__`` assignment (allowed between classes of the
    same slot layout) — the reader's way to build one per message."""

    __slots__ = Message.__slots__


_new_object = object.__new__


def new_message(  # noqa: PLR0917 — the per-message path: positional, in field order
    seq: int,
    stamp_ns: int,
    publish_ns: int,
    kind: int,
    meta: bytes,
    payload: npt.NDArray[np.uint8],
    dropped_before: int,
) -> Message:
    """``Message(seq=…, …)`` at a sixth of the cost (the reader builds one per message): the
    frozen dataclass's ``__init__`` sets each field through ``object.__setattr__`` by name (≈ 14.6 k
    instructions); this fills a :class:`MessageSlots` and re-classes it (≈ 2.3 k; through the
    slots' descriptors it was 6.2 k). The result is the same frozen ``Message``."""
    msg: Any = _new_object(MessageSlots)
    msg.seq = seq
    msg.stamp_ns = stamp_ns
    msg.publish_ns = publish_ns
    msg.kind = kind
    msg.meta = meta
    msg.payload = payload
    msg.dropped_before = dropped_before
    msg.__class__ = Message
    return msg  # type: ignore[no-any-return]


@dataclass(frozen=True, slots=True)
class ReaderStats:
    """What one reader got. ``lag_*``: delivery time − publish time (the transport's own lag);
    ``capture_lag_ns``: delivery time − the producer's stamp, for the last message (the sensor's
    end-to-end lag when the stamp is the capture time on this clock)."""

    pid: int
    policy: Policy
    read_seq: int
    delivered: int
    dropped: int
    torn: int
    lag_last_ns: int
    lag_max_ns: int
    lag_mean_ns: float
    capture_lag_ns: int


@dataclass(frozen=True, slots=True)
class ChannelStats:
    """Counters of a stream: ``published`` by the writer, per reader what it got."""

    name: str
    published: int
    readers: tuple[ReaderStats, ...]

    @property
    def delivered(self) -> int:
        return sum(r.delivered for r in self.readers)

    @property
    def dropped(self) -> int:
        return sum(r.dropped for r in self.readers)


def socket_name(name: str, generation: int) -> bytes:
    """The abstract Unix socket where the writer of ``name`` (segment ``generation``) takes
    attaches."""
    return f"\0redrive.{name}.{generation:x}".encode()


def drain(fd: int) -> None:
    """Reset the eventfd ``fd`` (non-blocking: nothing to reset is fine)."""
    with contextlib.suppress(BlockingIOError):
        os.eventfd_read(fd)


def wait_fd(fd: int, timeout_s: float) -> bool:
    """Wait until ``fd`` is readable (or ``timeout_s``); True if it is."""
    ready, _, _ = select.select([fd], [], [], max(0.0, timeout_s))
    return bool(ready)


def channel_stats(seg: Segment, name: str) -> ChannelStats:
    """The counters of stream ``name`` as its segment holds them now."""
    w, lay = seg.words, seg.layout
    readers = []
    for r in range(lay.max_readers):
        base = lay.reader_word(r)
        if w[base + R_STATE] != 1:
            continue
        delivered = int(w[base + R_DELIVERED])
        readers.append(
            ReaderStats(
                pid=int(w[base + R_PID]),
                policy=Policy(int(w[base + R_POLICY])),
                read_seq=int(w[base + R_READ_SEQ]),
                delivered=delivered,
                dropped=int(w[base + R_DROPPED]),
                torn=int(w[base + R_TORN]),
                lag_last_ns=int(w[base + R_LAG_LAST]),
                lag_max_ns=int(w[base + R_LAG_MAX]),
                lag_mean_ns=w[base + R_LAG_SUM] / delivered if delivered else 0.0,
                capture_lag_ns=int(w[base + R_CAPTURE_LAG]),
            )
        )
    return ChannelStats(name=name, published=int(w[W_WRITE_SEQ]), readers=tuple(readers))
