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
"""

from __future__ import annotations

import contextlib
import enum
import logging
import os
import select
import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import TransportError
from redrive.transport._fence import fence, ordered
from redrive.transport.segment import (
    HEADER_BYTES,
    META_CAPACITY,
    META_OFFSET,
    R_CAPTURE_LAG,
    R_DELIVERED,
    R_DROPPED,
    R_LAG_LAST,
    R_LAG_MAX,
    R_LAG_SUM,
    R_PID,
    R_PIN,
    R_POLICY,
    R_READ_SEQ,
    R_START,
    R_STATE,
    R_TORN,
    R_WAITING,
    READER_WORDS,
    S_BEGIN,
    S_END,
    S_KIND,
    S_META_LEN,
    S_NBYTES,
    S_PUBLISH,
    S_STAMP,
    W_HEARTBEAT,
    W_ORDER,
    W_POLICY,
    W_PUBLISHED,
    W_WRITE_SEQ,
    W_WRITER_WAITING,
    Layout,
    Segment,
    process_alive,
    self_identity,
)
from redrive.types import SensorData

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

logger = logging.getLogger(__name__)

_CHECK_S = 0.05  # how often a waiting side checks that the other side is alive


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


def _socket_name(name: str, generation: int) -> bytes:
    return f"\0redrive.{name}.{generation:x}".encode()


def _drain(fd: int) -> None:
    with contextlib.suppress(BlockingIOError):
        os.eventfd_read(fd)


def _wait_fd(fd: int, timeout_s: float) -> bool:
    """Wait until ``fd`` is readable (or ``timeout_s``); True if it is."""
    ready, _, _ = select.select([fd], [], [], max(0.0, timeout_s))
    return bool(ready)


def _stats(seg: Segment, name: str) -> ChannelStats:
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
    return ChannelStats(name=name, published=int(w[W_PUBLISHED]), readers=tuple(readers))


class Writer:
    """The one writer of stream ``name``; creates (and on close unlinks) its segment.

    Args:
        name: stream name: letters, digits, ``_ . -``.
        capacity_bytes: the largest payload.
        slots: slots in the ring (≥ ``max_readers`` + 2).
        policy: :class:`Policy`.
        max_readers: reader entries (each reader process takes one).

    Raises:
        TransportError: a live writer has the name, bad sizes, /dev/shm too small.
    """

    def __init__(
        self,
        name: str,
        *,
        capacity_bytes: int,
        slots: int = 4,
        policy: Policy = Policy.KEEP_LATEST,
        max_readers: int = 2,
    ) -> None:
        if capacity_bytes <= 0 or max_readers < 1 or slots < max_readers + 2:
            msg = (
                f"stream {name!r}: need capacity_bytes > 0, max_readers ≥ 1 and slots ≥ "
                f"max_readers + 2 (got {capacity_bytes}, {max_readers}, {slots})"
            )
            raise TransportError(msg)
        self.name = name
        self.policy = policy
        layout = Layout(n_slots=slots, capacity=capacity_bytes, max_readers=max_readers)
        self._seg = Segment.create(name, layout, policy=policy.value)
        self._w = self._seg.words
        self._layout = layout
        self._slot_seq = [0] * slots  # message each slot holds
        self._slot_words = [layout.slot_offset(s) // 8 for s in range(slots)]
        mm = self._seg.mm
        self._payload = [
            np.frombuffer(mm, np.uint8, capacity_bytes, layout.slot_offset(s) + HEADER_BYTES)
            for s in range(slots)
        ]
        self._raw = memoryview(mm)
        self._readers = [layout.reader_word(r) for r in range(max_readers)]
        self._reader_fd = [-1] * max_readers
        self._fd_lock = threading.Lock()
        self._space_fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self._lru = list(range(slots))  # slots, least recently written first
        self._seq = 0
        self._loaned = False
        self._closed = False
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        self._sock.bind(_socket_name(name, self._seg.generation))
        self._sock.listen(max_readers * 2)
        self._sock.settimeout(0.2)
        self._thread = threading.Thread(
            target=self._accept_loop, name=f"redrive-shm-{name}", daemon=True
        )
        self._thread.start()

    # -- attach handshake (a thread) ----------------------------------------------------------
    def _accept_loop(self) -> None:
        while not self._closed:
            try:
                conn, _ = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            with conn:
                try:
                    conn.settimeout(2.0)
                    data, fds, _, _ = socket.recv_fds(conn, 16, 1)
                    index = int.from_bytes(data[:8], "little")
                    if len(fds) != 1 or not 0 <= index < len(self._reader_fd):
                        for fd in fds:
                            os.close(fd)
                        continue
                    with self._fd_lock:
                        old, self._reader_fd[index] = self._reader_fd[index], fds[0]
                    if old >= 0:
                        os.close(old)
                    socket.send_fds(conn, [b"ok"], [self._space_fd])
                except OSError as err:
                    logger.debug("stream %s: a reader's attach failed: %s", self.name, err)

    # -- publishing -----------------------------------------------------------------------------
    @property
    def capacity(self) -> int:
        return self._layout.capacity

    def _claim(self, deadline: float | None) -> int:
        """A slot to write message ``self._seq + 1`` into, marked as being written."""
        w = self._w
        nxt = self._seq + 1
        last_check = time.monotonic()
        while True:
            need_free = self._lossless_floor()
            readers = [b for b in self._readers if w[b + R_STATE] == 1]
            pinned = {w[b + R_PIN] for b in readers}
            for slot in self._lru:  # least recently written first
                held = self._slot_seq[slot]
                if need_free is not None and held > need_free:
                    break  # the newer slots all hold unread lossless messages too
                if slot in pinned:
                    continue
                base_w = self._slot_words[slot]
                w[base_w + S_BEGIN] = nxt  # ① the slot is being written
                fence()  # ②
                if any(w[b + R_PIN] == slot for b in readers):  # ③
                    w[base_w + S_BEGIN] = held
                    continue
                return slot
            # no slot: only lossless back-pressure (or pins of dead readers) gets here
            now = time.monotonic()
            if deadline is not None and now >= deadline:
                behind = ", ".join(
                    f"pid {w[b + R_PID]} at message {w[b + R_READ_SEQ]}"
                    for b in self._live_readers()
                )
                msg = (
                    f"stream {self.name!r}: message {nxt} not published: every slot holds a "
                    f"message a lossless reader has not read yet ({behind}); the reader is too "
                    "slow or stuck — raise the timeout, add slots, or read as keep-latest"
                )
                raise TransportError(msg)
            if now - last_check >= _CHECK_S:
                last_check = now
                self._reap_dead_readers()
            wait = _CHECK_S if deadline is None else min(_CHECK_S, deadline - now)
            w[W_WRITER_WAITING] = 1
            fence()  # the readers' read_seq stores are seen after this, or they see the flag
            if self._lossless_floor() == need_free and _wait_fd(self._space_fd, wait):
                _drain(self._space_fd)
            w[W_WRITER_WAITING] = 0

    def _live_readers(self) -> list[int]:
        w = self._w
        return [base for base in self._readers if w[base + R_STATE] == 1]

    def _lossless_floor(self) -> int | None:
        """The lowest read position of the lossless readers (None without any)."""
        if self.policy is not Policy.LOSSLESS:
            return None
        w = self._w
        floor = None
        for base in self._readers:
            if w[base + R_STATE] == 1 and w[base + R_POLICY] == Policy.LOSSLESS.value:
                seq = int(w[base + R_READ_SEQ])
                floor = seq if floor is None else min(floor, seq)
        return floor

    def _reap_dead_readers(self) -> None:
        w = self._w
        for base in self._readers:
            if w[base + R_STATE] == 1 and not process_alive(
                int(w[base + R_PID]), int(w[base + R_START])
            ):
                lossless = w[base + R_POLICY] == Policy.LOSSLESS.value
                pid, missed = int(w[base + R_PID]), self._seq - int(w[base + R_READ_SEQ])
                w[base + R_PIN] = -1
                w[base + R_STATE] = 0
                if lossless:
                    msg = (
                        f"stream {self.name!r}: lossless reader pid {pid} exited with {missed} "
                        "message(s) unread; they are lost to it (a new reader starts from the "
                        "oldest message still held)"
                    )
                    raise ReaderGoneError(msg)
                logger.info("stream %s: reader pid %d is gone; entry freed", self.name, pid)

    def _commit(self, slot: int, nbytes: int, stamp_ns: int, kind: int, meta: bytes) -> int:
        w, seq = self._w, self._seq + 1
        base = self._slot_words[slot]
        if meta:
            off = base * 8 + META_OFFSET
            self._raw[off : off + len(meta)] = meta
        w[base + S_STAMP] = stamp_ns
        now = time.time_ns()
        w[base + S_PUBLISH] = now
        w[base + S_KIND] = kind
        w[base + S_NBYTES] = nbytes
        w[base + S_META_LEN] = len(meta)
        ordered()  # ⑤
        w[base + S_END] = seq  # ⑥
        w[W_ORDER + seq % self._layout.n_slots] = slot  # ⑦
        w[W_WRITE_SEQ] = seq  # ⑧
        w[W_PUBLISHED] = seq
        w[W_HEARTBEAT] = now
        self._seq = seq
        self._slot_seq[slot] = seq
        self._lru.remove(slot)
        self._lru.append(slot)
        fence()  # write_seq is seen by a reader before it sleeps, or its waiting flag is seen here
        with self._fd_lock:
            for base_r, fd in zip(self._readers, self._reader_fd, strict=True):
                if fd >= 0 and w[base_r + R_WAITING]:
                    os.eventfd_write(fd, 1)
        return seq

    def _check(self, nbytes: int, meta: bytes) -> None:
        if self._closed:
            msg = f"stream {self.name!r} is closed"
            raise TransportError(msg)
        if self._loaned:
            msg = f"stream {self.name!r}: a loaned slot is still open; finish that `with` first"
            raise TransportError(msg)
        if nbytes > self._layout.capacity:
            msg = (
                f"stream {self.name!r}: a {nbytes}-byte message does not fit its "
                f"{self._layout.capacity}-byte slots; create the stream with a larger "
                "capacity_bytes"
            )
            raise TransportError(msg)
        if len(meta) > META_CAPACITY:
            msg = f"stream {self.name!r}: {len(meta)} bytes of meta (at most {META_CAPACITY})"
            raise TransportError(msg)

    def publish(
        self,
        payload: bytes | bytearray | memoryview | npt.NDArray[Any],
        *,
        stamp_ns: int = 0,
        kind: int = 0,
        meta: bytes = b"",
        timeout_s: float | None = 5.0,
    ) -> int:
        """Copy ``payload`` (any C-contiguous buffer) into the next slot; returns its sequence.

        Raises:
            TransportError: too large; lossless back-pressure for longer than ``timeout_s``
                (None = wait forever); :class:`ReaderGoneError` when a lossless reader died.
        """
        src = np.frombuffer(payload, np.uint8) if not isinstance(payload, np.ndarray) else payload
        if src.dtype != np.uint8 or src.ndim != 1:
            src = src.reshape(-1).view(np.uint8)
        nbytes = src.shape[0]
        self._check(nbytes, meta)
        slot = self._claim(None if timeout_s is None else time.monotonic() + timeout_s)
        np.copyto(self._payload[slot][:nbytes], src)  # ④
        return self._commit(slot, nbytes, stamp_ns, kind, meta)

    @contextlib.contextmanager
    def loan(
        self,
        nbytes: int,
        *,
        stamp_ns: int = 0,
        kind: int = 0,
        meta: bytes = b"",
        timeout_s: float | None = 5.0,
    ) -> Iterator[npt.NDArray[np.uint8]]:
        """The next slot itself, ``nbytes`` long, to fill in place; published when the block
        ends without an exception (an exception abandons the slot, nothing is published)."""
        self._check(nbytes, meta)
        slot = self._claim(None if timeout_s is None else time.monotonic() + timeout_s)
        self._loaned = True
        try:
            yield self._payload[slot][:nbytes]
        except BaseException:
            self._w[self._slot_words[slot] + S_BEGIN] = self._slot_seq[slot]
            raise
        finally:
            self._loaned = False
        self._commit(slot, nbytes, stamp_ns, kind, meta)

    def publish_sample(self, sample: SensorData, *, timeout_s: float | None = 5.0) -> int:
        """Publish a ``SensorData`` (typed, see :mod:`redrive.transport.codec`); returns its
        sequence number."""
        from redrive.transport.codec import write_sample

        write_sample(self.loan, sample, timeout_s=timeout_s)
        return self._seq

    @property
    def seq(self) -> int:
        """The last published message's sequence number."""
        return self._seq

    def stats(self) -> ChannelStats:
        return _stats(self._seg, self.name)

    def close(self) -> None:
        """Unlink the segment (readers see the writer gone) and stop the attach thread."""
        if self._closed:
            return
        self._closed = True
        self._sock.close()
        self._thread.join(timeout=1.0)
        with self._fd_lock:
            for fd in self._reader_fd:
                if fd >= 0:
                    os.close(fd)
            self._reader_fd = [-1] * len(self._reader_fd)
        os.close(self._space_fd)
        self._payload = []
        self._raw.release()
        self._seg.close(unlink=True)

    def __enter__(self) -> Writer:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __del__(self) -> None:
        if not getattr(self, "_closed", True):
            with contextlib.suppress(Exception):
                self.close()


