"""The Sensor Dispatcher for live data: shared-memory streams read as a log.

:class:`LiveLog` implements :class:`redrive.io.LogReader` over the streams of a live session, so
the replay path's :class:`~redrive.assembly.frames.FrameAssembler` (sensor map inference, nearest-stamp
synchronisation, ego-state interpolation) assembles live frames unchanged. ``ros1`` streams yield
the scraper's serialised bytes, decoded here with redrive's decoders and a ROS 1 Noetic typestore
(``cdr`` streams: the ROS 2 scraper's CDR bytes and a ROS 2 Humble one);
``sensor`` streams yield already-typed samples (``native`` messages).

**Clocks.** The frame assembler compares a message's *log time* (when it arrived) with header
stamps. Live, arrival is the wall clock while the stamps are the source's clock — the wall clock
for a live sensor, but years earlier for ``rosbag play`` or a replayed log. The log time given to
a message is therefore its publish time minus the smallest (publish − stamp) offset seen so far in
the session: arrival on the stamps' clock, with the lowest latency seen counted as zero.

Every stream is read as a *keep-latest observer*: the dispatcher never slows a source down; the
messages it did not get are counted (:attr:`LiveLog.dropped`). Ego-state and transform streams
are read with a backlog (from the oldest message their ring holds, also after being lapped), so
the first frames, whose sweeps were published before the dispatcher's first read, find the ego
states around their stamps. Recording reads the same streams
losslessly on its own (:mod:`redrive.live.recorder`).
"""

from __future__ import annotations

import logging
import select
import struct
import threading
import time
from collections.abc import Collection, Iterator, Mapping, Sequence
from pathlib import Path
from types import MappingProxyType, TracebackType
from typing import Any

from redrive.errors import ConfigError, TransportError
from redrive.io.base import LogMessage, ReaderCapabilities, TopicInfo
from redrive.io.ros.decoders import capabilities_of, decoder_for
from redrive.io.ros.decoders.base import Decoded, DecodedKind
from redrive.io.ros.deserialize import Deserializer
from redrive.io.ros.typestore import typestore_for
from redrive.live.streams import StreamSpec
from redrive.transport import Policy, ProducerGoneError, Reader
from redrive.transport.codec import KIND_CDR, KIND_ROS1, KIND_SENSOR, decode_sample

__all__ = ["LiveLog"]

logger = logging.getLogger(__name__)

_POLL_S = 0.1
_HISTORY_KINDS = frozenset({DecodedKind.VEHICLE_STATE, DecodedKind.TRANSFORMS})


def _native_kind(spec: StreamSpec) -> dict[str, Any]:
    """``kind``/``sensor_type`` of a typed-sample stream: those of the ROS type it stands for
    (:data:`~redrive.live.streams.PAYLOAD_MSGTYPE`); nothing for ROS 1 byte streams."""
    if spec.payload == "ros1":
        return {}
    decoder = decoder_for(spec.msgtype)
    if decoder is None:
        return {}
    return {"kind": decoder.kind, "sensor_type": decoder.sensor_type}


def _wants_backlog(spec: StreamSpec) -> bool:
    """Whether ``spec``'s stream is read from the oldest message its ring holds: ego states and
    transforms, which frames are interpolated in. A sensor stream read newest-first starts at
    its newest sweep, whose stamp can then lie before the newest ego state; with the ego states'
    ring read from its oldest, the states on both sides of that stamp are there."""
    decoder = decoder_for(spec.msgtype)
    return decoder is not None and decoder.kind in _HISTORY_KINDS


