"""Camera calibrations of a log: intrinsics (``CameraInfo``) + extrinsics (``/tf_static``).

:func:`camera_calibrations` answers "how do points of ``base_link`` land in this camera's
pixels?" for every camera of a log that says so itself:

- its intrinsics come from the first ``sensor_msgs/CameraInfo`` message of each camera info
  topic (the KITTI reader yields them natively, from ``P2``);
- its mount comes from the static transforms (``/tf_static`` and namespaced ``…/tf_static``):
  ``base_link`` → the camera info's header frame (the optical frame);
- camera info topics are paired with image topics by namespace, as ``image_transport`` lays them
  out: ``/ns/camera_info`` serves ``/ns/image_raw``, ``/ns/image_rect_color``,
  ``/ns/image_raw/compressed`` … — every image topic directly in ``/ns`` (or its
  ``…/compressed``).

Only those topics are read, and reading stops as soon as every camera info topic has given one
message and the static transforms connect each camera: a long log is never scanned.  Dynamic
``/tf`` is not read (camera mounts are static).  Cameras without a camera info, uncalibrated ones
(K and P zero) and cameras the static transforms do not connect to the base frame are left out
(logged at DEBUG).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.assembly.tf_buffer import TransformBuffer, TransformLookupError
from redrive.errors import UnsupportedMessageError
from redrive.io.base import LogReader, TopicInfo
from redrive.io.ros.decoders import decode, topic_kind
from redrive.io.ros.decoders.base import DecodedKind
from redrive.io.ros.decoders.tf import is_static_tf_topic
from redrive.types import CameraInfo, SensorType, Transform
from redrive.types._arrays import frozen_array

__all__ = [
    "CameraCalibration",
    "camera_calibrations",
    "camera_info_topics",
    "static_tf_topics",
    "static_transforms",
]

logger = logging.getLogger(__name__)

#: Sub-topics of an image topic that are still that camera's images (image_transport).
_TRANSPORTS = frozenset({"compressed"})


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraCalibration:
    """How points of the base frame project into one camera's image.

    Attributes:
        image_topic: the camera's image topic (``/camera_front/image_raw``).
        info_topic: the camera info topic it was read from (``/camera_front/camera_info``).
        frame_id: the camera's optical frame (the camera info's header frame; z forward, x right,
            y down).
        base_frame: the frame ``base_from_optical`` maps into (``base_link``).
        stamp_ns: header stamp of the camera info message used, int ns.
        info: the intrinsics.
        base_from_optical: (4, 4) float64 rigid transform, optical frame → base frame (m).
    """

    image_topic: str
    info_topic: str
    frame_id: str
    base_frame: str
    stamp_ns: int
    info: CameraInfo
    base_from_optical: npt.NDArray[np.float64]

    def __post_init__(self) -> None:
        matrix = frozen_array(
            self.base_from_optical,
            name="CameraCalibration.base_from_optical",
            dtype=np.float64,
            shape=(4, 4),
        )
        object.__setattr__(self, "base_from_optical", matrix)

    def image_from_base(self) -> npt.NDArray[np.float64]:
        """(3, 4) float64: base-frame points (m, homogeneous) → pixels (homogeneous).

        ``info.image_from_optical() @ inv(base_from_optical)``; use it with
        :func:`redrive.geometry.project_points` (points in the base frame, (N, 3) m).
        """
        optical_from_base = np.linalg.inv(self.base_from_optical)
        out: npt.NDArray[np.float64] = self.info.image_from_optical() @ optical_from_base
        return out


def _namespace(topic: str) -> str:
    """``/a/b/camera_info`` → ``/a/b``; ``/camera_info`` → ``""`` (the root)."""
    return topic.rstrip("/").rsplit("/", 1)[0]


def _in_namespace(image_topic: str, namespace: str) -> bool:
    if not image_topic.startswith(namespace + "/"):
        return False
    parts = image_topic[len(namespace) + 1 :].split("/")
    return len(parts) == 1 or (len(parts) == 2 and parts[1] in _TRANSPORTS)


def camera_info_topics(topics: Mapping[str, TopicInfo]) -> dict[str, str]:
    """Image topic → the camera info topic of its namespace, for every image topic that has one.

    ``topics`` is a log's :attr:`~redrive.io.base.LogReader.topics`.  Image topics are those
    decoded as camera samples (``Image``, ``CompressedImage``); camera info topics those of
    type ``sensor_msgs/CameraInfo``.
    """
    infos: dict[str, str] = {}  # namespace → info topic
    images: list[str] = []
    for topic, info in topics.items():
        kind = topic_kind(info)
        if kind == (DecodedKind.CAMERA_INFO, None):
            infos.setdefault(_namespace(topic), topic)
        elif kind == (DecodedKind.SENSOR, SensorType.CAMERA):
            images.append(topic)
    out: dict[str, str] = {}
    for image in sorted(images):
        for namespace, info_topic in infos.items():
            if _in_namespace(image, namespace):
                out[image] = info_topic
                break
    return out


class _Search:
    """What has been read so far: the first camera info of each topic, the static transforms."""

    def __init__(self, log: LogReader, *, info_topics: set[str], max_messages: int) -> None:
        self.log = log
        self.info_topics = info_topics
        self.max_messages = max_messages
        self.infos: dict[str, tuple[str, int, CameraInfo]] = {}  # topic → (frame, stamp, info)
        self.transforms: list[Transform] = []
        self.buffer = TransformBuffer()
        self.read = 0

    def add_transforms(self, transforms: Iterable[Transform]) -> None:
        for transform in transforms:
            try:
                self.buffer.add(transform, static=True)
            except ValueError as err:
                logger.debug("%s: static transform skipped: %s", self.log.path, err)
                continue
            self.transforms.append(transform)

    def connected(self, base_frame: str) -> bool:
        """Every camera info read so far has a transform from ``base_frame``."""
        return all(
            _resolve(self.buffer, base_frame, frame_id) is not None
            for frame_id, _, _ in self.infos.values()
        )

    def read_messages(
        self,
        topics: list[str],
        *,
        start_ns: int | None,
        stop_ns: int | None = None,
        done: Callable[[], bool],
    ) -> int | None:
        """Read ``topics`` in ``[start_ns, stop_ns)`` until ``done()``; the last log time read."""
        last_ns: int | None = None
        for message in self.log.messages(topics=topics, start_ns=start_ns, stop_ns=stop_ns):
            if self.read >= self.max_messages:
                logger.debug("%s: stopped after %d messages", self.log.path, self.read)
                break
            self.read += 1
            last_ns = message.log_time_ns
            if message.topic in self.info_topics and message.topic in self.infos:
                continue
            try:
                decoded = decode(message, self.log.deserialize)
            except UnsupportedMessageError as err:
                logger.debug("%s: %s", self.log.path, err)
                continue
            value = decoded.value
            if isinstance(value, CameraInfo):
                self.infos[message.topic] = (decoded.frame_id, decoded.stamp_ns, value)
            elif isinstance(value, tuple):
                self.add_transforms(t for t in value if isinstance(t, Transform))
            if done():
                break
        return last_ns


def _resolve(
    buffer: TransformBuffer, base_frame: str, frame_id: str
) -> npt.NDArray[np.float64] | None:
    try:
        return buffer.lookup(base_frame, frame_id, 0)
    except TransformLookupError:
        return None


def static_tf_topics(log: LogReader) -> list[str]:
    """The log's static transform topics (``/tf_static`` and namespaced ``…/tf_static``)."""
    return sorted(
        t
        for t, info in log.topics.items()
        if is_static_tf_topic(t) and topic_kind(info) == (DecodedKind.TRANSFORMS, None)
    )


