"""A reader of a shared-memory stream: attaches to its segment, pins and copies out or views
messages, re-checks them for tearing (see :mod:`redrive.transport.channel` for the protocol and
the numbered steps).
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import struct
import time
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import TransportError
from redrive.transport._fence import WEAK_ORDERING, fence
from redrive.transport.segment import (
    HEADER_BYTES,
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
    S_META_LEN,
    S_NBYTES,
    S_STAMP,
    W_ORDER,
    W_POLICY,
    W_WRITE_SEQ,
    W_WRITER_WAITING,
    Segment,
    process_alive,
    self_identity,
)
from redrive.transport.stream import (
    CHECK_S,
    LONG_WAIT_BYTES,
    POLL_NS,
    SPIN_NS,
    ChannelStats,
    Message,
    MessageSlots,
    Policy,
    ProducerGoneError,
    channel_stats,
    drain,
    new_message,
    socket_name,
    wait_fd,
    yield_cpu,
)
from redrive.types import SensorData

__all__ = ["Reader"]

logger = logging.getLogger(__name__)

_time_ns = time.time_ns
_new_object = object.__new__
#: a slot's header words stamp_ns, publish_ns, kind, nbytes, meta_len, read with one call
_HEADER = struct.Struct("5q")
_HEADER_AT = 8 * S_STAMP
#: a slot's seq_begin, seq_end and header words, read with one call (in address order)
_SLOT_HEAD = struct.Struct(f"q{8 * (S_END - S_BEGIN) - 8}xq{8 * (S_STAMP - S_END) - 8}x5q")
#: a reader entry's words read_seq, pin, delivered, dropped, torn, lag_last, lag_max, lag_sum,
#: capture_lag (native int64, each stored whole), written with one call
_ENTRY = struct.Struct("9q")


_PENDING, _DONE = -2, -3  # a view's state when it holds no slot: handed out / finished


class _View:
    """What :meth:`Reader.view` returns: pins the next message on ``__enter__``, re-checks and
    unpins it on ``__exit__`` (a class, not a generator: no generator frame per message). The
    reader hands the same object out again once it is finished; ``_slot`` is the state:
    ``_PENDING`` (handed out, not entered), the slot (entered; -1 after a timeout),
    ``_DONE``."""

    __slots__ = (
        "_dropped",
        "_intact",
        "_latest",
        "_msg",
        "_reader",
        "_seq",
        "_slot",
        "_timeout_s",
    )

    def __init__(self, reader: Reader, timeout_s: float | None, latest: bool) -> None:
        self._reader, self._timeout_s, self._latest = reader, timeout_s, latest
        self._slot = _PENDING
        self._msg: Message | None = None
        self._intact = False  # whether the message was whole when it was released
        self._seq = self._dropped = 0

    def __enter__(self) -> Message | None:
        rd = self._reader
        if self._slot != _PENDING:
            err = f"stream {rd.name!r}: a view is entered once; call reader.view() again"
            raise TransportError(err)
        slot = -1
        if rd._ready and not self._latest:
            # the fast path (ⓐ–ⓕ): the next message is there, within a ring of this reader's
            # position, and its slot still holds it; anything else goes through _next
            w, rs = rd._w, rd._read_seq
            ws = w[W_WRITE_SEQ]  # ⓐ
            if WEAK_ORDERING:
                fence()  # ⓑ
            seq = rs + 1
            if seq <= ws <= rs + rd._n_slots:
                slot = w[W_ORDER + seq % rd._n_slots]  # ⓒ
                w[rd._pin_word] = slot  # ⓓ
                fence()  # ⓔ
                # ⓕ seq_begin and seq_end, and with them the header (used only if they match)
                begin, end, stamp_ns, publish_ns, kind, nbytes, meta_len = _SLOT_HEAD.unpack_from(
                    rd._mm, rd._slot_bytes[slot]
                )
                if begin != seq or end != seq:
                    w[rd._pin_word] = -1
                    slot = -1
        if slot < 0:
            slot, seq, dropped = rd._next(self._timeout_s, self._latest)
            if slot < 0:
                self._slot = slot
                return None
            stamp_ns, publish_ns, kind, nbytes, meta_len = _HEADER.unpack_from(
                rd._mm, rd._slot_bytes[slot] + _HEADER_AT
            )
        else:
            dropped = 0
        self._slot, self._seq, self._dropped = slot, seq, dropped
        if rd._view_n[slot] != nbytes:  # the slot's read-only view of this length, made once
            rd._view_n[slot] = nbytes
            rd._views[slot] = rd._payload[slot][:nbytes]
        msg: Any = _new_object(MessageSlots)  # as new_message, without its call
        msg.seq = seq
        msg.stamp_ns = stamp_ns
        msg.publish_ns = publish_ns
        msg.kind = kind
        msg.meta = rd._meta(rd._slot_words[slot]) if meta_len else b""
        msg.payload = rd._views[slot]
        msg.dropped_before = dropped
        msg.__class__ = Message
        done: Message = msg
        self._msg = done
        return done

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        msg, rd, slot = self._msg, self._reader, self._slot
        self._slot = _DONE
        if msg is None:  # timed out: nothing pinned
            rd._free_view = self
            return
        self._msg, seq = None, self._seq
        # re-check the slot (ⓗⓘ), unpin it (ⓙ), count. This reader is the only writer of its
        # entry's counters (the writer only frees the entry of a dead reader): it keeps their
        # running values and stores them, with read_seq and the pin, in one call (ⓙ: the words
        # in address order, read_seq before the pin — a writer that sees the position before the
        # unpin takes another slot)
        w = rd._w
        if WEAK_ORDERING:
            fence()  # ⓗ
        base = rd._slot_words[slot]
        intact = self._intact = w[base] == seq and w[base + S_END] == seq  # ⓘ (S_BEGIN: +0)
        rd._read_seq = seq
        if intact:
            now = _time_ns()
            lag = rd._lag_last = now - msg.publish_ns
            rd._delivered += 1
            rd._lag_sum += lag
            if lag > rd._lag_max:  # noqa: PLR1730 — max() is a call per message
                rd._lag_max = lag
            rd._capture_lag = now - msg.stamp_ns if msg.stamp_ns else lag
        else:
            rd._torn += 1
        if self._dropped:
            rd._dropped += self._dropped
        _ENTRY.pack_into(
            rd._mm, rd._counters_at, seq, -1,  # read_seq, pin (unpinned)
            rd._delivered, rd._dropped, rd._torn, rd._lag_last, rd._lag_max, rd._lag_sum,
            rd._capture_lag,
        )  # fmt: skip
        if rd._wake_writer:
            fence()  # read_seq is seen by a writer before it sleeps, or its flag is seen here
            if w[W_WRITER_WAITING]:
                os.eventfd_write(rd._space_fd, 1)
        rd._free_view = self


class Reader:
    """A reader of stream ``name`` (waits up to ``timeout_s`` for the writer to create it).

    Args:
        policy: how this reader reads: the stream's policy by default; ``KEEP_LATEST`` on a
            lossless stream observes it without back-pressure.
        backlog: for a keep-latest reader: start at the oldest message the ring still holds,
            and when the writer laps it, go on from the oldest one still held rather than the
            newest. It never slows the writer either, and loses only what was overwritten: for a
            stream whose history matters more than its freshness (a 100-Hz ego state that frames
            are interpolated in), where the default skips to the newest message.

    Raises:
        TransportError: no such stream within ``timeout_s``; every reader entry taken; a
            lossless reader asked of a keep-latest stream.
    """

    def __init__(
        self,
        name: str,
        *,
        timeout_s: float = 5.0,
        policy: Policy | None = None,
        backlog: bool = False,
    ) -> None:
        self.name = name
        self._want_policy = policy
        self._backlog = backlog
        self._seg: Segment | None = None
        self._fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self._space_fd = -1
        self._closed = False
        self._ready = False  # attached and open: the fast paths may run
        self._free_view: _View | None = None  # a finished view, handed out again by view()
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
            if policy is Policy.LOSSLESS or self._backlog:
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
        self._n_slots = lay.n_slots
        self.policy = policy
        self._lossless = policy is Policy.LOSSLESS
        # this entry's counters (zeroed above), kept here and stored whole (see _View.__exit__)
        self._delivered = self._dropped = self._torn = self._lag_sum = self._lag_max = 0
        self._lag_last = self._capture_lag = 0
        self._base = base
        self._pin_word = base + R_PIN
        self._wake_writer = False  # set by _handshake, once the writer's eventfd is known
        self._counters_at = 8 * (base + R_READ_SEQ)
        self._read_seq = start_seq
        self._slot_words = [lay.slot_offset(s) // 8 for s in range(lay.n_slots)]
        self._slot_bytes = [lay.slot_offset(s) for s in range(lay.n_slots)]
        self._payload = [
            np.frombuffer(seg.mm, np.uint8, lay.capacity, lay.slot_offset(s) + HEADER_BYTES)
            for s in range(lay.n_slots)
        ]
        for arr in self._payload:
            arr.flags.writeable = False
        self._views = list(self._payload)  # the last view's array of each slot
        self._view_n = [lay.capacity] * lay.n_slots  # … and its length
        self._mm = seg.mm
        self._raw = memoryview(seg.mm)
        seg.populate()
        self._handshake(entry, seg.generation)
        self._ready = True

    def _handshake(self, entry: int, generation: int) -> None:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC) as sock:
            sock.settimeout(5.0)
            try:
                sock.connect(socket_name(self.name, generation))
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
        self._wake_writer = self._lossless

    def _detach(self) -> None:
        seg = self._seg
        if seg is None:
            return
        self._ready = False
        self._w[self._base + R_PIN] = -1
        self._w[self._base + R_STATE] = 0
        self._payload = self._views = []
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
        """Pin the next message: (slot, seq, dropped before it).

        A message already there costs no clock reading: the deadline (``timeout_s`` from now)
        starts when there is none.
        """
        if self._closed:
            msg = f"reader of stream {self.name!r} is closed"
            raise TransportError(msg)
        if self._seg is None:
            self._attach(time.monotonic() + (timeout_s or 0.0))
        deadline: float | None = None
        last_check = 0.0
        jump = latest
        skip_to = 0  # a lossless or backlog reader's first message still held (see below)
        spin_until = yield_from = 0
        # A message this call failed to pin twice in a row: its slot is being written again. A
        # keep-latest reader that joined while the writer reused the newest message's slot (every
        # reader then had read it) can want that message; a live writer soon publishes a newer
        # one, a killed one never does — so it is not retried until write_seq moves, and the
        # liveness check below runs meanwhile.
        failed = stuck = -1
        while True:
            w, n_slots = self._w, self._n_slots
            ws = w[W_WRITE_SEQ]  # ⓐ
            if WEAK_ORDERING:
                fence()  # ⓑ
            rs = self._read_seq
            if ws > rs and ws != stuck:
                if jump:
                    want = ws
                elif ws - rs <= n_slots:
                    want = max(rs + 1, skip_to)
                else:  # a ring behind: the newest, or with a backlog the oldest still held
                    want = max(ws - n_slots + 1, skip_to) if self._backlog else ws
                slot = w[W_ORDER + want % n_slots]  # ⓒ
                pin = self._base + R_PIN
                w[pin] = slot  # ⓓ
                fence()  # ⓔ
                base = self._slot_words[slot]
                if w[base + S_BEGIN] == want and w[base + S_END] == want:  # ⓕ
                    return slot, want, want - rs - 1
                w[pin] = -1
                if self._backlog and not self._lossless:
                    skip_to = min(want + 1, ws)  # overwritten meanwhile: the next oldest
                elif not self._lossless:
                    jump = True  # overwritten meanwhile: newest
                elif w[base + S_END] > want:
                    # overwritten before this reader's position was seen (it joined while the
                    # writer reused a slot every reader then had read): gone, counted as dropped
                    skip_to = want + 1
                if want == failed:
                    stuck = ws  # see above
                failed = want
                continue
            now = time.monotonic()
            if not last_check:
                last_check = now
                deadline = None if timeout_s is None else now + timeout_s
            if now - last_check >= CHECK_S or (deadline is not None and now >= deadline):
                last_check = now
                if self._seg is not None and not self._seg.owner_alive():
                    if w[W_WRITE_SEQ] > self._read_seq and stuck < 0:
                        continue  # it left messages behind: deliver them first
                    self._reattach_or_raise()
                    failed = stuck = -1
                    continue
            if deadline is not None and now >= deadline:
                return -1, 0, 0
            t_ns = time.perf_counter_ns()
            if not spin_until:
                last = w[W_ORDER + rs % n_slots] if rs > 0 else -1  # rs's slot (or its next's)
                if last >= 0 and w[self._slot_words[last] + S_NBYTES] > LONG_WAIT_BYTES:
                    spin_until = yield_from = t_ns + POLL_NS  # see LONG_WAIT_BYTES
                else:
                    spin_until, yield_from = t_ns + SPIN_NS, t_ns + POLL_NS
            if t_ns < spin_until:
                if t_ns >= yield_from:
                    yield_cpu()  # see SPIN_NS
                continue  # poll write_seq a little before sleeping
            wait = CHECK_S if deadline is None else min(CHECK_S, deadline - now)
            flag = self._base + R_WAITING
            w[flag] = 1
            fence()  # the writer sees the flag after this, or its write_seq is seen below
            if w[W_WRITE_SEQ] in (self._read_seq, stuck) and wait_fd(self._fd, wait):
                drain(self._fd)
            w[flag] = 0

    def _meta(self, base: int) -> bytes:
        """The meta bytes of the slot whose header starts at word ``base``."""
        off = base * 8 + META_OFFSET
        return bytes(self._raw[off : off + self._w[base + S_META_LEN]])

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
            vw = _View(self, timeout_s, latest)  # its own: a view handed out stays as it is
            got = vw.__enter__()
            if got is None:
                return None
            nbytes = got.payload.shape[0]
            if out is None:
                copy = np.empty(nbytes, np.uint8)
            elif out.dtype == np.uint8 and out.ndim == 1 and out.shape[0] >= nbytes:
                copy = out[:nbytes]
            else:
                self._w[self._pin_word] = -1  # unread: the next read gives it again
                msg_text = (
                    f"stream {self.name!r}: read(out=…) needs a 1-D uint8 array of at least "
                    f"{nbytes} bytes"
                )
                raise TransportError(msg_text)
            np.copyto(copy, got.payload)  # ⓖ
            vw.__exit__(None, None, None)
            if vw._intact:
                return new_message(
                    got.seq,
                    got.stamp_ns,
                    got.publish_ns,
                    got.kind,
                    got.meta,
                    copy,
                    got.dropped_before,
                )

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

    def view(self, timeout_s: float | None = None, *, latest: bool = False) -> _View:
        """The next message as a read-only view into shared memory, valid inside the block
        (the slot is pinned: the writer does not reuse it meanwhile). Gives None on timeout::

            with reader.view(timeout_s=1.0) as msg:   # msg: Message | None
                ...
        """
        vw = self._free_view
        if vw is None:  # the last one is still out (entered, or handed out and not entered yet)
            return _View(self, timeout_s, latest)
        self._free_view = None
        vw._timeout_s, vw._latest, vw._slot = timeout_s, latest, _PENDING
        return vw

    def stats(self) -> ChannelStats:
        if self._seg is None:
            return ChannelStats(name=self.name, published=0, readers=())
        return channel_stats(self._seg, self.name)

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
        self._ready = False
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