class LiveLog:
    """A live session's streams as a (never-ending) log.

    Args:
        specs: the session's streams.
        session: the session name (shown as the log's path, ``live:<session>``).
        stop: set it to end :meth:`messages`.
        attach_timeout_s: how long to wait for each stream's writer.
        warn_gone: log a stream whose writer went away as a warning (False: at DEBUG, for an
            observer such as the Foxglove view, for which a finished source is no news).
        duration_hint_s: the duration the sensor map infers rates over (live topics have no
            counts yet: the map is inferred from types).

    Raises:
        ProducerGoneError: a stream has no writer within ``attach_timeout_s``.
    """

    format = "live"

    def __init__(
        self,
        specs: Sequence[StreamSpec],
        session: str,
        *,
        stop: threading.Event | None = None,
        attach_timeout_s: float = 10.0,
        warn_gone: bool = True,
    ) -> None:
        if not specs:
            msg = "a live session needs at least one topic"
            raise ConfigError(msg)
        self.path = Path(f"live:{session}")
        self.session = session
        self.stop = stop or threading.Event()
        self._gone_level = logging.WARNING if warn_gone else logging.DEBUG
        self._specs = {s.topic: s for s in specs}
        self._readers: dict[str, Reader] = {}
        try:
            for spec in specs:
                self._readers[spec.topic] = Reader(
                    spec.stream,
                    timeout_s=attach_timeout_s,
                    policy=Policy.KEEP_LATEST,
                    backlog=_wants_backlog(spec),
                )
        except BaseException:
            self.close()
            raise
        ros1_types = sorted({s.msgtype for s in specs if s.payload == "ros1"})
        store = typestore_for(1, needed=ros1_types)[0] if ros1_types else None
        cdr_types = sorted({s.msgtype for s in specs if s.payload == "cdr"})
        cdr_store = typestore_for(2, needed=cdr_types)[0] if cdr_types else None
        self._deserializer = Deserializer(self.path, ros1=store, cdr=cdr_store)
        # types whose first field is a std_msgs/Header: the stamp is bytes 4..12 (ROS 1: after
        # the header's seq; CDR: after the encapsulation header)
        self._has_header = {
            t
            for types, st in ((ros1_types, store), (cdr_types, cdr_store))
            for t in types
            if st is not None
            and t in st.fielddefs
            and st.fielddefs[t][1][:1]
            and st.fielddefs[t][1][0][0] == "header"
        }
        self._offset_ns: int | None = None
        self._topics = MappingProxyType(
            {
                s.topic: TopicInfo(
                    topic=s.topic,
                    msgtype=s.msgtype,
                    count=0,
                    encoding="native" if s.payload == "sensor" else s.payload,
                    **_native_kind(s),
                )
                for s in specs
            }
        )
        self._start_ns = time.time_ns()
        self.received: dict[str, int] = dict.fromkeys(self._specs, 0)
        self.dropped: dict[str, int] = dict.fromkeys(self._specs, 0)
        self.gone: set[str] = set()

    # -- LogReader ---------------------------------------------------------------------------
    @property
    def topics(self) -> Mapping[str, TopicInfo]:
        return self._topics

    @property
    def capabilities(self) -> ReaderCapabilities:
        """From the session's topics; message-typed when every stream carries ROS bytes."""
        return capabilities_of(
            self._topics.values(),
            message_typed=all(s.payload != "sensor" for s in self._specs.values()),
        )

    @property
    def typestores(self) -> Mapping[str, Any]:
        """Encoding (``ros1`` / ``cdr``) → the typestore the streams' bytes are read with."""
        return self._deserializer.typestores

    @property
    def start_ns(self) -> int:
        return self._start_ns

    @property
    def end_ns(self) -> int:
        return max(self._start_ns + 1, time.time_ns())

    @property
    def message_count(self) -> int:
        return sum(self.received.values())

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        """Messages as they arrive, until :attr:`stop` is set or every writer is gone.

        ``log_time_ns`` is when the source published the message (wall clock); ``start_ns`` /
        ``stop_ns`` are ignored (live data has no past).
        """
        del start_ns, stop_ns
        wanted = {t: r for t, r in self._readers.items() if topics is None or t in topics}
        unknown = set(topics or ()) - set(self._readers)
        if unknown:
            logger.debug("live log %s: no stream for %s", self.session, sorted(unknown))
        fds = [r.fileno() for r in wanted.values()]
        while not self.stop.is_set() and len(self.gone) < len(wanted):
            select.select(fds, [], [], _POLL_S)
            # everything that is there, from every stream, in arrival order: a sweep read before
            # the ego states published ahead of it would be assembled without them
            batch = [m for t, r in wanted.items() if t not in self.gone for m in self._drain(t, r)]
            batch.sort(key=lambda m: m.log_time_ns)
            yield from batch

    def _drain(self, topic: str, reader: Reader) -> Iterator[LogMessage]:
        spec = self._specs[topic]
        while True:
            try:
                msg = reader.read(timeout_s=0.0)
            except ProducerGoneError as err:
                if topic not in self.gone:
                    logger.log(self._gone_level, "live topic %s: %s", topic, err)
                    self.gone.add(topic)
                return
            if msg is None:
                return
            self.received[topic] += 1
            self.dropped[topic] += msg.dropped_before
            if msg.kind in (KIND_ROS1, KIND_CDR):
                stamp = None
                if spec.msgtype in self._has_header and msg.payload.shape[0] >= 12:
                    sec, nsec = struct.unpack_from("<II", msg.payload.data, 4)
                    stamp = sec * 1_000_000_000 + nsec
                yield LogMessage(
                    topic=topic,
                    msgtype=spec.msgtype,
                    log_time_ns=self._log_time(msg.publish_ns, stamp),
                    encoding="ros1" if msg.kind == KIND_ROS1 else "cdr",
                    raw=msg.payload.data,
                )
            elif msg.kind == KIND_SENSOR:
                sample = decode_sample(msg.meta, msg.payload)
                decoded = Decoded(
                    stamp_ns=sample.stamp_ns, frame_id=sample.frame_id, value=sample.data
                )
                yield LogMessage(
                    topic=topic,
                    msgtype=spec.msgtype,
                    log_time_ns=self._log_time(msg.publish_ns, sample.stamp_ns),
                    encoding="native",
                    payload=decoded,
                )
            else:
                msg_text = f"live topic {topic}: message {msg.seq} has unknown kind {msg.kind}"
                raise TransportError(msg_text)

    def _log_time(self, publish_ns: int, stamp_ns: int | None) -> int:
        """Arrival time on the stamps' clock (see the module text)."""
        if stamp_ns:
            offset = publish_ns - stamp_ns
            if self._offset_ns is None or offset < self._offset_ns:
                self._offset_ns = offset
        return publish_ns - (self._offset_ns or 0)

    def deserialize(self, message: LogMessage) -> object:
        return self._deserializer(message)

    def close(self) -> None:
        for reader in self._readers.values():
            reader.close()
        self._readers.clear()

    def __enter__(self) -> LiveLog:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
