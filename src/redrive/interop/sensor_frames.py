"""Each sensor frame of a run's log placed on ``base_link`` in the export, as the run placed it.

A run's boxes are in ``base_link``; a viewer draws a cloud in its header's frame, so a sensor
frame without a transform chain to ``base_link`` leaves the boxes and the cloud in two
unconnected trees (the Luminar bag of ``../shared/data``: ``luminar_lidar`` and nothing else).
:func:`sensor_mount_transforms` gives each sensor frame of the run's sensor map that the log's
static transforms (and, when the export keeps it, the log's ``/tf``) do not connect a transform
``base_link → frame``, from what the Sensor Dispatcher used when the run ran
(:class:`~redrive.assembly.frames.FrameAssembler`: the sensor map's ``location``, else the log's
mounts, else the sensor at ``base_link``'s origin):

1. the ``location`` of a ``--sensor-map`` file: that translation, axes parallel (the data model
   has no mount rotation, so the run took them parallel);
2. the log's ``/tf`` (read for its first second) when it holds the mount and the export leaves
   ``/tf`` out — the full transform, rotation included;
3. otherwise the identity, with a warning: the run took the sensor to sit at ``base_link``'s
   origin, and the export shows it there.

A frame the log's static transforms connect (or its ``/tf``, when the export keeps it) is left
as the log has it, a ``location`` notwithstanding: a frame has one parent.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Sequence

import numpy as np

from redrive.assembly.mounts import BASE_FRAME, SensorMounts
from redrive.assembly.sensor_map import SensorMapOverrides, infer_sensor_map
from redrive.errors import ConfigError, UnsupportedMessageError
from redrive.geometry.se3 import transform_from_matrix
from redrive.io.base import LogReader
from redrive.io.ros.decoders import decode, decoder_for
from redrive.io.ros.decoders.tf import is_static_tf_topic
from redrive.types import Transform

__all__ = ["sensor_mount_transforms"]

logger = logging.getLogger(__name__)

_SEC = 1_000_000_000


def _frame_ids(reader: LogReader, topics: Sequence[str]) -> dict[str, str]:
    """topic → the frame id of its first message, in one pass from the log's start (a reader
    decompresses each chunk once) that ends when every topic has given one: the ROS message's
    header frame — the frame a viewer draws the log's own message in — else the decoder's."""
    wanted = {t for t in topics if t in reader.topics}
    out: dict[str, str] = {}
    seen: set[str] = set()
    if not wanted:
        return out
    for message in reader.messages(topics=wanted):
        if message.topic in seen:
            continue
        seen.add(message.topic)
        if message.encoding != "native" and decoder_for(message.msgtype) is not None:
            with contextlib.suppress(UnsupportedMessageError):  # the header, not the cloud
                header = getattr(reader.deserialize(message), "header", None)
                frame = getattr(header, "frame_id", None)
                if isinstance(frame, str):
                    out[message.topic] = frame
        if message.topic not in out and (
            decoder_for(message.msgtype) is not None or message.encoding == "native"
        ):
            with contextlib.suppress(UnsupportedMessageError):
                out[message.topic] = decode(message, reader.deserialize).frame_id
        if seen == wanted:
            break
    return out


def _dynamic_mounts(reader: LogReader, static: Sequence[Transform]) -> SensorMounts:
    """The static transforms and the log's ``/tf`` messages of its first second."""
    mounts = SensorMounts()
    mounts.add("/tf_static", static)
    dynamic = [
        t
        for t in reader.topics
        if (t.rstrip("/").endswith("/tf") or t == "tf") and not is_static_tf_topic(t)
    ]
    if dynamic:
        stop = reader.start_ns + _SEC
        for message in reader.messages(topics=dynamic, stop_ns=stop):
            try:
                value = decode(message, reader.deserialize).value
            except UnsupportedMessageError as err:
                logger.debug("%s: %s", reader.path, err)
                continue
            if isinstance(value, tuple):
                mounts.add(message.topic, (t for t in value if isinstance(t, Transform)))
    return mounts


def sensor_mount_transforms(
    reader: LogReader,
    *,
    static: Sequence[Transform],
    log_tf_kept: bool,
    overrides: SensorMapOverrides | None = None,
) -> tuple[Transform, ...]:
    """``base_link → sensor frame`` for each sensor frame the log's transforms in the export
    leave unconnected (see the module text); ``static``: the log's static transforms,
    ``log_tf_kept``: the export passes the log's ``/tf`` on."""
    try:
        smap = infer_sensor_map(
            reader.topics, duration_ns=reader.end_ns - reader.start_ns, overrides=overrides
        )
    except ConfigError:
        return ()
    frames = _frame_ids(reader, [s.topic for s in smap.sensors])
    placed = SensorMounts()
    placed.add("/tf_static", static)
    dynamic: SensorMounts | None = None
    out: dict[str, Transform] = {}
    for spec in smap.sensors:
        frame = frames.get(spec.topic, "")
        if not frame or frame in out or placed.base_from(frame) is not None:
            continue
        if dynamic is None:
            dynamic = _dynamic_mounts(reader, static)
        mat = dynamic.base_from(frame, reader.start_ns)
        if mat is not None and log_tf_kept:
            continue  # the log's own /tf, in the export, connects it (a frame has one parent)
        if spec.location is not None:  # what the run used first
            out[frame] = Transform(
                parent_frame=BASE_FRAME,
                child_frame=frame,
                translation=np.asarray(spec.location, dtype=np.float64),
            )
            continue
        if mat is not None:
            out[frame] = transform_from_matrix(mat, parent_frame=BASE_FRAME, child_frame=frame)
            continue
        logger.warning(
            "%s: no transform from %r (topic %s) to %s in the log or the sensor map; the run "
            "took the sensor to sit at %s's origin, and the export places it there (identity "
            "assumed — give its location in a sensor map, --sensor-map, to place it)",
            reader.path,
            frame,
            spec.topic,
            BASE_FRAME,
            BASE_FRAME,
        )
        out[frame] = Transform(parent_frame=BASE_FRAME, child_frame=frame)
    return tuple(out.values())
