"""The writer of a shared-memory stream: creates its segment, claims slots, publishes, takes
readers' attaches (see :mod:`redrive.transport.channel` for the protocol and the numbered steps).
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import struct
import threading
import time
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import TransportError
from redrive.transport._fence import WEAK_ORDERING, fence
from redrive.transport.segment import (
    HEADER_BYTES,
    META_CAPACITY,
    META_OFFSET,
    R_PID,
    R_PIN,
    R_POLICY,
    R_READ_SEQ,
    R_START,
    R_STATE,
    R_WAITING,
    READER_WORDS,
    S_BEGIN,
    S_END,
    S_STAMP,
    W_ORDER,
    W_WRITE_SEQ,
    W_WRITER_WAITING,
    Layout,
    Segment,
    process_alive,
)
from redrive.transport.stream import (
    CHECK_S,
    LONG_WAIT_BYTES,
    POLL_NS,
    SPIN_NS,
    ChannelStats,
    Policy,
    ReaderGoneError,
    channel_stats,
    drain,
    socket_name,
    wait_fd,
    yield_cpu,
)
from redrive.types import SensorData

__all__ = ["Writer"]

logger = logging.getLogger(__name__)

_LOSSLESS = Policy.LOSSLESS.value
_time_ns = time.time_ns
_NO_READER = 1 << 62  # the lowest read position when no reader is live
#: a slot's header words stamp_ns, publish_ns, kind, nbytes, meta_len (native int64, each stored
#: whole), written with one call
_HEADER = struct.Struct("5q")
_HEADER_AT = 8 * S_STAMP


_PENDING, _DONE = -1, -2  # a loan's state when it holds no slot: handed out / finished


class _Loan:
    """What :meth:`Writer.loan` returns: claims the slot on ``__enter__``, publishes it on a clean
    ``__exit__`` and abandons it on an exception (a class, not a generator: no generator frame
    per message). The writer hands the same object out again once it is finished, so a message
    allocates nothing here; ``_slot`` is the state: ``_PENDING`` (handed out, not entered), the
    slot (entered), ``_DONE``."""

    __slots__ = ("_kind", "_meta", "_nbytes", "_slot", "_stamp_ns", "_timeout_s", "_writer")

    def __init__(  # noqa: PLR0917 — positional, in the order loan() sets them
        self,
        writer: Writer,
        nbytes: int,
        stamp_ns: int,
        kind: int,
        meta: bytes,
        timeout_s: float | None,
    ) -> None:
        self._writer, self._nbytes, self._stamp_ns = writer, nbytes, stamp_ns
        self._kind, self._meta, self._timeout_s = kind, meta, timeout_s
        self._slot = _PENDING

    def __enter__(self) -> npt.NDArray[np.uint8]:
        wr, nbytes, meta = self._writer, self._nbytes, self._meta
        if self._slot != _PENDING:
            msg = f"stream {wr.name!r}: a loan is entered once; call writer.loan() again"
            raise TransportError(msg)
        if (
            wr._closed
            or wr._loaned
            or nbytes > wr._capacity
            or (meta and len(meta) > META_CAPACITY)
        ):
            wr._check(nbytes, meta)  # raises the error that applies
        # the fast claim (①②③), _claim's first choice without its lists: the slot of the
        # newest message every live reader has read (the lowest read position), if it still
        # holds it and no reader pins it — the slot just read, still in cache: the one written
        # last when the readers keep up, else the one they left last. Anything else goes
        # through _claim's full pass (without readers it keeps the newest message for one that
        # comes)
        w, floor = wr._w, _NO_READER
        for state, read_seq in wr._entry_words:
            if w[state] == 1:
                seq = w[read_seq]
                if seq < floor:  # noqa: PLR1730 — min() is a call per reader and message
                    floor = seq
        slot = wr._order[floor % wr._n_slots] if 0 < floor < _NO_READER else -1
        if slot >= 0 and wr._slot_seq[slot] == floor:
            begin = wr._slot_words[slot]  # + S_BEGIN
            w[begin] = wr._seq + 1  # ① the slot is being written
            fence()  # ②
            # ③ every entry's pin, live or not: a free entry's is -1, and a reader that turned
            # live after the loop above is checked too
            for pin in wr._pin_words:
                if w[pin] == slot:
                    w[begin] = floor  # it holds its message again
                    slot = -1
                    break
        else:
            slot = -1
        if slot < 0:
            slot = wr._claim(self._timeout_s, nbytes)
        self._slot = slot
        wr._loaned = True
        if wr._out_n[slot] != nbytes:  # the slot's view of this length, made once
            wr._out_n[slot] = nbytes
            wr._out[slot] = wr._payload[slot][:nbytes]
        return wr._out[slot]

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        wr, slot = self._writer, self._slot
        self._slot = _DONE
        wr._loaned = False
        wr._free_loan = self
        w, base = wr._w, wr._slot_words[slot]
        if exc_type is not None:  # abandoned: the slot holds its old message again
            w[base + S_BEGIN] = wr._slot_seq[slot]
            return
        # publish (④ was the caller's fill)
        seq, mm, meta = wr._seq + 1, wr._mm, self._meta
        if meta:
            n_meta = len(meta)
            off = base * 8 + META_OFFSET
            wr._raw[off : off + n_meta] = meta
        else:
            n_meta = 0
        # the header's five words in one call (no other side reads them before ⑥)
        _HEADER.pack_into(
            mm, wr._header_at[slot], self._stamp_ns, _time_ns(), self._kind, self._nbytes, n_meta
        )
        if WEAK_ORDERING:
            fence()  # ⑤
        w[base + S_END] = seq  # ⑥
        i = seq % wr._n_slots
        w[W_ORDER + i] = wr._order[i] = slot  # ⑦
        w[W_WRITE_SEQ] = seq  # ⑧ (also the stream's published count)
        wr._seq = wr._slot_seq[slot] = seq
        if slot != wr._last:
            lru = wr._lru
            lru.remove(slot)
            lru.append(slot)
            wr._last = slot
        fence()  # write_seq is seen by a reader before it sleeps, or its waiting flag is seen here
        # the readers' waiting flags: a load each for up to two entries (≈ 270 instructions a
        # load), one struct call beyond (≈ 900 with the compare)
        flags = wr._waiting_words
        if wr._few_readers:
            for flag in flags:
                if w[flag]:
                    wr._wake_readers()
                    break
        elif wr._waiting.unpack_from(mm, wr._waiting_at) != wr._nobody_waits:
            wr._wake_readers()


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
        self._capacity = capacity_bytes
        self._slot_seq = [0] * slots  # message each slot holds
        self._slot_words = [layout.slot_offset(s) // 8 for s in range(slots)]
        self._header_at = [layout.slot_offset(s) + _HEADER_AT for s in range(slots)]  # bytes
        mm = self._mm = self._seg.mm
        self._payload = [
            np.frombuffer(mm, np.uint8, capacity_bytes, layout.slot_offset(s) + HEADER_BYTES)
            for s in range(slots)
        ]
        self._raw = memoryview(mm)
        self._readers = [layout.reader_word(r) for r in range(max_readers)]
        self._waiting_words = [b + R_WAITING for b in self._readers]
        # what a message looks at, precomputed: each reader entry's (state, read_seq) words, its
        # pin word; every entry's waiting flag in one load (see _Loan.__exit__)
        self._entry_words = tuple((b + R_STATE, b + R_READ_SEQ) for b in self._readers)
        self._pin_words = tuple(b + R_PIN for b in self._readers)
        self._waiting = struct.Struct("q" + f"{8 * (READER_WORDS - 1)}xq" * (max_readers - 1))
        self._waiting_at = 8 * (self._readers[0] + R_WAITING)
        self._nobody_waits = (0,) * max_readers
        self._few_readers = max_readers <= 2
        self._last = -1  # the slot written last (-1: none yet)
        self._order = [-1] * slots  # the order words as written: message n's slot at n % slots
        self._out = [self._payload[s] for s in range(slots)]  # the last loan's view of each slot
        self._out_n = [capacity_bytes] * slots  # … and its length
        self._free_loan: _Loan | None = None  # a finished loan, handed out again by loan()
        self._n_slots = slots
        self._lossless = policy is Policy.LOSSLESS
        self._reader_fd = [-1] * max_readers
        self._fd_lock = threading.Lock()
        self._space_fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self._lru = list(range(slots))  # slots, least recently written first
        self._seq = 0
        self._loaned = False
        self._closed = False
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        self._sock.bind(socket_name(name, self._seg.generation))
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

    def _claim(self, timeout_s: float | None, nbytes: int = 0) -> int:
        """A slot to write message ``self._seq + 1`` (``nbytes``) into, marked as being written.

        The first pass takes no clock reading: the deadline (``timeout_s`` from now) starts when
        no slot is free, which is also the only case that waits.
        """
        w, slot_seq, lru = self._w, self._slot_seq, self._lru
        nxt = self._seq + 1
        lossless = self._lossless
        deadline: float | None = None
        last_check = 0.0
        spin_until = yield_from = 0
        while True:
            # one pass over the reader entries: the live ones, their pins, the lowest read
            # position of all and of the lossless ones (-1: no such reader; positions are ≥ 0)
            readers: list[int] = []
            pinned: list[int] = []
            read_by_all = need_free = -1
            for b in self._readers:
                if w[b + R_STATE] != 1:
                    continue
                readers.append(b)
                pinned.append(w[b + R_PIN])
                seq = w[b + R_READ_SEQ]
                if read_by_all < 0 or seq < read_by_all:
                    read_by_all = seq
                if lossless and w[b + R_POLICY] == _LOSSLESS and (need_free < 0 or seq < need_free):
                    need_free = seq
            if read_by_all >= 0:
                # a slot whose message every reader has read is of use to nobody: take the one
                # written last (just read, still in cache) rather than walking the whole ring
                for slot in reversed(lru):
                    if slot_seq[slot] > read_by_all or slot in pinned:
                        continue
                    if self._try_claim(slot, nxt, readers):
                        return slot
            for slot in lru:  # least recently written first
                if need_free >= 0 and slot_seq[slot] > need_free:
                    break  # the newer slots all hold unread lossless messages too
                if slot in pinned:
                    continue
                if self._try_claim(slot, nxt, readers):
                    return slot
            # no slot: only lossless back-pressure (or pins of dead readers) gets here
            now = time.monotonic()
            if not last_check:
                last_check = now
                deadline = None if timeout_s is None else now + timeout_s
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
            if now - last_check >= CHECK_S:
                last_check = now
                self._reap_dead_readers()
            t_ns = time.perf_counter_ns()
            if not spin_until and nbytes > LONG_WAIT_BYTES:
                spin_until = yield_from = t_ns + POLL_NS  # see LONG_WAIT_BYTES
            elif not spin_until:
                spin_until, yield_from = t_ns + SPIN_NS, t_ns + POLL_NS
            if t_ns < spin_until:
                if t_ns >= yield_from:
                    yield_cpu()  # see SPIN_NS
                continue  # poll the readers' positions a little before sleeping
            wait = CHECK_S if deadline is None else min(CHECK_S, deadline - now)
            w[W_WRITER_WAITING] = 1
            fence()  # the readers' read_seq stores are seen after this, or they see the flag
            floor = self._lossless_floor()
            if (-1 if floor is None else floor) == need_free and wait_fd(self._space_fd, wait):
                drain(self._space_fd)
            w[W_WRITER_WAITING] = 0

    def _try_claim(self, slot: int, nxt: int, readers: list[int]) -> bool:
        """Mark ``slot`` as being written (①②③); False (and unmarked) if a reader pins it."""
        w, begin = self._w, self._slot_words[slot] + S_BEGIN
        w[begin] = nxt  # ① the slot is being written
        fence()  # ②
        for b in readers:  # ③
            if w[b + R_PIN] == slot:
                w[begin] = self._slot_seq[slot]
                return False
        return True

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

    def _wake_readers(self) -> None:
        """Signal the eventfd of every reader whose waiting flag is up (it sleeps, or is about
        to)."""
        w = self._w
        for i, flag in enumerate(self._waiting_words):
            if w[flag]:
                with self._fd_lock:  # the attach thread may be replacing the descriptor
                    fd = self._reader_fd[i]
                    if fd >= 0:
                        os.eventfd_write(fd, 1)

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
        with self.loan(
            src.shape[0], stamp_ns=stamp_ns, kind=kind, meta=meta, timeout_s=timeout_s
        ) as out:
            np.copyto(out, src)  # ④
        return self._seq

    def loan(
        self,
        nbytes: int,
        *,
        stamp_ns: int = 0,
        kind: int = 0,
        meta: bytes = b"",
        timeout_s: float | None = 5.0,
    ) -> _Loan:
        """The next slot itself, ``nbytes`` long, to fill in place; published when the block
        ends without an exception (an exception abandons the slot, nothing is published)::

            with writer.loan(n, stamp_ns=t) as out:   # out: uint8 (n,), the slot's memory
                out[:] = ...
        """
        ln = self._free_loan
        if ln is None:  # the last one is still out (entered, or handed out and not entered yet)
            return _Loan(self, nbytes, stamp_ns, kind, meta, timeout_s)
        self._free_loan = None
        ln._nbytes, ln._stamp_ns, ln._kind, ln._meta = nbytes, stamp_ns, kind, meta
        ln._timeout_s, ln._slot = timeout_s, _PENDING
        return ln

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
        return channel_stats(self._seg, self.name)

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
        self._payload = self._out = []
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
