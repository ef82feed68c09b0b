"""The Sensor Data Scraper for one ROS 1 topic: rospy in, shared memory out.

Runs as its own process under Debian's ``/usr/bin/python3`` (rospy imports nowhere else), started
by :func:`redrive.live.session.start_ros1_scraper` as a *script* (``python3 ros1_scraper.py``) so
that only :mod:`redrive.transport` (numpy + stdlib) is imported, never the rest of redrive.

It subscribes with ``rospy.AnyMsg`` — the message arrives as the serialised bytes the publisher
sent, and is not deserialised here — and publishes each one into the stream as a
:data:`~redrive.transport.codec.KIND_ROS1` message (topic, type and md5sum in the meta, the
receive time as its stamp). The core decodes it with redrive's decoders.

The message is received straight into its shared-memory slot: :func:`receive_in_place` replaces
rospy's read loop for ``AnyMsg`` subscriptions (``recv`` into a fresh bytes object, appended to a
``BytesIO``, sliced out again — three copies and two allocations of every message) by reading
the 4-byte length, loaning the next slot of the stream and ``recv_into`` it; the kernel's copy
is the only one. rospy's connection handling (handshake, reconnects, the master) is untouched.

If the ROS master restarts (its pid changes), the subscription is registered anew with the new
master. SIGTERM/SIGINT stop it, and so does the death of the process that started it; the stream's segment is unlinked on every exit path.

Usage: ``python3 ros1_scraper.py --topic /velodyne_points --stream live-1.velodyne_points
--capacity 4000000 [--policy lossless] [--slots 8] [--await-lossless 20]``; prints ``READY``
once subscribed (with ``--await-lossless``: ``STREAM`` first, and it subscribes once a recorder
reads the stream).
"""

from __future__ import annotations

import argparse
import errno
import json
import logging
import os
import signal
import struct
import sys
import threading
import time
import xmlrpc.client
from collections.abc import Callable
from typing import Any

logger = logging.getLogger("redrive.live.ros1_scraper")

#: ask the master whether it restarted every this many 0.25-s ticks (once a second)
_MASTER_EVERY = 4
#: rospy's socket read size: below glibc's mmap threshold as raised by keep_freed_memory (a
#: read buffer of 64 MiB was a fresh mmap for every read)
_RECV_BYTES = 4 << 20
_LENGTH = struct.Struct("<I")

#: ``deliver(transport, size, read_into)``: receive one message of ``size`` bytes of the
#: connection ``transport``; ``read_into(view)`` fills a writable byte view of that size from it
Deliver = Callable[[Any, int, Callable[[Any], None]], None]


def receive_in_place(rospy: Any, deliver: Deliver) -> None:
    """Make rospy's TCPROS connections of ``AnyMsg`` subscribers hand each message's length to
    ``deliver`` and let it read the bytes where they belong (see the module text); rospy's own
    callbacks then get nothing. Other connections keep rospy's read loop."""
    from rospy.impl.tcpros_base import TCPROSTransport, TransportTerminated

    original = TCPROSTransport.receive_once

    def fill(transport: Any, view: memoryview) -> None:
        got = 0
        carry = transport.read_buff  # bytes that came with the handshake, read first
        if carry.tell():
            data = carry.getvalue()[: carry.tell()]
            got = min(len(data), len(view))
            view[:got] = data[:got]
            carry.seek(0)
            carry.truncate(0)
            carry.write(data[got:])
        sock = transport.socket
        while got < len(view):
            try:
                n = sock.recv_into(view[got:])
            except OSError as err:
                if err.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                    continue
                text = "unable to receive data from sender, check sender's logs for details"
                raise TransportTerminated(text) from err
            if n == 0:
                text = "unable to receive data from sender, check sender's logs for details"
                raise TransportTerminated(text)
            got += n

    def receive_once(self: Any) -> list[Any]:
        if getattr(self.protocol, "recv_data_class", None) is not rospy.AnyMsg:
            return original(self)  # type: ignore[no-any-return]
        if self.socket is None or self.done or rospy.is_shutdown():
            return original(self)  # type: ignore[no-any-return]  # rospy's own answer
        self.socket.setblocking(1)
        length = bytearray(4)
        fill(self, memoryview(length))
        (size,) = _LENGTH.unpack(length)
        deliver(self, size, lambda view: fill(self, memoryview(view).cast("B")))
        self.stat_bytes += 4 + size
        self.stat_num_msg += 1
        return []

    TCPROSTransport.receive_once = receive_once


def _master_pid(uri: str) -> int | None:
    try:
        answer: Any = xmlrpc.client.ServerProxy(uri).getPid("/redrive_scraper")
        code, _, pid = answer
    except (OSError, xmlrpc.client.Error, ValueError):
        return None
    return int(pid) if code == 1 else None


def _publishers(sub: Any) -> list[str]:
    """The caller ids of the publishers this subscriber has an open connection to."""
    impl = getattr(sub, "impl", None)
    connections = list(getattr(impl, "connections", ()) or ())
    return sorted(
        str(getattr(c, "callerid_pub", "unknown"))
        for c in connections
        if not getattr(c, "done", False)
    )


def _ignore(_msg: Any) -> None:
    """rospy's callback: :func:`receive_in_place` delivers every message before it."""


