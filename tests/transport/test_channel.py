"""The shared-memory channel: round trips, policies, zero-copy views, faults, other interpreters."""

from __future__ import annotations

import dataclasses
import os
import signal
import stat
import subprocess
import sys
import threading
import time
import uuid
import zlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from redrive.errors import TransportError
from redrive.transport import (
    Message,
    Policy,
    ProducerGoneError,
    Reader,
    ReaderGoneError,
    Writer,
    remove_stale,
    segment_path,
    stale_segments,
)
from redrive.transport.stream import new_message
from tests.transport._peer import payload

SRC = Path(__file__).resolve().parents[2] / "src"
PEER = Path(__file__).with_name("_peer.py")
SYSTEM_PYTHON = Path("/usr/bin/python3")


@pytest.fixture
def name() -> Iterator[str]:
    """A fresh stream name; no segment of it may be left behind."""
    stream = f"test.{uuid.uuid4().hex[:12]}"
    yield stream
    assert not segment_path(stream).exists(), f"{segment_path(stream)} left behind"


class Peer:
    """A peer process (see _peer.py) with line-based stdin/stdout."""

    def __init__(self, *args: str, python: str = sys.executable) -> None:
        env = dict(os.environ, PYTHONPATH=f"{SRC}:{SRC.parent}")
        self.proc = subprocess.Popen(
            [python, str(PEER), *args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        self.expect("READY")

    def expect(self, word: str) -> None:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().strip()
        if line != word:
            err = (
                self.proc.stderr.read() if self.proc.stderr and self.proc.poll() is not None else ""
            )
            pytest.fail(f"peer said {line!r}, expected {word!r}\n{err}")

    def send(self, text: str = "") -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(text + "\n")
        self.proc.stdin.flush()

    def lines(self) -> list[str]:
        out, err = self.proc.communicate(timeout=60)
        assert self.proc.returncode == 0, err
        return out.splitlines()

    def kill(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)
        for f in (self.proc.stdin, self.proc.stdout, self.proc.stderr):
            if f is not None:
                f.close()


# -- in one process ---------------------------------------------------------------------------


def test_round_trip_copy_and_view(name: str) -> None:
    with Writer(name, capacity_bytes=1 << 16, slots=4, policy=Policy.LOSSLESS) as w:
        mode = stat.S_IMODE(os.stat(segment_path(name)).st_mode)
        assert mode == 0o600
        with Reader(name) as r:
            assert r.read(timeout_s=0.01) is None
            assert w.publish(b"first", stamp_ns=11, kind=3, meta=b"m") == 1
            msg = r.read(timeout_s=1.0)
            assert msg is not None
            assert (msg.seq, msg.stamp_ns, msg.kind, msg.meta) == (1, 11, 3, b"m")
            assert msg.payload.tobytes() == b"first"
            with w.loan(4, stamp_ns=12) as buf:
                buf[:] = np.frombuffer(b"abcd", np.uint8)
            with r.view(timeout_s=1.0) as view:
                assert view is not None
                assert view.payload.tobytes() == b"abcd"
                assert not view.payload.flags.writeable
            with r.view(timeout_s=0.01) as none:
                assert none is None
            buf = np.zeros(1 << 16, np.uint8)
            w.publish(b"into")
            into = r.read(timeout_s=1.0, out=buf)
            assert into is not None
            assert into.payload.tobytes() == b"into"
            assert np.shares_memory(into.payload, buf)
            w.publish(b"x")
            with pytest.raises(TransportError, match="at least 1 bytes"):
                r.read(timeout_s=1.0, out=np.zeros(0, np.uint8))
            stats = w.stats()
            assert stats.published == 4
            assert stats.readers[0].delivered == 3
            assert stats.readers[0].dropped == 0


def _fill_then_fail(w: Writer) -> None:
    with w.loan(8) as buf:
        buf[:] = 7
        raise ValueError("fill failed")


def test_loan_and_view_abandon_on_error_and_are_entered_once(name: str) -> None:
    w = Writer(name, capacity_bytes=64, slots=3, max_readers=1, policy=Policy.LOSSLESS)
    with w, Reader(name) as r:
        with pytest.raises(ValueError, match="fill failed"):
            _fill_then_fail(w)
        assert w.seq == 0  # abandoned: nothing published
        assert r.read(timeout_s=0.01) is None
        loan = w.loan(3, stamp_ns=5)
        with loan as buf:
            buf[:] = np.frombuffer(b"abc", np.uint8)
        with pytest.raises(TransportError, match="entered once"), loan:
            pass
        view = r.view(timeout_s=1.0)
        with view as msg:
            assert msg is not None
            assert (msg.seq, msg.stamp_ns, msg.payload.tobytes()) == (1, 5, b"abc")
            with pytest.raises(dataclasses.FrozenInstanceError):
                msg.seq = 2  # type: ignore[misc]
        with pytest.raises(TransportError, match="entered once"), view:
            pass
        for i in range(2, 6):
            w.publish(bytes([i]), stamp_ns=i)
            got = r.read(timeout_s=1.0)
            assert got is not None
            assert (got.seq, got.payload.tobytes()) == (i, bytes([i]))
        (stats,) = w.stats().readers
        assert (stats.read_seq, stats.delivered, stats.dropped, stats.torn) == (5, 5, 0, 0)
        assert 0 < stats.lag_last_ns <= stats.lag_max_ns
        assert 0 < stats.lag_mean_ns <= stats.lag_max_ns


def test_new_message_is_the_dataclass_message() -> None:
    payload = np.arange(4, dtype=np.uint8)
    fast = new_message(3, 11, 12, 2, b"m", payload, 1)
    slow = Message(
        seq=3, stamp_ns=11, publish_ns=12, kind=2, meta=b"m", payload=payload, dropped_before=1
    )
    assert type(fast) is Message
    for field in dataclasses.fields(Message):
        assert getattr(fast, field.name) is getattr(slow, field.name), field.name


def test_loans_and_views_handed_out_and_not_entered_keep_their_arguments(name: str) -> None:
    """The writer and the reader hand a finished loan / view out again (no object per message);
    one that is handed out and not entered yet is never the one handed out again."""
    with (
        Writer(name, capacity_bytes=64, slots=4, policy=Policy.LOSSLESS) as w,
        Reader(name) as r,
    ):
        with r.view(timeout_s=0.0) as nothing:  # a fresh reader's view that times out
            assert nothing is None
        first, second = w.loan(3, stamp_ns=10), w.loan(5, stamp_ns=20)
        with second as out:
            out[:] = 2
        with first as out:
            out[:] = 1
        with w.loan(2, stamp_ns=30) as out:
            out[:] = 3
        early, late = r.view(timeout_s=1.0), r.view(timeout_s=1.0)
        got = []
        for view in (late, early, r.view(timeout_s=1.0)):
            with view as msg:
                assert msg is not None
                got.append((msg.seq, msg.stamp_ns, msg.payload.tobytes()))
        assert got == [(1, 20, b"\2" * 5), (2, 10, b"\1" * 3), (3, 30, b"\3" * 2)]
        w.publish(b"abcd")
        with pytest.raises(TransportError, match="at least 4 bytes"):
            r.read(timeout_s=1.0, out=np.zeros(2, np.uint8))
        again = r.read(timeout_s=1.0)  # the refused read left it unread
        assert again is not None
        assert (again.seq, again.payload.tobytes()) == (4, b"abcd")


def test_without_readers_the_newest_message_is_kept_for_one_that_joins(name: str) -> None:
    """The writer reuses the slot written last only when readers have read it: with none
    attached, a reader that joins while the next message is being written gets the newest."""
    with Writer(name, capacity_bytes=64, slots=4) as w:
        w.publish(b"one", stamp_ns=1)
        with w.loan(3, stamp_ns=2) as out:
            out[:] = np.frombuffer(b"two", np.uint8)
            with Reader(name) as r:
                got: list[Message | None] = []
                reading = threading.Thread(
                    target=lambda: got.append(r.read(timeout_s=1.0)), daemon=True
                )
                reading.start()
                reading.join(timeout=5.0)
                assert got, "the reader never got a message"
                assert got[0] is not None
                assert (got[0].seq, got[0].payload.tobytes()) == (1, b"one")


def test_a_pinned_view_is_never_overwritten(name: str) -> None:
    """Keep-latest: the writer skips the slot a reader holds, however far it runs ahead."""
    with Writer(name, capacity_bytes=64, slots=3, max_readers=1) as w, Reader(name) as r:
        w.publish(np.full(64, 1, np.uint8))
        with r.view(timeout_s=1.0) as held:
            assert held is not None
            for i in range(2, 50):
                w.publish(np.full(64, i, np.uint8))
            assert (held.payload == 1).all()  # still message 1
        newest = r.read(timeout_s=1.0)
        assert newest is not None
        assert newest.seq == 49
        assert newest.dropped_before == 47
        assert int(newest.payload[0]) == 49


def test_a_slot_every_reader_has_read_is_reused_first(name: str) -> None:
    """A reader that keeps up gets every message through the same (cache-warm) slot; unread
    messages are never the ones overwritten."""
    with (
        Writer(name, capacity_bytes=64, slots=4, policy=Policy.LOSSLESS) as w,
        Reader(name) as r,
    ):
        addresses = set()
        for i in range(1, 9):
            w.publish(np.full(64, i, np.uint8))
            with r.view(timeout_s=1.0) as msg:
                assert msg is not None
                assert (msg.seq, int(msg.payload[0])) == (i, i)
                addresses.add(msg.payload.__array_interface__["data"][0])
        assert len(addresses) == 1
        for i in range(9, 12):  # unread: each takes another slot
            w.publish(np.full(64, i, np.uint8))
        got = [r.read(timeout_s=1.0) for _ in range(3)]
        assert [(m.seq, int(m.payload[0])) for m in got if m is not None] == [
            (9, 9),
            (10, 10),
            (11, 11),
        ]


def test_a_late_lossless_reader_skips_messages_no_longer_held(name: str) -> None:
    """Messages every attached reader had read may be overwritten before a new lossless reader
    joins: it starts at the oldest one still held and counts the rest as dropped."""
    with (
        Writer(name, capacity_bytes=64, slots=4, policy=Policy.LOSSLESS) as w,
        Reader(name) as first,
    ):
        for i in range(1, 11):
            w.publish(np.full(64, i, np.uint8))
            assert first.read(timeout_s=1.0) is not None
        with Reader(name, policy=Policy.LOSSLESS) as late:
            msg = late.read(timeout_s=1.0)
            assert msg is not None
            assert (msg.seq, int(msg.payload[0])) == (10, 10)
            assert msg.dropped_before == 2  # it joined at 7: 8 and 9 were overwritten
            w.publish(np.full(64, 11, np.uint8))
            nxt = late.read(timeout_s=1.0)
            assert nxt is not None
            assert (nxt.seq, nxt.dropped_before) == (11, 0)


@pytest.mark.parametrize("madvise", [True, False])
def test_a_reader_takes_no_page_fault_in_any_slot(
    name: str, monkeypatch: pytest.MonkeyPatch, *, madvise: bool
) -> None:
    """A reader populates its mapping when it joins (``MADV_POPULATE_READ``, or a byte of each
    page read where the kernel has none): its first view of each slot, every page touched,
    takes no page fault (unpopulated: 16 per 1 MiB slot with the kernel's fault-around, 66 in
    all here)."""
    import resource

    from redrive.transport import segment

    if not madvise:
        monkeypatch.setattr(segment, "_MADV_POPULATE_READ", -1)  # EINVAL, as an old kernel
    nbytes = 1 << 20
    with (
        Writer(name, capacity_bytes=nbytes, slots=4, policy=Policy.LOSSLESS, max_readers=1) as w,
        Reader(name) as r,
    ):
        for i in range(4):  # every slot holds an unread message
            w.publish(np.full(nbytes, i, np.uint8))
        sums = []
        before = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
        for _ in range(4):
            with r.view(timeout_s=1.0) as msg:
                assert msg is not None
                sums.append(int(np.add.reduce(msg.payload[::4096], dtype=np.uint64)))
        faults = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - before
    assert sums == [i * (nbytes // 4096) for i in range(4)]
    assert faults < 8  # the interpreter's own (a few); the slots' would be ≥ 64


def test_errors_say_what_to_do(name: str) -> None:
    with pytest.raises(TransportError, match="slots ≥ max_readers"):
        Writer(name, capacity_bytes=10, slots=2, max_readers=1)
    with pytest.raises(TransportError, match="letters, digits"):
        Writer("/velodyne_points", capacity_bytes=10)
    with pytest.raises(ProducerGoneError, match="start its producer first"):
        Reader(name, timeout_s=0.05)
    with Writer(name, capacity_bytes=10) as w:
        with pytest.raises(TransportError, match="already has a live writer"):
            Writer(name, capacity_bytes=10)
        with pytest.raises(TransportError, match="larger capacity_bytes"):
            w.publish(b"x" * 11)
        with pytest.raises(TransportError, match="cannot be read losslessly"):
            Reader(name, policy=Policy.LOSSLESS)
        with pytest.raises(RuntimeError), w.loan(5):
            raise RuntimeError
        assert w.seq == 0  # an abandoned loan publishes nothing


def test_lossless_back_pressure_times_out_clearly(name: str) -> None:
    with (
        Writer(name, capacity_bytes=8, slots=3, max_readers=1, policy=Policy.LOSSLESS) as w,
        Reader(name) as r,
    ):
        for _ in range(3):
            w.publish(b"12345678")
        start = time.monotonic()
        with pytest.raises(TransportError, match="lossless reader has not read"):
            w.publish(b"12345678", timeout_s=0.2)
        assert time.monotonic() - start >= 0.2
        assert [r.read(timeout_s=1.0).seq for _ in range(3)] == [1, 2, 3]  # type: ignore[union-attr]
        assert w.publish(b"12345678", timeout_s=0.2) == 4


@settings(max_examples=40, deadline=None)
@given(
    sizes=st.lists(st.integers(0, 5000), min_size=1, max_size=40),
    reads=st.lists(st.booleans(), min_size=1, max_size=80),
)
def test_any_writes_and_reads_round_trip_and_drops_equal_gaps(
    sizes: list[int], reads: list[bool]
) -> None:
    """Keep-latest, interleaved at random: every delivered message is byte-exact, sequence numbers
    rise, and the drop counter equals the gaps the reader saw."""
    stream = f"test.h{uuid.uuid4().hex[:10]}"
    rng = np.random.default_rng(len(sizes))
    sent: dict[int, bytes] = {}
    seen: list[int] = []
    with Writer(stream, capacity_bytes=5000, slots=4) as w, Reader(stream) as r:
        pending = list(sizes)
        for do_read in reads + [True] * 10:
            if not do_read and pending:
                data = rng.integers(0, 256, pending.pop(), dtype=np.uint8).tobytes()
                sent[w.publish(data)] = data
                continue
            msg = r.read(timeout_s=0)
            if msg is None:
                continue
            assert msg.payload.tobytes() == sent[msg.seq]
            assert msg.seq - (seen[-1] if seen else 0) - 1 == msg.dropped_before
            seen.append(msg.seq)
        stats = r.stats().readers[0]
        assert stats.delivered == len(seen)
        last = seen[-1] if seen else 0
        assert stats.dropped == last - len(seen)
    assert not segment_path(stream).exists()


# -- between processes -------------------------------------------------------------------------


def _check_lines(lines: list[str], seed: int, count: int) -> None:
    got = [tuple(int(v) for v in line.split()) for line in lines if line[0].isdigit()]
    assert [s for s, _ in got] == list(range(1, count + 1))
    for seq, crc in got:
        assert crc == zlib.crc32(payload(seed, seq)), seq


def test_lossless_between_processes_delivers_every_message(name: str) -> None:
    writer = Peer("write", name, "300", "5", "LOSSLESS")
    try:
        reader = Peer("read", name, "300", "LOSSLESS")
        writer.send()  # go
        _check_lines(reader.lines(), seed=5, count=300)
        writer.expect("DONE")
        writer.send()
        assert writer.proc.wait(timeout=10) == 0
    finally:
        if writer.proc.poll() is None:
            writer.kill()


def test_reader_here_writer_there_in_place_views(name: str) -> None:
    writer = Peer("write", name, "200", "9", "LOSSLESS")
    try:
        with Reader(name) as r:
            writer.send()
            for seq in range(1, 201):
                with r.view(timeout_s=10.0) as msg:
                    assert msg is not None
                    assert msg.seq == seq
                    assert zlib.crc32(msg.payload) == zlib.crc32(payload(9, seq))
            writer.expect("DONE")
            writer.send()
            assert writer.proc.wait(timeout=10) == 0
            with pytest.raises(ProducerGoneError, match="is gone"):
                r.read(timeout_s=1.0)
    finally:
        if writer.proc.poll() is None:
            writer.kill()


@pytest.mark.skipif(
    not SYSTEM_PYTHON.is_file()
    or subprocess.run([str(SYSTEM_PYTHON), "-c", "import numpy"], check=False).returncode != 0,
    reason="/usr/bin/python3 with numpy is not here (make system-test-deps installs python3-numpy)",
)
def test_writer_under_the_system_python(name: str) -> None:
    """The ROS scraper's side: a writer under Debian's /usr/bin/python3, the reader here."""
    writer = Peer("write", name, "100", "3", "LOSSLESS", python=str(SYSTEM_PYTHON))
    try:
        with Reader(name) as r:
            writer.send()
            got = [r.read(timeout_s=10.0) for _ in range(100)]
            for seq, msg in enumerate(got, start=1):
                assert msg is not None
                assert msg.seq == seq
                assert msg.payload.tobytes() == payload(3, seq).tobytes()
            writer.expect("DONE")
            writer.send()
            assert writer.proc.wait(timeout=10) == 0
    finally:
        if writer.proc.poll() is None:
            writer.kill()


def test_writer_killed_mid_write_never_yields_a_torn_message(name: str) -> None:
    hang = Peer("hang", name)  # one message published, the second half-written in its slot
    with Reader(name, policy=Policy.KEEP_LATEST) as r:
        first = r.read(timeout_s=1.0)
        assert first is not None
        assert first.seq == 1
        hang.kill()
        start = time.monotonic()
        with pytest.raises(ProducerGoneError, match="is gone"):
            r.read(timeout_s=5.0)
        assert time.monotonic() - start < 1.0  # noticed within the liveness check period
        assert r.stats().readers[0].torn == 0
    assert segment_path(name) in stale_segments()
    assert remove_stale(name) == [segment_path(name)]


def test_newest_message_torn_by_a_killed_writer_ends_the_read(name: str) -> None:
    """A keep-latest reader that joins while the writer reuses the slot of the newest message
    (every reader then had read it) finds that message being rewritten; the writer is killed
    there. The read must notice the writer is gone, not retry the torn message for ever."""
    from redrive.transport.segment import S_BEGIN, W_ORDER, W_WRITE_SEQ

    hang = Peer("hang", name)  # message 1 published, message 2 half-written in another slot
    with Reader(name, policy=Policy.KEEP_LATEST) as r:
        w = r._w
        newest = int(w[W_WRITE_SEQ])
        assert newest == 1
        slot = int(w[W_ORDER + newest % r._n_slots])
        w[r._slot_words[slot] + S_BEGIN] = newest + 1  # the writer began rewriting it ...
        hang.kill()  # ... and died there
        outcome: list[object] = []

        def read() -> None:
            try:
                outcome.append(r.read(timeout_s=5.0))
            except ProducerGoneError as err:
                outcome.append(err)

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        reader.join(timeout=10.0)
        assert not reader.is_alive(), "the read spins on a torn message of a dead writer"
        assert len(outcome) == 1
        assert isinstance(outcome[0], ProducerGoneError)
    remove_stale(name)


def test_writer_restart_reattaches_the_reader(name: str) -> None:
    first = Peer("write", name, "5", "1", "LOSSLESS")
    with Reader(name) as r:
        first.send()
        assert [r.read(timeout_s=5.0).seq for _ in range(5)] == [1, 2, 3, 4, 5]  # type: ignore[union-attr]
        first.kill()  # killed: its segment is stale
        with pytest.raises(ProducerGoneError):
            r.read(timeout_s=1.0)
        second = Peer("write", name, "5", "2", "LOSSLESS")  # removes the stale segment
        try:
            second.send()
            msgs = [r.read(timeout_s=5.0) for _ in range(5)]
            assert [m.seq for m in msgs if m] == [1, 2, 3, 4, 5]
            assert msgs[0] is not None
            assert msgs[0].payload.tobytes() == payload(2, 1).tobytes()
            second.expect("DONE")
            second.send()
            assert second.proc.wait(timeout=10) == 0
        finally:
            if second.proc.poll() is None:
                second.kill()


def test_reader_killed_keep_latest_writer_goes_on_and_a_new_reader_attaches(name: str) -> None:
    with Writer(name, capacity_bytes=200_000, slots=4, max_readers=1) as w:
        reader = Peer("read", name, "1000", "KEEP_LATEST")
        w.publish(payload(0, 1))
        reader.kill()
        for seq in range(2, 30):  # the dead reader's pin and entry do not stop the writer
            w.publish(payload(0, seq))
        # its entry is free again (max_readers=1)
        with Reader(name, timeout_s=2.0) as again:
            msg = again.read(timeout_s=1.0)
            assert msg is not None
            assert msg.seq == 29


def test_reader_killed_lossless_writer_fails_clearly(name: str) -> None:
    with Writer(name, capacity_bytes=200_000, slots=3, max_readers=1, policy=Policy.LOSSLESS) as w:
        reader = Peer("read", name, "1000", "LOSSLESS")
        reader.kill()
        for seq in range(1, 4):  # three slots fill without the reader
            w.publish(payload(0, seq), timeout_s=5.0)
        with pytest.raises(ReaderGoneError, match=r"lossless reader pid \d+ exited"):
            w.publish(payload(0, 4), timeout_s=5.0)
        assert w.publish(payload(0, 99), timeout_s=1.0) > 0  # no reader left: goes on
