"""The Sensor Data Scraper for one ROS 1 topic: rospy in, shared memory out.

Runs as its own process under Debian's ``/usr/bin/python3`` (rospy imports nowhere else), started
by :func:`redrive.live.session.start_ros1_scraper` as a *script* (``python3 ros1_scraper.py``) so
that only :mod:`redrive.transport` (numpy + stdlib) is imported, never the rest of redrive.

It subscribes with ``rospy.AnyMsg`` — the message arrives as the serialised bytes the publisher
sent, and is not deserialised here — and publishes each one into the stream as a
:data:`~redrive.transport.codec.KIND_ROS1` message (topic, type and md5sum in the meta, the
receive time as its stamp). The core decodes it with redrive's decoders.

If the ROS master restarts (its pid changes), the subscription is registered anew with the new
master. SIGTERM/SIGINT stop it, and so does the death of the process that started it; the stream's segment is unlinked on every exit path.

Usage: ``python3 ros1_scraper.py --topic /velodyne_points --stream live-1.velodyne_points
--capacity 4000000 [--policy lossless] [--slots 8] [--await-lossless 20]``; prints ``READY``
once subscribed (with ``--await-lossless``: ``STREAM`` first, and it subscribes once a recorder
reads the stream).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import threading
import time
import xmlrpc.client
from typing import Any

logger = logging.getLogger("redrive.live.ros1_scraper")

#: ask the master whether it restarted every this many 0.25-s ticks (once a second)
_MASTER_EVERY = 4
#: rospy's socket read size: below glibc's mmap threshold as raised by keep_freed_memory (a
#: read buffer of 64 MiB was a fresh mmap for every read)
_RECV_BYTES = 4 << 20


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

    def on_message(msg: Any) -> None:
        now = time.time_ns()
        with lock:
            counts["received"] += 1
            if not meta:
                header = msg._connection_header
                meta.append(encode_ros1_meta(args.topic, header["type"], header["md5sum"]))
                # the full definition, for a recorder that does not know the type: printed
                # before the first message is published, so it is there when that one is read
                definition = {
                    "type": header["type"],
                    "md5sum": header["md5sum"],
                    "definition": header.get("message_definition", ""),
                }
                print("DEF " + json.dumps(definition), flush=True)
            try:
                writer.publish(msg._buff, stamp_ns=now, kind=KIND_ROS1, meta=meta[0],
                               timeout_s=args.timeout)  # fmt: skip
                counts["published"] += 1
            except (TransportError, ReaderGoneError) as err:
                counts["failed"] += 1
                logger.warning(
                    "%s: message %d not forwarded: %s", args.topic, counts["received"], err
                )

    try:
        if args.await_lossless > 0:
            print("STREAM", flush=True)
            deadline = time.monotonic() + args.await_lossless
            while not any(r.policy == Policy.LOSSLESS for r in writer.stats().readers):
                if time.monotonic() >= deadline or stop.is_set():
                    logger.error("%s: no recorder attached to %s", args.topic, args.stream)
                    return 1
                time.sleep(0.01)
        rospy.init_node("redrive_scraper", anonymous=True, disable_signals=True)
        import rosgraph

        uri = rosgraph.get_master_uri()

        def subscribe() -> Any:
            return rospy.Subscriber(
                args.topic, rospy.AnyMsg, on_message, queue_size=1000, buff_size=_RECV_BYTES,
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