def static_transforms(log: LogReader, *, max_messages: int = 10_000) -> TransformBuffer:
    """Every static transform of ``log`` (sensor mounts) in one buffer; look them up at stamp 0.

    Reads only the static transform topics, at most ``max_messages`` messages.
    """
    search = _Search(log, info_topics=set(), max_messages=max_messages)
    search.read_messages(static_tf_topics(log), start_ns=None, done=lambda: False)
    return search.buffer


def camera_calibrations(
    log: LogReader,
    *,
    base_frame: str = "base_link",
    stamp_ns: int | None = None,
    max_messages: int = 10_000,
) -> dict[str, CameraCalibration]:
    """The calibration of every camera of ``log`` that has a camera info and a static mount.

    Args:
        log: an open log.
        base_frame: the frame the calibrations map from (``base_link``; the KITTI reader makes
            its velodyne frame ``base_link`` too).
        stamp_ns: use the first camera infos at or after this log time (default: from the log's
            start).  A log's calibration is normally constant; KITTI object folders are the
            exception — every frame comes from another drive — so pass the frame's stamp there.
            The static transforms published from ``stamp_ns`` on are used; when they do not
            connect a camera, those published before it are read too (the later ones win).
        max_messages: read at most this many messages in all, whatever is still missing.

    Returns:
        image topic → calibration, for every image topic paired with a camera info topic (see
        :func:`camera_info_topics`) whose camera is calibrated and mounted; one camera info
        serves all the image topics of its namespace.
    """
    pairs = camera_info_topics(log.topics)
    info_topics = set(pairs.values())
    for topic, info in log.topics.items():
        if topic_kind(info) == (DecodedKind.CAMERA_INFO, None) and topic not in info_topics:
            logger.debug("%s: camera info %s serves no image topic", log.path, topic)
    if not info_topics:
        logger.debug("%s: no camera info topic next to an image topic", log.path)
        return {}
    tf_topics = static_tf_topics(log)
    search = _Search(log, info_topics=info_topics, max_messages=max_messages)
    last_ns = search.read_messages(
        sorted(info_topics) + tf_topics,
        start_ns=stamp_ns,
        done=lambda: len(search.infos) == len(info_topics),
    )
    if tf_topics and search.infos and not search.connected(base_frame):
        # the camera infos are read (or the end or the limit is reached): go on with the
        # static transforms alone, not through the camera infos that follow
        search.read_messages(tf_topics, start_ns=last_ns, done=lambda: search.connected(base_frame))
    if tf_topics and search.infos and stamp_ns is not None and not search.connected(base_frame):
        # the transforms published before stamp_ns (recorders latch /tf_static at the start),
        # then those read above again, so the later ones win
        later = search.transforms
        search.transforms, search.buffer = [], TransformBuffer()
        search.read_messages(tf_topics, start_ns=None, stop_ns=stamp_ns, done=lambda: False)
        search.add_transforms(later)
    return _calibrations(log, pairs, search, base_frame=base_frame)


def _calibrations(
    log: LogReader, pairs: Mapping[str, str], search: _Search, *, base_frame: str
) -> dict[str, CameraCalibration]:
    buffer = search.buffer
    out: dict[str, CameraCalibration] = {}
    for image_topic, info_topic in pairs.items():
        found = search.infos.get(info_topic)
        if found is None:
            logger.debug("%s: %s: no message on %s", log.path, image_topic, info_topic)
            continue
        frame_id, stamp_ns, info = found
        if not info.is_calibrated:
            logger.debug("%s: %s: %s is not calibrated", log.path, image_topic, info_topic)
            continue
        base_from_optical = _resolve(buffer, base_frame, frame_id)
        if base_from_optical is None:
            logger.debug(
                "%s: %s: no static transform %s → %r (camera info frame)",
                log.path,
                image_topic,
                base_frame,
                frame_id,
            )
            continue
        out[image_topic] = CameraCalibration(
            image_topic=image_topic,
            info_topic=info_topic,
            frame_id=frame_id,
            base_frame=base_frame,
            stamp_ns=stamp_ns,
            info=info,
            base_from_optical=base_from_optical,
        )
    return out