def main(argv: list[str] | None = None) -> int:
    import rospy

    from redrive.errors import TransportError
    from redrive.transport import Policy, ReaderGoneError, Writer
    from redrive.transport.codec import KIND_ROS1, encode_ros1_meta
    from redrive.transport.heap import keep_freed_memory

    keep_freed_memory()  # rospy's per-message buffers reuse warm pages (redrive.transport.heap)

    parser = argparse.ArgumentParser(prog="ros1_scraper", description=__doc__)
    parser.add_argument("--topic", required=True)
    parser.add_argument("--stream", required=True)
    parser.add_argument("--capacity", type=int, required=True, help="largest message, bytes")
    parser.add_argument("--policy", choices=("keep_latest", "lossless"), default="lossless")
    parser.add_argument("--slots", type=int, default=8)
    # the dispatcher, the recorder and the Foxglove live view
    parser.add_argument("--max-readers", type=int, default=3)
    parser.add_argument("--timeout", type=float, default=5.0, help="lossless back-pressure, s")
    parser.add_argument(
        "--await-lossless",
        type=float,
        default=0.0,
        metavar="S",
        help="print STREAM once the stream exists, and subscribe only once a lossless reader "
        "(a recorder) attached, up to S seconds: no message is published before it reads",
    )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s scraper %(message)s")

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    writer = Writer(
        args.stream,
        capacity_bytes=args.capacity,
        slots=args.slots,
        policy=Policy.LOSSLESS if args.policy == "lossless" else Policy.KEEP_LATEST,
        max_readers=args.max_readers,
    )
    counts = {"received": 0, "published": 0, "failed": 0}
    meta: list[bytes] = []
    lock = threading.Lock()

    send = threading.Lock()  # one connection at a time fills the stream's next slot
    scratch = bytearray()  # a message that cannot be forwarded is read into this

    def deliver(transport: Any, size: int, read_into: Callable[[Any], None]) -> None:
        now = time.time_ns()
        with lock:
            counts["received"] += 1
            received = counts["received"]
            if not meta:
                header = transport.header
                meta.append(encode_ros1_meta(args.topic, header["type"], header["md5sum"]))
                # the full definition, for a recorder that does not know the type: printed
                # before the first message is published, so it is there when that one is read
                definition = {
                    "type": header["type"],
                    "md5sum": header["md5sum"],
                    "definition": header.get("message_definition", ""),
                }
                print("DEF " + json.dumps(definition), flush=True)
        with send:
            read = False
            try:
                with writer.loan(size, stamp_ns=now, kind=KIND_ROS1, meta=meta[0],
                                 timeout_s=args.timeout) as slot:  # fmt: skip
                    read = True
                    read_into(slot)  # from the socket into the slot: the only copy
                published = True
            except (TransportError, ReaderGoneError) as err:
                published = False
                logger.warning("%s: message %d not forwarded: %s", args.topic, received, err)
            if not read:  # no slot: the message is still on the socket
                if len(scratch) < size:
                    scratch.extend(bytes(size - len(scratch)))
                read_into(memoryview(scratch)[:size])
        with lock:
            counts["published" if published else "failed"] += 1

    try:
        if args.await_lossless > 0:
            print("STREAM", flush=True)
            deadline = time.monotonic() + args.await_lossless
            while not any(r.policy == Policy.LOSSLESS for r in writer.stats().readers):
                if time.monotonic() >= deadline or stop.is_set():
                    logger.error("%s: no recorder attached to %s", args.topic, args.stream)
                    return 1
                time.sleep(0.01)
        receive_in_place(rospy, deliver)
        rospy.init_node("redrive_scraper", anonymous=True, disable_signals=True)
        import rosgraph

        uri = rosgraph.get_master_uri()

        def subscribe() -> Any:
            return rospy.Subscriber(
                args.topic, rospy.AnyMsg, _ignore, queue_size=1000, buff_size=_RECV_BYTES,
                tcp_nodelay=True,
            )  # fmt: skip

        sub = subscribe()
        pid = _master_pid(uri)
        print("READY", flush=True)
        parent = os.getppid()
        state = ""
        ticks = 0
        while not stop.wait(0.25):
            with lock:
                now_state = json.dumps({
                    "publishers": _publishers(sub),
                    "received": counts["received"],
                    "forwarded": counts["published"],
                    "failed": counts["failed"],
                })  # fmt: skip
            if now_state != state:
                print("STATE " + now_state, flush=True)
                state = now_state
            if os.getppid() != parent:  # redrive live was killed: no orphan scraper stays
                logger.warning("the process that started this scraper is gone: stopping")
                break
            ticks += 1
            if ticks % _MASTER_EVERY:  # an XML-RPC call costs the scraper and the master CPU
                continue
            now_pid = _master_pid(uri)
            if now_pid is not None and pid is not None and now_pid != pid:
                logger.info("ROS master restarted (pid %d → %d): subscribing again", pid, now_pid)
                try:
                    sub.unregister()
                except Exception as err:  # the old master is gone: nothing to unregister from
                    logger.debug("unregister: %s", err)
                sub = subscribe()
            if now_pid is not None:
                pid = now_pid
        rospy.signal_shutdown("redrive scraper stopped")
    finally:
        writer.close()
    logger.info(
        "%s: received %d, forwarded %d, failed %d",
        args.topic,
        counts["received"],
        counts["published"],
        counts["failed"],
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
