"""Inputs whose header stamps follow another clock than the frames' — found before a run.

Frames are matched by header stamps.  A log can carry an input whose header stamps follow
another clock than the driving sensor's: the Embark bag of ``../shared/data``
(``rosbag1_real/embag_luminar_test.bag``) has its clouds stamped 2020-03-12 and its odometry
stamped 1970 (simulated time), so no frame ever gets a vehicle state.  The frame assembler
warns about it once the frames are read (:meth:`FrameAssembler._other_clock`); a run needs to
know it before the first frame, so that a planner that cannot get a state is skipped with the
reason instead of failing on every frame.

:func:`other_clock_inputs` reads the first message of the driving topic and of the vehicle-state
and ground-truth topics and compares each one's *header stamp − log time*: on one clock the
two offsets are within a recorder's latency of each other; an input whose offset differs from
the driver's by more than a minute (the assembler's own bound) follows another clock.  The log
times are what makes this sound on logs whose inputs start at different times: a state topic
that starts ten minutes into the log has the driver's offset all the same.
"""

from __future__ import annotations

import logging

from redrive.assembly.sensor_map import SensorMap
from redrive.errors import UnsupportedMessageError
from redrive.io.base import LogReader
from redrive.io.ros.decoders import decode, decoder_for

__all__ = ["OTHER_CLOCK_NS", "other_clock_inputs"]

logger = logging.getLogger(__name__)

#: an input whose header stamps lie further than this from the frames' follows another clock
OTHER_CLOCK_NS = 60_000_000_000


def other_clock_inputs(log: LogReader, sensor_map: SensorMap) -> dict[str, str]:
    """``vehicle_state`` / ``ground_truth`` → why no frame will get a sample of it, for each
    whose header stamps follow another clock than the driving sensor's (empty when the log has
    no driver, or every input is on its clock)."""
    if sensor_map.driver is None:
        return {}
    driver_topic = sensor_map.sensor(sensor_map.driver).topic
    driver_offset = _first_offset_ns(log, driver_topic)
    if driver_offset is None:
        return {}
    out: dict[str, str] = {}
    for name, topic in (
        ("vehicle_state", sensor_map.vehicle_state_topic),
        ("ground_truth", sensor_map.ground_truth_topic),
    ):
        if topic is None or topic == driver_topic:
            continue
        offset = _first_offset_ns(log, topic)
        if offset is None:
            continue
        gap = abs(offset - driver_offset)
        if gap <= OTHER_CLOCK_NS:
            continue
        days = gap / 86_400e9
        span = f"{days:.1f} days" if days >= 1.0 else f"{gap / 1e9:.0f} s"
        out[name] = (
            f"the log's {name.replace('_', ' ')} ({topic}) has header stamps {span} from the "
            f"frames' ({driver_topic}): they follow another clock (simulated time, or a clock "
            "that was not set), so no frame gets a sample of it"
        )
    return out


def _first_offset_ns(log: LogReader, topic: str) -> int | None:
    """Header stamp − log time of the first decodable message on ``topic``; None when none of
    its first few messages decodes (or the topic has no decoder)."""
    messages = log.messages(topics=[topic])
    try:
        for tried, message in enumerate(messages):
            if tried >= 5:
                break
            if message.encoding != "native" and decoder_for(message.msgtype) is None:
                return None
            try:
                decoded = decode(message, log.deserialize)
            except UnsupportedMessageError as err:
                logger.debug("%s: %s", log.path, err)
                continue
            return decoded.stamp_ns - message.log_time_ns
    finally:
        close = getattr(messages, "close", None)
        if close is not None:
            close()
    return None
