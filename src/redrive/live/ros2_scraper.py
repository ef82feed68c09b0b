"""The Sensor Data Scraper for ROS 2 topics: Cyclone DDS in, shared memory out.

One process for all of a session's ROS 2 topics (one DDS participant, as a ROS 2 node has one),
started by :func:`redrive.live.ros2.ros2_session` as ``python -m redrive.live.ros2_scraper``.
Each topic gets a DDS reader of its type (built from the ROS 2 definitions,
:func:`redrive.live.ros2_dds.idl_struct`) whose reliability and durability follow what the
publisher offers (a reliable reader would not match a best-effort sensor; a transient-local one
receives a latched ``/tf_static``) with a deep history, so nothing is dropped while this process
is scheduled out. Samples are taken as CDR bytes — never deserialised here — and published into
the topic's stream as :data:`~redrive.transport.codec.KIND_CDR` messages (the receive time as
their stamp); the core decodes them with redrive's decoders and records them as they came.

SIGTERM/SIGINT stop it; the streams' segments are unlinked on every exit path.

Usage: ``python -m redrive.live.ros2_scraper --domain 0 --spec JSON``; ``JSON`` is a list of
``{"topic", "msgtype", "stream", "capacity", "reliability", "durability"}``; prints ``READY``
once every reader exists.
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
from typing import Any

logger = logging.getLogger("redrive.live.ros2_scraper")

#: history depth of each reader: samples DDS keeps for a topic until this process takes them.
READER_DEPTH = 100


def main(argv: list[str] | None = None) -> int:
    from cyclonedds.core import WaitSet

    from redrive.errors import TransportError
    from redrive.io.typestore import typestore_for
    from redrive.live.ros2_dds import QosProfile, RawReader, participant
    from redrive.transport import Policy, ReaderGoneError, Writer
    from redrive.transport.codec import KIND_CDR

    parser = argparse.ArgumentParser(prog="ros2_scraper", description=__doc__)
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--spec", required=True, help="the topics, JSON (see the module text)")
    parser.add_argument("--slots", type=int, default=8)
    parser.add_argument("--timeout", type=float, default=5.0, help="lossless back-pressure, s")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s ros2 scraper %(message)s")
    specs: list[dict[str, Any]] = json.loads(args.spec)

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    store = typestore_for(2, needed=[s["msgtype"] for s in specs])[0]
    writers: dict[str, Writer] = {}
    counts = {s["topic"]: [0, 0] for s in specs}  # received, failed
    try:
        dp = participant(args.domain)
        waitset = WaitSet(dp)
        readers = []
        for spec in specs:
            writers[spec["topic"]] = Writer(
                spec["stream"],
                capacity_bytes=int(spec["capacity"]),
                slots=args.slots,
                policy=Policy.LOSSLESS,
                max_readers=3,  # the dispatcher, the recorder, the Foxglove view
            )
            qos = QosProfile(
                reliability=spec["reliability"], durability=spec["durability"], depth=READER_DEPTH
            )
            reader = RawReader(dp, spec["topic"], spec["msgtype"], store=store, qos=qos)
            waitset.attach(reader.condition)
            readers.append(reader)
        print("READY", flush=True)
        parent = os.getppid()
        while not stop.is_set():
            waitset.wait(100_000_000)  # ns: wake at least every 0.1 s to see a stop
            if os.getppid() != parent:  # redrive live was killed: no orphan scraper stays
                break
            for reader in readers:
                for cdr, _source_ns in reader.take():
                    counts[reader.topic][0] += 1
                    try:
                        writers[reader.topic].publish(
                            cdr, stamp_ns=time.time_ns(), kind=KIND_CDR, timeout_s=args.timeout
                        )
                    except (TransportError, ReaderGoneError) as err:
                        counts[reader.topic][1] += 1
                        logger.warning("%s: a sample not forwarded: %s", reader.topic, err)
    finally:
        for writer in writers.values():
            writer.close()
    for topic, (received, failed) in counts.items():
        logger.info("%s: received %d, not forwarded %d", topic, received, failed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
