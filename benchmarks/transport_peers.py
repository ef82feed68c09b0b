"""The peers of ``redrive bench transport``: ``multiprocessing.Queue``, ZeroMQ, eCAL and iceoryx2
as sides of the same benchmark (one sender and one receiver class each), and :data:`SIDES`, the
package's sides (redrive copy-out and in place, pipe + pickle) with these added.

``PYTHONPATH=src python -m benchmarks transport [--sides …]`` runs them (the cell machinery is
:mod:`redrive.benchmarks.transport`'s: each spawned child looks its side up in this module).

===================  ==========================================================================
side                 publisher → subscriber
===================  ==========================================================================
``mp-queue``         ``multiprocessing.Queue(maxsize=4)`` ``put(ndarray)`` → ``get()``
``zmq``              ZeroMQ PUSH → PULL over ``ipc://``, ``send(copy=False)`` /
                     ``recv(copy=False)`` (no copy in Python; the kernel copies through the socket)
``ecal``             eCAL 6 ``Publisher.send(bytes)`` → ``Subscriber`` receive callback, default
                     configuration (shared memory on one host; *lossy*: no back-pressure)
``iceoryx2``         iceoryx2 publish-subscribe of ``Slice[c_uint8]``: ``loan_slice_uninit``
                     (written in place) → ``receive`` (a view into shared memory), one event
                     notification per message to wake the subscriber
===================  ==========================================================================

``mp-queue`` and ``zmq`` hand over a reference and serialise later, so they rotate over
``slots + 1`` source arrays (``zmq`` also waits on the send tracker before reusing one). eCAL's
Python ``send`` takes only ``bytes``: the publisher passes ``array.tobytes()`` (one more copy,
which its API imposes). Every side has 4 slots / a queue depth of 4 (iceoryx2
``subscriber_max_buffer_size(4)``, ZeroMQ high-water marks 4, ``Queue(4)``); iceoryx2 is lossless
(no safe overflow, ``RetryUntilDelivered``, its publisher created before the subscriber — the other
order lost a block of samples after the first four in about one run in ten); eCAL's publisher
waits until it sees the subscriber, plus 0.2 s, and still usually loses the first message.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import queue
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from redrive.benchmarks.transport.sides import SIDES as PACKAGE_SIDES
from redrive.benchmarks.transport.sides import U8, CellConfig, SideSpec, _NoWait, _Payload, _Tally
from redrive.errors import TransportError

__all__ = ["CATALOGUE", "DEFAULT_SIDES", "PACKAGE_SIDES", "SIDES"]

#: this module, as the catalogue the spawned children look their side up in
CATALOGUE = __name__


class _QueueSender(_NoWait):
    def __init__(self, cfg: CellConfig, shared: Any) -> None:
        self.payload = _Payload(cfg)
        # put() pickles later, in the queue's feeder thread: a source array is reused only after
        # more than maxsize later puts succeeded, i.e. after the subscriber got it
        self.ring = [self.payload.new_source() for _ in range(cfg.slots + 1)]
        self.queue = shared

    def send(self, seq: int, stamp_ns: int) -> None:
        src = self.ring[seq % len(self.ring)] if seq >= 0 else self.ring[0].copy()
        self.payload.stamp(src, seq, stamp_ns)
        self.queue.put(src)

    def close(self) -> None:
        self.queue.close()
        self.queue.join_thread()


class _QueueReceiver:
    def __init__(self, cfg: CellConfig, shared: Any, tally: _Tally) -> None:
        self.queue = shared
        self.tally = tally

    def recv(self, timeout_s: float) -> bool:
        try:
            item = self.queue.get(timeout=timeout_s)
        except queue.Empty:
            return False
        self.tally.consume(item)
        return True

    def close(self) -> None:
        self.queue.close()


# -- ZeroMQ ----------------------------------------------------------------------------------------


def _zmq_address(cfg: CellConfig) -> str:
    return f"ipc://{Path(tempfile.gettempdir()) / f'redrive-bench-{cfg.endpoint}.ipc'}"


class _ZmqSender(_NoWait):
    def __init__(self, cfg: CellConfig, shared: Any) -> None:
        zmq: Any = importlib.import_module("zmq")
        self.payload = _Payload(cfg)
        self.ring = [self.payload.new_source() for _ in range(cfg.slots + 1)]
        self.trackers: list[Any] = [None] * len(self.ring)
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.PUSH)
        self.sock.setsockopt(zmq.SNDHWM, cfg.slots)
        self.sock.setsockopt(zmq.LINGER, 5000)
        self.sock.bind(_zmq_address(cfg))

    def send(self, seq: int, stamp_ns: int) -> None:
        i = seq % len(self.ring) if seq >= 0 else 0
        if self.trackers[i] is not None:
            self.trackers[i].wait()  # zmq still holds this buffer (copy=False)
        src = self.ring[i]
        self.payload.stamp(src, seq, stamp_ns)
        self.trackers[i] = self.sock.send(src, copy=False, track=True)

    def close(self) -> None:
        self.sock.close()
        self.ctx.term()


class _ZmqReceiver:
    def __init__(self, cfg: CellConfig, shared: Any, tally: _Tally) -> None:
        zmq: Any = importlib.import_module("zmq")
        self.tally = tally
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.PULL)
        self.sock.setsockopt(zmq.RCVHWM, cfg.slots)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.connect(_zmq_address(cfg))

    def recv(self, timeout_s: float) -> bool:
        if not self.sock.poll(round(timeout_s * 1000)):
            return False
        frame = self.sock.recv(copy=False)
        self.tally.consume(np.frombuffer(frame.buffer, np.uint8))
        return True

    def close(self) -> None:
        self.sock.close()
        self.ctx.term()


def _zmq_cleanup(cfg: CellConfig) -> None:
    with contextlib.suppress(FileNotFoundError):
        Path(_zmq_address(cfg).removeprefix("ipc://")).unlink()


# -- eCAL ------------------------------------------------------------------------------------------


def _ecal() -> Any:
    return importlib.import_module("ecal.nanobind_core")


class _EcalSender:
    def __init__(self, cfg: CellConfig, shared: Any) -> None:
        self.ecal = _ecal()
        self.ecal.initialize(f"redrive-bench-pub-{os.getpid()}")
        self.payload = _Payload(cfg)
        self.src = self.payload.new_source()
        self.pub = self.ecal.Publisher(f"redrive_bench_{cfg.endpoint}")

    def wait_connected(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while self.pub.get_subscriber_count() < 1:
            if time.monotonic() > deadline:
                msg = f"eCAL: no subscriber matched the topic in {timeout_s:g} s"
                raise TransportError(msg)
            time.sleep(0.01)
        time.sleep(0.2)  # registration is seen before the shared-memory connection is up

    def send(self, seq: int, stamp_ns: int) -> None:
        self.payload.stamp(self.src, seq, stamp_ns)
        self.pub.send(self.src.tobytes())  # the Python API takes only bytes

    def close(self) -> None:
        del self.pub
        self.ecal.finalize()


class _EcalReceiver:
    def __init__(self, cfg: CellConfig, shared: Any, tally: _Tally) -> None:
        self.ecal = _ecal()
        self.ecal.initialize(f"redrive-bench-sub-{os.getpid()}")
        self.tally = tally
        self.sub = self.ecal.Subscriber(f"redrive_bench_{cfg.endpoint}")

        def callback(_topic: Any, _datatype: Any, data: Any) -> None:
            tally.consume(data.buffer)

        self.sub.set_receive_callback(callback)

    def recv(self, timeout_s: float) -> bool:
        # the callback (an eCAL thread) consumes; this only waits for it
        got = self.tally.wake.wait(timeout_s)
        self.tally.wake.clear()
        return got

    def close(self) -> None:
        self.sub.remove_receive_callback()
        del self.sub
        self.ecal.finalize()


# -- iceoryx2 --------------------------------------------------------------------------------------


def _iox2_service(cfg: CellConfig) -> tuple[Any, Any, Any, Any]:
    import ctypes

    iox2: Any = importlib.import_module("iceoryx2")
    iox2.set_log_level(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    name = iox2.ServiceName.new(f"redrive/bench/{cfg.endpoint}")
    service = (
        node.service_builder(name)
        .publish_subscribe(iox2.Slice[ctypes.c_uint8])
        .subscriber_max_buffer_size(cfg.slots)
        .history_size(0)
        .enable_safe_overflow(False)  # lossless: back-pressure instead of overwriting
        .max_publishers(1)
        .max_subscribers(1)
        .open_or_create()
    )
    event = node.service_builder(name).event().open_or_create()
    return iox2, node, service, event


def _as_u8(ptr: int, nbytes: int) -> U8:
    import ctypes

    buf: Any = (ctypes.c_uint8 * nbytes).from_address(ptr)
    return np.frombuffer(buf, np.uint8)


class _Iox2Sender:
    def __init__(self, cfg: CellConfig, shared: Any) -> None:
        self.iox2, self.node, self.service, event = _iox2_service(cfg)
        self.payload = _Payload(cfg)
        self.size = cfg.size_bytes
        self.pub = (
            self.service.publisher_builder()
            .initial_max_slice_len(cfg.size_bytes)
            .allocation_strategy(self.iox2.AllocationStrategy.Static)
            .backpressure_strategy(self.iox2.BackpressureStrategy.RetryUntilDelivered)
            .create()
        )
        self.notifier = event.notifier_builder().create()

    def wait_connected(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while self.service.dynamic_config.number_of_subscribers < 1:
            if time.monotonic() > deadline:
                msg = f"iceoryx2: no subscriber connected in {timeout_s:g} s"
                raise TransportError(msg)
            time.sleep(0.01)
        self.pub.update_connections()

    def send(self, seq: int, stamp_ns: int) -> None:
        sample = self.pub.loan_slice_uninit(self.size)
        self.payload.fill(_as_u8(sample.payload_ptr, self.size), seq, stamp_ns)
        sample.assume_init().send()
        self.notifier.notify()

    def close(self) -> None:
        self.notifier.delete()
        self.pub.delete()
        del self.service, self.node


class _Iox2Receiver:
    def __init__(self, cfg: CellConfig, shared: Any, tally: _Tally) -> None:
        self.iox2, self.node, self.service, event = _iox2_service(cfg)
        self.tally = tally
        self.sub = self.service.subscriber_builder().create()
        self.listener = event.listener_builder().create()

    def recv(self, timeout_s: float) -> bool:
        sample = self.sub.receive()
        if sample is None:
            self.listener.timed_wait(self.iox2.Duration.from_secs_f64(timeout_s))
            sample = self.sub.receive()
            if sample is None:
                return False
        self.tally.consume(_as_u8(sample.payload_ptr, sample.payload().len()))
        sample.delete()
        return True

    def close(self) -> None:
        self.listener.delete()
        self.sub.delete()
        del self.service, self.node


def _iox2_cleanup(cfg: CellConfig) -> None:
    # a child that was killed leaves its node's files in /dev/shm and /tmp/iceoryx2
    iox2: Any = importlib.import_module("iceoryx2")
    iox2.set_log_level(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    node.try_cleanup_dead_nodes()
    del node


def _queue_shared(ctx: Any, cfg: CellConfig) -> Any:
    return ctx.Queue(maxsize=cfg.slots)


SIDES: Mapping[str, SideSpec] = {
    **PACKAGE_SIDES,
    **{
        s.name: s
        for s in (
            SideSpec(
                name="mp-queue", label="multiprocessing.Queue", module="multiprocessing",
                package="(standard library)", publisher_first=False, lossy=False, in_place=False,
                make_sender=_QueueSender, make_receiver=_QueueReceiver, make_shared=_queue_shared,
            ),
            SideSpec(
                name="zmq", label="ZeroMQ ipc, copy=False", module="zmq", package="pyzmq",
                publisher_first=False, lossy=False, in_place=False,
                make_sender=_ZmqSender, make_receiver=_ZmqReceiver, cleanup=_zmq_cleanup,
            ),
            SideSpec(
                name="ecal", label="eCAL shm (default, lossy)", module="ecal.nanobind_core",
                package="eclipse-ecal", publisher_first=False, lossy=True, in_place=False,
                make_sender=_EcalSender, make_receiver=_EcalReceiver,
            ),
            SideSpec(
                name="iceoryx2", label="iceoryx2, in place", module="iceoryx2", package="iceoryx2",
                # subscriber first lost a block of samples after the first 4 in ~1 run of 10, even
                # with RetryUntilDelivered; publisher first lost none in 36 runs
                publisher_first=True, lossy=False, in_place=True,
                make_sender=_Iox2Sender, make_receiver=_Iox2Receiver, cleanup=_iox2_cleanup,
            ),
        )
    },
}  # fmt: skip
DEFAULT_SIDES = tuple(SIDES)
