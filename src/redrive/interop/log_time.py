"""Where a run's frames sit on its log's time axis (the MCAP export, ``redrive serve``).

A run's frames are stamped with the header stamp of the sample that drove them (the Sensor
Dispatcher syncs by header stamps), a log's messages sit at their *log time*, when the recorder
received them.  The two are one axis for a synthetic log and most datasets, but not for every
bag: the Luminar bag of ``../shared/data`` has header stamps of 2020-03-12 and log times of
2020-11-04, so results written at their frames' stamps would sit 237.8 days from the clouds they
were computed from.  :func:`frame_log_times` gives each frame the log time of the message that
drove it — read again from the log: the driver sensor's topic of the sensor map (the one the run
inferred, or ``overrides`` from the run's ``--sensor-map``), or the ground-truth topic for a
log without a sensor to drive frames — so the export and the server put a frame's results at
the log time of its sample; the messages themselves keep the header stamps.

A frame whose stamp no message of that topic has (a closed loop's own ticks) is moved by the
offset of the nearest frame that has one; when no frame has one the axis is the stamps'.  When
the first, middle and last frames' messages are found at log times equal to their stamps, the
stamps are taken as the axis without reading the rest (a synthetic log, the datasets: the
export of an MCAP log stays a copy of its chunks, not a second read of its clouds).
"""

from __future__ import annotations

import bisect
import logging
import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from redrive.assembly.sensor_map import SensorMapOverrides, infer_sensor_map
from redrive.errors import ConfigError, UnsupportedMessageError
from redrive.io.base import LogMessage, LogReader
from redrive.io.ros.decoders import decode, decoder_for

__all__ = ["LogTimeAxis", "driving_topic", "frame_log_times"]

logger = logging.getLogger(__name__)

_SEC = 1_000_000_000


@dataclass(frozen=True, slots=True, kw_only=True)
class LogTimeAxis:
    """frame stamp → log time: ``stamps_ns`` (sorted) with the ``offsets_ns`` (log time −
    stamp) of the frames whose driving message was found.  Empty: the stamps are the axis."""

    stamps_ns: tuple[int, ...] = ()
    offsets_ns: tuple[int, ...] = ()

    def log_time_ns(self, stamp_ns: int) -> int:
        """The log time of the frame stamped ``stamp_ns`` (the nearest found frame's offset
        when it was not found itself)."""
        if not self.stamps_ns:
            return stamp_ns
        i = bisect.bisect_left(self.stamps_ns, stamp_ns)
        last = i == len(self.stamps_ns)
        if last or (i > 0 and stamp_ns - self.stamps_ns[i - 1] < self.stamps_ns[i] - stamp_ns):
            i -= 1
        return stamp_ns + self.offsets_ns[i]

    @property
    def shifted(self) -> bool:
        """Some frame's log time is not its stamp."""
        return any(self.offsets_ns)


def driving_topic(reader: LogReader, *, overrides: SensorMapOverrides | None = None) -> str | None:
    """The topic whose messages drive the frames of a run of ``reader`` (the sensor map's
    driver, else its ground truth); None when the log has neither."""
    try:
        smap = infer_sensor_map(
            reader.topics, duration_ns=reader.end_ns - reader.start_ns, overrides=overrides
        )
    except ConfigError as err:
        logger.warning("%s: %s; results stay at their frames' stamps", reader.path, err)
        return None
    if smap.driver is not None:
        return smap.sensor(smap.driver).topic
    return smap.ground_truth_topic


def _raw_header_stamp(message: LogMessage) -> int | None:
    """The ``std_msgs/Header`` stamp read from the first bytes of a ROS 1 or CDR message whose
    first field is a header (None when the bytes are too short); 0 → the log time."""
    raw = message.raw
    if message.encoding == "ros1" and len(raw) >= 12:
        sec, nsec = struct.unpack_from("<II", raw, 4)  # seq, then stamp.sec, stamp.nsec
    elif message.encoding == "cdr" and len(raw) >= 12:
        order = "<" if raw[1] & 1 else ">"  # the encapsulation header: CDR_LE / CDR_BE
        sec, nsec = struct.unpack_from(f"{order}iI", raw, 4)
    else:
        return None
    stamp = sec * _SEC + nsec
    return stamp if stamp != 0 else message.log_time_ns


def _stamps(
    reader: LogReader, topic: str, *, start_ns: int | None = None, stop_ns: int | None = None
) -> Iterator[tuple[int, int]]:
    """(stamp as the decoder gives it, log time) of every message of ``topic``.

    The stamp is read from the message's first bytes when that agrees with the decoder on the
    first message (a header first, as sensor messages have); otherwise every message is
    decoded."""
    raw_ok: bool | None = None
    for message in reader.messages(topics=[topic], start_ns=start_ns, stop_ns=stop_ns):
        if raw_ok is not False and message.encoding != "native":
            stamp = _raw_header_stamp(message)
            if raw_ok is None:
                raw_ok = stamp is not None and stamp == _decoded_stamp(reader, message)
            if raw_ok and stamp is not None:
                yield stamp, message.log_time_ns
                continue
        decoded = _decoded_stamp(reader, message)
        if decoded is not None:
            yield decoded, message.log_time_ns


def _decoded_stamp(reader: LogReader, message: LogMessage) -> int | None:
    if decoder_for(message.msgtype) is None and message.encoding != "native":
        return None
    try:
        return decode(message, reader.deserialize).stamp_ns
    except UnsupportedMessageError:
        return None


def _one_axis(reader: LogReader, topic: str, stamps_ns: Sequence[int]) -> bool:
    """Whether the first, middle and last frames' messages sit at log times equal to their
    stamps (looked up at those log times only: an indexed read of three chunks) — a log whose
    writer sets the log time to the header stamp (``redrive synth``, the datasets), where
    reading the whole driver topic again would only confirm it."""
    for stamp in {stamps_ns[0], stamps_ns[len(stamps_ns) // 2], stamps_ns[-1]}:
        at = _stamps(reader, topic, start_ns=stamp, stop_ns=stamp + 1)
        if not any(found == stamp for found, _ in at):
            return False
    return True


def frame_log_times(
    reader: LogReader,
    frame_stamps_ns: Sequence[int],
    *,
    overrides: SensorMapOverrides | None = None,
) -> LogTimeAxis:
    """The log time of each of a run's frames (see the module text)."""
    if not frame_stamps_ns:
        return LogTimeAxis()
    topic = driving_topic(reader, overrides=overrides)
    if topic is None or topic not in reader.topics:
        return LogTimeAxis()
    if _one_axis(reader, topic, frame_stamps_ns):
        return LogTimeAxis()
    wanted = set(frame_stamps_ns)
    found: dict[int, int] = {}
    for stamp, log_time in _stamps(reader, topic):
        if stamp in wanted and stamp not in found:
            found[stamp] = log_time - stamp
    if not found:
        logger.info(
            "%s: no message of %s has a frame's stamp; results stay at their frames' stamps",
            reader.path,
            topic,
        )
        return LogTimeAxis()
    stamps = tuple(sorted(found))
    axis = LogTimeAxis(stamps_ns=stamps, offsets_ns=tuple(found[s] for s in stamps))
    if axis.shifted:
        spread = max(axis.offsets_ns) - min(axis.offsets_ns)
        logger.info(
            "%s: results put at their samples' log times on %s (log time − header stamp %.3f s%s)",
            reader.path,
            topic,
            axis.offsets_ns[0] / _SEC,
            f", varying by {spread / 1e6:.1f} ms" if spread else "",
        )
    return axis
