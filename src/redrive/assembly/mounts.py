"""Where each sensor sits on the vehicle: the one home of "sensor frame X in base_link at time t".

Every mount lookup (the Sensor Dispatcher's ``sensor_location``, camera calibrations, the GUI's
point transforms) goes through a :class:`~redrive.assembly.tf_buffer.TransformBuffer`, so chains
(``base_link → roof → mount → velodyne``), ROS 1 leading slashes (``/velodyne``) and mounts that
are only published on the dynamic ``/tf`` are all answered the same way.

Reading ``/tf`` costs (it is often 100 Hz and more), so :func:`mount_tf_topics` reads it only
when the static transforms do not place every sensor: it reads ``/tf_static`` and the first
message of each sensor topic (for its frame id) before the frames are assembled.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterable, Sequence

import numpy as np
import numpy.typing as npt

from redrive.assembly.tf_buffer import TransformBuffer, TransformLookupError
from redrive.errors import UnsupportedMessageError
from redrive.io.base import LogReader
from redrive.io.ros.decoders import decode, decoder_for
from redrive.io.ros.decoders.tf import is_static_tf_topic
from redrive.types import Transform

__all__ = ["BASE_FRAME", "SensorMounts", "first_frame_ids", "mount_tf_topics"]

logger = logging.getLogger(__name__)

#: the vehicle frame sensor locations are given in (REP-105).
BASE_FRAME = "base_link"


class SensorMounts:
    """Transforms read from a log's tf topics, answering ``base_link ← sensor frame`` lookups.

    Transforms from a static topic (``/tf_static``, ``…/tf_static``) and transforms stamped 0
    are static; the rest are dynamic (interpolated at the asked stamp by the buffer).
    """

    def __init__(self, *, base_frame: str = BASE_FRAME) -> None:
        self.base_frame = base_frame
        self.buffer = TransformBuffer()

    def add(self, topic: str, transforms: Iterable[Transform]) -> None:
        """The transforms of one tf message read from ``topic``."""
        static = True if is_static_tf_topic(topic) else None
        for tf in transforms:
            try:
                self.buffer.add(tf, static=static)
            except ValueError as err:  # a transform from a frame to itself
                logger.debug("%s: transform skipped: %s", topic, err)

    def knows(self, frame_id: str) -> bool:
        """The frame appears in some transform read so far."""
        return frame_id.lstrip("/") in self.buffer.frames

    def base_from(self, frame_id: str, stamp_ns: int = 0) -> npt.NDArray[np.float64] | None:
        """``base_from_<frame_id>`` (4×4) at ``stamp_ns``; None when no transform path is known.

        A frame equal to the base frame is the identity.
        """
        try:
            return self.buffer.lookup(self.base_frame, frame_id, stamp_ns)
        except TransformLookupError:
            return None

    def location(self, frame_id: str, stamp_ns: int = 0) -> tuple[float, float, float] | None:
        """(x, y, z) metres of ``frame_id``'s origin in the base frame; None when unknown."""
        if not frame_id:
            return None
        mat = self.base_from(frame_id, stamp_ns)
        if mat is None:
            return None
        return float(mat[0, 3]), float(mat[1, 3]), float(mat[2, 3])


def first_frame_ids(log: LogReader, topics: Sequence[str]) -> dict[str, str]:
    """topic → frame id of its first decodable message (one message per topic is read)."""
    out: dict[str, str] = {}
    for topic in topics:
        info = log.topics.get(topic)
        if info is None:
            continue
        for message in log.messages(topics=[topic]):
            if decoder_for(message.msgtype) is None and message.encoding != "native":
                break
            with contextlib.suppress(UnsupportedMessageError):
                out[topic] = decode(message, log.deserialize).frame_id
            break
    return out


def mount_tf_topics(
    log: LogReader,
    *,
    tf_topics: Sequence[str],
    sensor_topics: Sequence[str],
    base_frame: str = BASE_FRAME,
) -> list[str]:
    """Which of ``tf_topics`` to read so that every sensor's mount is known.

    The static ones always; the dynamic ones (``/tf``) only when the static transforms leave a
    sensor frame unconnected to ``base_frame`` (its mount is on ``/tf``, or nowhere).
    """
    static = [t for t in tf_topics if is_static_tf_topic(t)]
    dynamic = [t for t in tf_topics if t not in static]
    if not dynamic:
        return list(static)
    if not static:
        return list(tf_topics)
    mounts = SensorMounts(base_frame=base_frame)
    for message in log.messages(topics=static):
        try:
            value = decode(message, log.deserialize).value
        except UnsupportedMessageError as err:
            logger.debug("%s: %s", log.path, err)
            continue
        if isinstance(value, tuple):
            mounts.add(message.topic, (t for t in value if isinstance(t, Transform)))
    frames = first_frame_ids(log, sensor_topics)
    if all(mounts.base_from(f) is not None for f in frames.values() if f):
        return list(static)
    return list(tf_topics)
