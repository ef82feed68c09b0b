"""The Sensor Data Scraper for ROS 2 topics: Cyclone DDS in, shared memory out.

One process for all of a session's ROS 2 topics (one DDS participant, as a ROS 2 node has one),
started by :func:`redrive.live.ros2.ros2_session` as ``python -m redrive.live.ros2_scraper``.
Each topic gets a DDS reader of its type (built from the ROS 2 definitions,
:func:`redrive.live.ros2_dds.idl_struct`) whose reliability and durability follow what the
publisher offers (a reliable reader would not match a best-effort sensor; a transient-local one
receives a latched ``/tf_static``) with a deep history, so nothing is dropped while this process
is scheduled out. Samples are taken as CDR bytes — never deserialised here, and copied once, from
Cyclone's buffer straight into a shared-memory slot — and published into the topic's stream as
:data:`~redrive.transport.codec.KIND_CDR` messages (the receive time as their stamp); the core
decodes them with redrive's decoders and records them as they came.

While it runs it reports on its stdout (one JSON object a line, read by
:class:`redrive.live.scraper_state.Ros2Reports`):

* ``STATE {"topic", "publishers", "received", "forwarded", "failed"}`` whenever a topic's matched
  publications (DDS instance handles of the writers its reader is matched with) or counts change,
  looked at every 0.25 s;
* with ``--discover``, ``OFFERED {"topic", "msgtype", "reliability", "durability"}`` once for each
  ROS 2 topic a publisher offers on the domain (the builtin topic ``DCPSPublication``, first
  publication's QoS), including those that appear later.

More topics are added while it runs by a line ``ADD {spec}`` on its stdin (a spec as in
``--spec``, plus ``"await": true`` to create the topic's DDS reader only once a lossless reader
— the recorder — reads the stream, so no sample is forwarded before it is recorded; it says
``STREAM {"topic"}`` once the stream exists); it answers ``ADDED {"topic"}`` or
``FAILED {"topic", "error"}``.

SIGTERM/SIGINT stop it, and so does the end of the process that started it; the streams'
segments are unlinked on every exit path.

Usage: ``python -m redrive.live.ros2_scraper --domain 0 --spec JSON [--discover]``; ``JSON`` is a
list of ``{"topic", "msgtype", "stream", "capacity", "reliability", "durability"}``; prints
``READY`` once every reader exists.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import queue
import signal
import sys
import threading
import time
from typing import Any

logger = logging.getLogger("redrive.live.ros2_scraper")

#: history depth of each reader: samples DDS keeps for a topic until this process takes them.
READER_DEPTH = 100
#: how often the matched publications and counts are looked at, s
_STATE_EVERY_S = 0.25
#: how long an added topic waits for its recorder to read the stream, s
_AWAIT_S = 30.0


def _say(kind: str, body: dict[str, Any]) -> None:
    print(f"{kind} {json.dumps(body)}", flush=True)


def _commands(lines: Any, out: queue.Queue[dict[str, Any]]) -> None:
    """``ADD {spec}`` lines of stdin into ``out`` (run in a thread)."""
    for line in lines:
        kind, _, body = line.partition(" ")
        if kind != "ADD":
            continue
        try:
            out.put(json.loads(body))
        except ValueError:
            logger.warning("not understood on stdin: %r", line)


class _Scraper:
    """The readers, their streams and counts of one scraper process."""

    def __init__(self, dp: Any, waitset: Any, slots: int, timeout_s: float) -> None:
        from redrive.io.ros.typestore import typestore_for

        self.dp, self.waitset, self.slots, self.timeout_s = dp, waitset, slots, timeout_s
        self.store = typestore_for(2)[0]
        self.writers: dict[str, Any] = {}
        self.readers: list[Any] = []
        self.counts: dict[str, list[int]] = {}  # received, failed
        #: added topics whose reader waits for a recorder: (spec, deadline)
        self.waiting: list[tuple[dict[str, Any], float]] = []
        self._said: dict[str, str] = {}

    def stream(self, spec: dict[str, Any]) -> None:
        from redrive.live.streams import ring_slots
        from redrive.transport import Policy, Writer

        self.writers[spec["topic"]] = Writer(
            spec["stream"],
            capacity_bytes=int(spec["capacity"]),
            slots=ring_slots(int(spec["capacity"]), self.slots),
            policy=Policy.LOSSLESS,
            max_readers=3,  # the dispatcher, the recorder, the Foxglove view
        )
        self.counts[spec["topic"]] = [0, 0]

    def subscribe(self, spec: dict[str, Any]) -> None:
        from redrive.live.ros2_dds import QosProfile, RawReader

        qos = QosProfile(
            reliability=spec["reliability"], durability=spec["durability"], depth=READER_DEPTH
        )
        reader = RawReader(self.dp, spec["topic"], spec["msgtype"], store=self.store, qos=qos)
        self.waitset.attach(reader.condition)
        self.readers.append(reader)

    def add(self, spec: dict[str, Any]) -> None:
        """An ``ADD`` command: the stream now, the reader now or once a recorder reads."""
        topic = spec.get("topic", "?")
        try:
            if topic in self.writers:
                raise ValueError(f"{topic} is recorded already")
            self.stream(spec)
            if spec.get("await"):
                _say("STREAM", {"topic": topic})
                self.waiting.append((spec, time.monotonic() + _AWAIT_S))
                return
            self.subscribe(spec)
        except Exception as err:  # reported to the core, which says it to the user
            _say("FAILED", {"topic": topic, "error": str(err)})
            return
        _say("ADDED", {"topic": topic})

    def check_waiting(self) -> None:
        from redrive.transport import Policy

        still = []
        for spec, deadline in self.waiting:
            topic = spec["topic"]
            if any(r.policy == Policy.LOSSLESS for r in self.writers[topic].stats().readers):
                try:
                    self.subscribe(spec)
                except Exception as err:
                    _say("FAILED", {"topic": topic, "error": str(err)})
                    continue
                _say("ADDED", {"topic": topic})
            elif time.monotonic() >= deadline:
                _say("FAILED", {"topic": topic, "error": f"no recorder read {spec['stream']}"})
            else:
                still.append((spec, deadline))
        self.waiting = still

    def forward(self) -> None:
        from redrive.errors import TransportError
        from redrive.transport import ReaderGoneError
        from redrive.transport.codec import KIND_CDR

        for reader in self.readers:
            counts = self.counts[reader.topic]
            writer = self.writers[reader.topic]
            with reader.taken() as samples:  # copied from Cyclone's buffer into the slot
                for sample in samples:
                    counts[0] += 1
                    try:
                        with writer.loan(
                            sample.nbytes,
                            stamp_ns=time.time_ns(),
                            kind=KIND_CDR,
                            timeout_s=self.timeout_s,
                        ) as slot:
                            sample.copy_into(slot)
                    except (TransportError, ReaderGoneError) as err:
                        counts[1] += 1
                        logger.warning("%s: a sample not forwarded: %s", reader.topic, err)

    def report(self) -> None:
        for reader in self.readers:
            received, failed = self.counts[reader.topic]
            state = {
                "topic": reader.topic,
                "publishers": sorted(str(h) for h in reader.publications()),
                "received": received,
                "forwarded": received - failed,
                "failed": failed,
            }
            text = json.dumps(state)
            if self._said.get(reader.topic) != text:
                self._said[reader.topic] = text
                print("STATE " + text, flush=True)


def _offered(discovery: Any, seen: set[str]) -> None:
    """``OFFERED`` lines for the ROS 2 topics first seen among the domain's publications."""
    from cyclonedds.core import InstanceState

    from redrive.live.ros2_dds import QosProfile, ros_topic, ros_type

    for sample in discovery.take(N=256):
        info = getattr(sample, "sample_info", None)
        if info is not None and (not info.valid_data or info.instance_state != InstanceState.Alive):
            continue  # a publication that went away
        topic = ros_topic(getattr(sample, "topic_name", "") or "")
        msgtype = ros_type(getattr(sample, "type_name", "") or "")
        if topic is None or msgtype is None or topic in seen:
            continue
        seen.add(topic)
        qos = QosProfile.from_dds(sample.qos)
        _say("OFFERED", {"topic": topic, "msgtype": msgtype, "reliability": qos.reliability,
                         "durability": qos.durability})  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    from cyclonedds.core import WaitSet

    from redrive.live.ros2_dds import participant, receiving_config
    from redrive.transport.heap import keep_freed_memory

    # Cyclone allocates (and zeroes) each sample twice, and the take copies it into a Python
    # bytes: ~2 MB blocks that glibc would otherwise map, fault in and give back every time
    keep_freed_memory()
    os.environ["CYCLONEDDS_URI"] = receiving_config(os.environ.get("CYCLONEDDS_URI"))
    parser = argparse.ArgumentParser(prog="ros2_scraper", description=__doc__)
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--spec", required=True, help="the topics, JSON (see the module text)")
    parser.add_argument("--slots", type=int, default=8)
    parser.add_argument("--timeout", type=float, default=5.0, help="lossless back-pressure, s")
    parser.add_argument(
        "--discover", action="store_true", help="report the topics publishers offer (OFFERED)"
    )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s ros2 scraper %(message)s")
    specs: list[dict[str, Any]] = json.loads(args.spec)

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    commands: queue.Queue[dict[str, Any]] = queue.Queue()
    threading.Thread(target=_commands, args=(sys.stdin, commands), daemon=True).start()
    scraper = None
    try:
        dp = participant(args.domain)
        waitset = WaitSet(dp)
        scraper = _Scraper(dp, waitset, args.slots, args.timeout)
        for spec in specs:
            scraper.stream(spec)
            scraper.subscribe(spec)
        discovery = None
        seen: set[str] = set()
        if args.discover:
            from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
            from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState

            discovery = BuiltinDataReader(dp, BuiltinTopicDcpsPublication)
            waitset.attach(
                ReadCondition(discovery, SampleState.Any | ViewState.Any | InstanceState.Any)
            )
        print("READY", flush=True)
        parent = os.getppid()
        reported = 0.0
        while not stop.is_set():
            # ns: wake at least every 0.1 s to see a stop (10 ms while a topic awaits its recorder)
            waitset.wait(10_000_000 if scraper.waiting else 100_000_000)
            if os.getppid() != parent:  # redrive live was killed: no orphan scraper stays
                break
            scraper.forward()
            while not commands.empty():
                scraper.add(commands.get_nowait())
            if scraper.waiting:
                scraper.check_waiting()
            if discovery is not None:
                _offered(discovery, seen)
            now = time.monotonic()
            if now - reported >= _STATE_EVERY_S:
                reported = now
                scraper.report()
    finally:
        if scraper is not None:
            for writer in scraper.writers.values():
                writer.close()
    if scraper is not None:
        for topic, (received, failed) in scraper.counts.items():
            logger.info("%s: received %d, not forwarded %d", topic, received, failed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