class Reader:
    """A reader of stream ``name`` (waits up to ``timeout_s`` for the writer to create it).

    Args:
        policy: how this reader reads: the stream's policy by default; ``KEEP_LATEST`` on a
            lossless stream observes it without back-pressure.

    Raises:
        TransportError: no such stream within ``timeout_s``; every reader entry taken; a
            lossless reader asked of a keep-latest stream.
    """

    def __init__(self, name: str, *, timeout_s: float = 5.0, policy: Policy | None = None) -> None:
        self.name = name
        self._want_policy = policy
        self._seg: Segment | None = None
        self._fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self._space_fd = -1
        self._closed = False
        self._attach(time.monotonic() + timeout_s)

    # -- attaching ---------------------------------------------------------------------------
    def _attach(self, deadline: float) -> None:
        while True:
            try:
                seg = Segment.attach(self.name)
            except FileNotFoundError:
                seg = None
            if seg is not None:
                if seg.owner_alive():
                    break
                seg.close()
            if time.monotonic() >= deadline:
                msg = (
                    f"no writer for stream {self.name!r} (no live /dev/shm/redrive.{self.name}); "
                    "start its producer first"
                )
                raise ProducerGoneError(msg)
            time.sleep(0.01)
        try:
            self._join(seg)
        except BaseException:
            seg.close()
            raise

    def _join(self, seg: Segment) -> None:
        w, lay = seg.words, seg.layout
        stream_policy = Policy(int(w[W_POLICY]))
        policy = self._want_policy or stream_policy
        if policy is Policy.LOSSLESS and stream_policy is not Policy.LOSSLESS:
            msg = f"stream {self.name!r} is keep-latest: it cannot be read losslessly"
            raise TransportError(msg)
        pid, start = self_identity()
        with seg.locked():
            entry = None
            for r in range(lay.max_readers):
                base = lay.reader_word(r)
                if w[base + R_STATE] == 0 or not process_alive(
                    int(w[base + R_PID]), int(w[base + R_START])
                ):
                    entry = r
                    break
            if entry is None:
                msg = (
                    f"stream {self.name!r} already has {lay.max_readers} readers; stop one or "
                    "create the stream with a larger max_readers"
                )
                raise TransportError(msg)
            base = lay.reader_word(entry)
            w[base + R_STATE] = 0
            ws = int(w[W_WRITE_SEQ])
            if policy is Policy.LOSSLESS:
                start_seq = max(0, ws - (lay.n_slots - 1))  # the oldest messages still held
            else:
                start_seq = max(0, ws - 1)  # the newest message
            for i in range(READER_WORDS):
                w[base + i] = 0
            w[base + R_PID], w[base + R_START] = pid, start
            w[base + R_POLICY], w[base + R_READ_SEQ], w[base + R_PIN] = policy.value, start_seq, -1
            fence()
            w[base + R_STATE] = 1
        self._seg, self._w, self._lay = seg, w, lay
        self.policy = policy
        self._base = base
        self._read_seq = start_seq
        self._slot_words = [lay.slot_offset(s) // 8 for s in range(lay.n_slots)]
        self._payload = [
            np.frombuffer(seg.mm, np.uint8, lay.capacity, lay.slot_offset(s) + HEADER_BYTES)
            for s in range(lay.n_slots)
        ]
        for arr in self._payload:
            arr.flags.writeable = False
        self._raw = memoryview(seg.mm)
        self._handshake(entry, seg.generation)

    def _handshake(self, entry: int, generation: int) -> None:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC) as sock:
            sock.settimeout(5.0)
            try:
                sock.connect(_socket_name(self.name, generation))
                socket.send_fds(sock, [entry.to_bytes(8, "little")], [self._fd])
                _, fds, _, _ = socket.recv_fds(sock, 16, 1)
            except OSError as err:
                msg = f"stream {self.name!r}: the writer did not answer the attach ({err})"
                raise ProducerGoneError(msg) from err
        if len(fds) != 1:
            msg = f"stream {self.name!r}: the writer sent no wake-up descriptor"
            raise TransportError(msg)
        if self._space_fd >= 0:
            os.close(self._space_fd)
        self._space_fd = fds[0]

    def _detach(self) -> None:
        seg = self._seg
        if seg is None:
            return
        self._w[self._base + R_PIN] = -1
        self._w[self._base + R_STATE] = 0
        self._payload = []
        self._raw.release()
        self._w = memoryview(b"\0" * 8).cast("q")
        seg.close()
        self._seg = None

    def _reattach_or_raise(self) -> None:
        """The writer is gone: re-attach to a new writer of the stream, or raise."""
        assert self._seg is not None
        if self._seg.replaced():
            try:
                new = Segment.attach(self.name)
            except (FileNotFoundError, TransportError):
                new = None
            if new is not None and new.owner_alive():
                new.close()
                logger.info("stream %s: writer restarted; re-attaching", self.name)
                self._detach()
                self._attach(time.monotonic() + 1.0)
                return
            if new is not None:
                new.close()
        msg = f"the writer of stream {self.name!r} is gone (last message {self._read_seq})"
        raise ProducerGoneError(msg)

    # -- reading -------------------------------------------------------------------------------
    def _next(self, timeout_s: float | None, latest: bool) -> tuple[int, int, int]:
        """Pin the next message: (slot, seq, dropped before it)."""
        if self._closed:
            msg = f"reader of stream {self.name!r} is closed"
            raise TransportError(msg)
        if self._seg is None:
            self._attach(time.monotonic() + (timeout_s or 0.0))
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        last_check = time.monotonic()
        jump = latest
        while True:
            w, lay = self._w, self._lay
            ws = w[W_WRITE_SEQ]  # ⓐ
            ordered()  # ⓑ
            rs = self._read_seq
            if ws > rs:
                want = ws if jump or ws - rs > lay.n_slots else rs + 1
                slot = w[W_ORDER + want % lay.n_slots]  # ⓒ
                pin = self._base + R_PIN
                w[pin] = slot  # ⓓ
                fence()  # ⓔ
                base = self._slot_words[slot]
                if w[base + S_BEGIN] == want and w[base + S_END] == want:  # ⓕ
                    return slot, want, want - rs - 1
                w[pin] = -1
                jump = self.policy is Policy.KEEP_LATEST  # overwritten meanwhile: newest
                continue
            now = time.monotonic()
            if now - last_check >= _CHECK_S or (deadline is not None and now >= deadline):
                last_check = now
                if self._seg is not None and not self._seg.owner_alive():
                    if w[W_WRITE_SEQ] > self._read_seq:
                        continue  # it left messages behind: deliver them first
                    self._reattach_or_raise()
                    continue
            if deadline is not None and now >= deadline:
                return -1, 0, 0
            wait = _CHECK_S if deadline is None else min(_CHECK_S, deadline - now)
            flag = self._base + R_WAITING
            w[flag] = 1
            fence()  # the writer sees the flag after this, or its write_seq is seen below
            if w[W_WRITE_SEQ] == self._read_seq and _wait_fd(self._fd, wait):
                _drain(self._fd)
            w[flag] = 0

    def _message(
        self, slot: int, seq: int, dropped: int, payload: npt.NDArray[np.uint8]
    ) -> Message:
        w, base = self._w, self._slot_words[slot]
        meta_len = w[base + S_META_LEN]
        meta = b""
        if meta_len:
            off = base * 8 + META_OFFSET
            meta = bytes(self._raw[off : off + meta_len])
        return Message(
            seq=seq,
            stamp_ns=int(w[base + S_STAMP]),
            publish_ns=int(w[base + S_PUBLISH]),
            kind=int(w[base + S_KIND]),
            meta=meta,
            payload=payload,
            dropped_before=dropped,
        )

    def _release(self, slot: int, seq: int, dropped: int, msg: Message) -> bool:
        """Re-check the slot (ⓗⓘ), unpin it (ⓙ), count; False if the message was torn."""
        w, me = self._w, self._base
        ordered()  # ⓗ
        base = self._slot_words[slot]
        intact = w[base + S_BEGIN] == seq and w[base + S_END] == seq  # ⓘ
        w[me + R_PIN] = -1  # ⓙ
        self._read_seq = seq
        w[me + R_READ_SEQ] = seq
        if dropped:
            w[me + R_DROPPED] += dropped
        if not intact:
            w[me + R_TORN] += 1
            return False
        now = time.time_ns()
        lag = now - msg.publish_ns
        w[me + R_DELIVERED] += 1
        w[me + R_CAPTURE_LAG] = now - msg.stamp_ns if msg.stamp_ns else lag
        w[me + R_LAG_LAST] = lag
        w[me + R_LAG_SUM] += lag
        w[me + R_LAG_MAX] = max(w[me + R_LAG_MAX], lag)
        if self.policy is Policy.LOSSLESS and self._space_fd >= 0:
            fence()  # read_seq is seen by a writer before it sleeps, or its flag is seen here
            if w[W_WRITER_WAITING]:
                os.eventfd_write(self._space_fd, 1)
        return True

    def read(
        self,
        timeout_s: float | None = None,
        *,
        latest: bool = False,
        out: npt.NDArray[np.uint8] | None = None,
    ) -> Message | None:
        """The next message, copied out of shared memory (None after ``timeout_s``).

        ``latest=True`` skips to the newest message (what was skipped counts as dropped).
        ``out``: a uint8 array of at least the stream's capacity to copy into (the payload is then
        a view of it, valid until the next read into it) — no allocation per message, whose page
        faults dominate the copy of a multi-MB message into a fresh array.

        Raises:
            ProducerGoneError: the writer is gone and everything it published has been read.
        """
        while True:
            slot, seq, dropped = self._next(timeout_s, latest)
            if slot < 0:
                return None
            nbytes = self._w[self._slot_words[slot] + S_NBYTES]
            if out is None:
                copy = np.empty(nbytes, np.uint8)
            elif out.dtype == np.uint8 and out.ndim == 1 and out.shape[0] >= nbytes:
                copy = out[:nbytes]
            else:
                self._w[self._base + R_PIN] = -1
                msg_text = (
                    f"stream {self.name!r}: read(out=…) needs a 1-D uint8 array of at least "
                    f"{nbytes} bytes"
                )
                raise TransportError(msg_text)
            np.copyto(copy, self._payload[slot][:nbytes])  # ⓖ
            msg = self._message(slot, seq, dropped, copy)
            if self._release(slot, seq, dropped, msg):
                return msg

    def read_sample(
        self, timeout_s: float | None = None, *, latest: bool = False
    ) -> tuple[Message, SensorData] | None:
        """The next message decoded as ``SensorData`` (copied out: keep it as long as you like).

        Raises:
            TransportError: the message is not a sensor sample.
        """
        from redrive.transport.codec import KIND_SENSOR, decode_sample

        msg = self.read(timeout_s, latest=latest)
        if msg is None:
            return None
        if msg.kind != KIND_SENSOR:
            err = f"stream {self.name!r}: message {msg.seq} is kind {msg.kind}, not a sensor sample"
            raise TransportError(err)
        return msg, decode_sample(msg.meta, msg.payload)

    @contextlib.contextmanager
    def view(
        self, timeout_s: float | None = None, *, latest: bool = False
    ) -> Iterator[Message | None]:
        """The next message as a read-only view into shared memory, valid inside the block
        (the slot is pinned: the writer does not reuse it meanwhile). Yields None on timeout."""
        slot, seq, dropped = self._next(timeout_s, latest)
        if slot < 0:
            yield None
            return
        nbytes = self._w[self._slot_words[slot] + S_NBYTES]
        msg = self._message(slot, seq, dropped, self._payload[slot][:nbytes])
        try:
            yield msg
        finally:
            self._release(slot, seq, dropped, msg)

    def stats(self) -> ChannelStats:
        if self._seg is None:
            return ChannelStats(name=self.name, published=0, readers=())
        return _stats(self._seg, self.name)

    def fileno(self) -> int:
        """The reader's wake-up ``eventfd``: readable when a message may have arrived (for
        ``select`` over several streams; a wake-up may be spurious — read with ``timeout_s=0``)."""
        return self._fd

    def writer_alive(self) -> bool:
        return self._seg is not None and self._seg.owner_alive()

    def close(self) -> None:
        """Leave the stream (frees the reader entry)."""
        if self._closed:
            return
        self._closed = True
        self._detach()
        os.close(self._fd)
        if self._space_fd >= 0:
            os.close(self._space_fd)

    def __enter__(self) -> Reader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __del__(self) -> None:
        if not getattr(self, "_closed", True):
            with contextlib.suppress(Exception):
                self.close()
