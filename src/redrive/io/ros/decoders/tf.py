"""``tf2_msgs/msg/TFMessage`` (ROS 1 bags: ``tf/msg/tfMessage``) → tuple of Transforms.

Each ``geometry_msgs/TransformStamped`` becomes ``Transform(parent_frame=header.frame_id,
child_frame=child_frame_id)``.  Messages on a ``tf_static`` topic are static: their transforms get
``stamp_ns == 0`` (the data model's mark of a static transform).  Frame names are kept as the log
wrote them; :class:`redrive.assembly.tf_buffer.TransformBuffer` strips leading slashes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from redrive.io.base import LogMessage
from redrive.io.ros.decoders._common import quat, stamp_ns_or, unsupported, vec3
from redrive.io.ros.decoders.base import Decoded, DecodedKind, Deserialize
from redrive.types import SensorType, Transform

__all__ = ["TFMessageDecoder", "is_static_tf_topic"]


def is_static_tf_topic(topic: str) -> bool:
    """True for ``/tf_static`` and namespaced ``…/tf_static`` topics."""
    return topic.rstrip("/").rsplit("/", 1)[-1] == "tf_static"


class TFMessageDecoder:
    """tf / tf_static messages → ``tuple[Transform, ...]`` (kind TRANSFORMS)."""

    name = "tf"
    msgtypes: tuple[str, ...] = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
    kind = DecodedKind.TRANSFORMS
    sensor_type: SensorType | None = None

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        static = is_static_tf_topic(message.topic)
        out: list[Transform] = []
        for item in msg.transforms:
            stamp_ns = 0 if static else stamp_ns_or(item.header.stamp, message.log_time_ns)
            try:
                out.append(
                    Transform(
                        parent_frame=str(item.header.frame_id),
                        child_frame=str(item.child_frame_id),
                        translation=np.array(vec3(item.transform.translation)),
                        rotation=np.array(quat(item.transform.rotation)),
                        stamp_ns=stamp_ns,
                    )
                )
            except ValueError as err:
                raise unsupported(
                    message,
                    f"transform {item.header.frame_id!r} → {item.child_frame_id!r} is invalid: {err}",
                    "fix the tf publisher, or drop this topic",
                ) from err
        first = msg.transforms[0] if msg.transforms else None
        stamp_ns = (
            stamp_ns_or(first.header.stamp, message.log_time_ns) if first else message.log_time_ns
        )
        frame_id = str(first.header.frame_id) if first else ""
        return Decoded(stamp_ns=stamp_ns, frame_id=frame_id, value=tuple(out))
