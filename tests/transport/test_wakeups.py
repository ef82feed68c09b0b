"""Waiting on a stream (a polling side yields the CPU, a sleeping reader is woken by the publish)
and the memory fence both sides call per message."""

from __future__ import annotations

import ctypes
import functools
import platform
import threading
import time
import uuid
from collections.abc import Iterator
from typing import Any

import pytest

from redrive.errors import TransportError
from redrive.transport import Policy, Reader, Writer, _fence, segment_path
from redrive.transport import reader as reader_module
from redrive.transport import writer as writer_module
from redrive.transport.segment import R_WAITING


@pytest.fixture
def name() -> Iterator[str]:
    stream = f"test.{uuid.uuid4().hex[:12]}"
    yield stream
    assert not segment_path(stream).exists(), f"{segment_path(stream)} left behind"


def _counting(monkeypatch: pytest.MonkeyPatch, module: Any) -> list[int]:
    calls = [0]

    def count() -> None:
        calls[0] += 1

    monkeypatch.setattr(module, "yield_cpu", count)
    monkeypatch.setattr(module, "SPIN_NS", 10**12)  # poll until the deadline
    monkeypatch.setattr(module, "POLL_NS", 0)  # yielding from the first poll
    return calls


def test_a_reader_polling_for_a_message_yields_the_cpu(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = _counting(monkeypatch, reader_module)
    with Writer(name, capacity_bytes=8, max_readers=1) as w, Reader(name) as r:
        with r.view(timeout_s=0.02) as msg:
            assert msg is None
        assert calls[0] >= 1
        w.publish(b"x")
        with r.view(timeout_s=1.0) as msg:  # there already: no poll
            assert msg is not None
        assert r.read(timeout_s=0.0) is None


def test_within_its_first_poll_ns_a_reader_polls_without_yielding(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = _counting(monkeypatch, reader_module)
    monkeypatch.setattr(reader_module, "POLL_NS", 10**12)
    with (
        Writer(name, capacity_bytes=8, max_readers=1),
        Reader(name) as r,
        r.view(timeout_s=0.02) as msg,
    ):
        assert msg is None
    assert calls[0] == 0


def test_a_writer_waiting_for_a_lossless_reader_yields_the_cpu(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = _counting(monkeypatch, writer_module)
    with (
        Writer(name, capacity_bytes=8, slots=3, max_readers=1, policy=Policy.LOSSLESS) as w,
        Reader(name) as r,
    ):
        for _ in range(3):
            w.publish(b"x")
        assert calls[0] == 0
        with pytest.raises(TransportError, match="lossless reader has not read"):
            w.publish(b"x", timeout_s=0.02)
        assert calls[0] >= 1
        assert r.read(timeout_s=0.0) is not None


def test_after_a_large_message_a_polling_reader_does_not_yield(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Yields only when the last message was at most LONG_WAIT_BYTES (here 4 bytes): after a
    larger one the next wait polls, then sleeps."""
    calls = _counting(monkeypatch, reader_module)
    monkeypatch.setattr(reader_module, "LONG_WAIT_BYTES", 4)
    with Writer(name, capacity_bytes=8, max_readers=1) as w, Reader(name) as r:
        w.publish(b"12345")  # 5 bytes: large
        with r.view(timeout_s=1.0) as msg:
            assert msg is not None
            assert bytes(msg.payload) == b"12345"
        with r.view(timeout_s=0.02) as msg:
            assert msg is None
        assert calls[0] == 0
        w.publish(b"1234")  # 4 bytes: small
        with r.view(timeout_s=1.0) as msg:
            assert msg is not None
        with r.view(timeout_s=0.02) as msg:
            assert msg is None
        assert calls[0] >= 1


@pytest.mark.parametrize(("nbytes", "yields"), [(4, True), (5, False)])
def test_a_writer_yields_only_before_a_small_message(
    name: str, monkeypatch: pytest.MonkeyPatch, nbytes: int, *, yields: bool
) -> None:
    calls = _counting(monkeypatch, writer_module)
    monkeypatch.setattr(writer_module, "LONG_WAIT_BYTES", 4)
    with (
        Writer(name, capacity_bytes=8, slots=3, max_readers=1, policy=Policy.LOSSLESS) as w,
        Reader(name) as r,
    ):
        for _ in range(3):
            w.publish(b"x" * nbytes)
        with pytest.raises(TransportError, match="lossless reader has not read"):
            w.publish(b"x" * nbytes, timeout_s=0.02)
        assert (calls[0] >= 1) is yields
        got = r.read(timeout_s=0.0)
        assert got is not None
        assert bytes(got.payload) == b"x" * nbytes


@pytest.mark.parametrize("max_readers", [1, 2, 3])
def test_a_sleeping_reader_in_any_entry_is_woken_by_the_publish(
    name: str, max_readers: int
) -> None:
    """The publish signals the eventfd of the reader whose waiting flag is up (the last entry
    here: with one or two entries the writer loads the flags one by one, beyond in one call)."""
    with Writer(name, capacity_bytes=8, slots=max_readers + 2, max_readers=max_readers) as w:
        busy = [Reader(name) for _ in range(max_readers - 1)]  # attached, never waiting
        sleeper = Reader(name)
        flag = w._readers[max_readers - 1] + R_WAITING
        woken = [0]
        wake = w._wake_readers

        def counted() -> None:
            woken[0] += 1
            wake()

        w._wake_readers = counted  # type: ignore[method-assign]
        got: list[int] = []

        def read() -> None:
            msg = sleeper.read(timeout_s=30.0)
            got.append(-1 if msg is None else msg.seq)

        thread = threading.Thread(target=read)
        thread.start()
        try:
            deadline = time.monotonic() + 30.0
            while not w._w[flag] and time.monotonic() < deadline:  # until it sleeps
                time.sleep(0.001)
            assert w._w[flag], "the reader never went to sleep"
            w.publish(b"wake")
            thread.join(30.0)
        finally:
            for r in (*busy, sleeper):
                if not thread.is_alive():
                    r.close()
        assert got == [1]
        assert woken[0] == 1


def _code(hex_bytes: str) -> tuple[Any, Any]:
    buf = ctypes.create_string_buffer(bytes.fromhex(hex_bytes), 32)
    return buf, ctypes.cast(buf, ctypes.CFUNCTYPE(None))  # read, never called


@pytest.mark.parametrize(
    ("code", "ignores"),
    [
        ("f30f1efa f048830c2400 c3", True),  # endbr64; lock orq $0,(%rsp); ret (GCC's libatomic)
        ("0faef0 c3", True),  # mfence; ret
        ("f0830c2400 c3", True),  # lock orl $0,(%rsp); ret
        ("83ff00 7405 f048830c2400 c3", False),  # cmp $0,%edi; je …: looks at the order
        ("c3", False),  # ret: no fence at all
    ],
)
def test_the_fence_is_called_without_its_order_only_where_its_code_ignores_it(
    code: str, ignores: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(_fence.platform, "machine", lambda: "x86_64")
    buf, func = _code(code.replace(" ", ""))
    assert _fence.ignores_its_order(func) is ignores
    monkeypatch.setattr(_fence.platform, "machine", lambda: "aarch64")
    assert not _fence.ignores_its_order(func)
    del buf


@pytest.mark.skipif(platform.machine() != "x86_64", reason="the code read is x86-64's")
def test_the_installed_libatomic_fence_is_called_without_an_argument() -> None:
    assert _fence.fence is not None
    assert not isinstance(_fence.fence, functools.partial)
    _fence.fence()
