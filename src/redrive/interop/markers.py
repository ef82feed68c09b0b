"""Shapes → ``visualization_msgs/msg/MarkerArray`` (ROS 2), for RViz users.

The same :class:`~redrive.interop.shapes.ShapeSet` a SceneUpdate is made of: a ``DELETEALL``
marker first (the array replaces what the topic showed), then a ``CUBE`` per box (namespace
``boxes``), an ``ARROW`` per moving box (``velocity``: from the box centre along its velocity,
``scale.x`` its speed in m/s as metres), a ``LINE_STRIP`` per line (``lines``) and a
``TEXT_VIEW_FACING`` per label (``labels``).  Marker ids count up within each array.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from rosbags.typesys.store import Typestore

from redrive.interop.shapes import (
    Color,
    ShapeSet,
    arrow_yaw_pitch,
    yaw_pitch_quaternion,
    yaw_quaternion,
)

__all__ = ["MARKER_ARRAY", "marker_array"]

MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
_CUBE, _ARROW, _LINE_STRIP, _TEXT, _DELETEALL = 1, 0, 4, 9, 3
_EMPTY_BYTES = np.zeros(0, dtype=np.uint8)


class _Markers:
    def __init__(self, typestore: Typestore, shapes: ShapeSet) -> None:
        self.ts = typestore
        sec, nanosec = divmod(int(shapes.stamp_ns), 1_000_000_000)
        self.header = self.new(
            "std_msgs/msg/Header",
            stamp=self.new("builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec),
            frame_id=shapes.frame_id,
        )
        self.items: list[Any] = []

    def new(self, msgtype: str, **fields: Any) -> Any:
        return self.ts.types[msgtype](**fields)

    def vector(self, msgtype: str, xyz: tuple[float, float, float]) -> Any:
        return self.new(msgtype, x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))

    def color(self, c: Color) -> Any:
        return self.new("std_msgs/msg/ColorRGBA", r=c[0], g=c[1], b=c[2], a=c[3])

    def add(
        self,
        *,
        ns: str,
        kind: int,
        action: int = 0,
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
        quaternion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
        scale: tuple[float, float, float] = (1.0, 1.0, 1.0),
        color: Color = (1.0, 1.0, 1.0, 1.0),
        points: tuple[tuple[float, float, float], ...] = (),
        text: str = "",
    ) -> None:
        pose = self.new(
            "geometry_msgs/msg/Pose",
            position=self.vector("geometry_msgs/msg/Point", position),
            orientation=self.new(
                "geometry_msgs/msg/Quaternion",
                x=quaternion[0],
                y=quaternion[1],
                z=quaternion[2],
                w=quaternion[3],
            ),
        )
        self.items.append(
            self.new(
                "visualization_msgs/msg/Marker",
                header=self.header,
                ns=ns,
                id=len(self.items),
                type=kind,
                action=action,
                pose=pose,
                scale=self.vector("geometry_msgs/msg/Vector3", scale),
                color=self.color(color),
                lifetime=self.new("builtin_interfaces/msg/Duration", sec=0, nanosec=0),
                frame_locked=False,
                points=[self.vector("geometry_msgs/msg/Point", p) for p in points],
                colors=[],
                texture_resource="",
                texture=self.new(
                    "sensor_msgs/msg/CompressedImage",
                    header=self.new(
                        "std_msgs/msg/Header",
                        stamp=self.new("builtin_interfaces/msg/Time", sec=0, nanosec=0),
                        frame_id="",
                    ),
                    format="",
                    data=_EMPTY_BYTES,
                ),
                uv_coordinates=[],
                text=text,
                mesh_resource="",
                mesh_file=self.new(
                    "visualization_msgs/msg/MeshFile", filename="", data=_EMPTY_BYTES
                ),
                mesh_use_embedded_materials=False,
            )
        )


def marker_array(shapes: ShapeSet, typestore: Typestore) -> Any:
    """The MarkerArray (a message object of ``typestore``, a ROS 2 store) of ``shapes``."""
    m = _Markers(typestore, shapes)
    m.add(ns="", kind=_CUBE, action=_DELETEALL)
    for box in shapes.boxes:
        m.add(
            ns="boxes",
            kind=_CUBE,
            position=box.center,
            quaternion=yaw_quaternion(box.yaw_rad),
            scale=box.size,
            color=box.color,
        )
        if box.velocity is not None:
            length, yaw, pitch = arrow_yaw_pitch(box.velocity)
            if length > 0.1:
                m.add(
                    ns="velocity",
                    kind=_ARROW,
                    position=box.center,
                    quaternion=yaw_pitch_quaternion(yaw, pitch),
                    scale=(length, 0.15, 0.3),
                    color=(box.color[0], box.color[1], box.color[2], 1.0),
                )
    for line in shapes.lines:
        m.add(
            ns="lines",
            kind=_LINE_STRIP,
            scale=(line.width_m, 0.0, 0.0),
            color=line.color,
            points=line.points,
        )
    for label in shapes.labels:
        m.add(
            ns="labels",
            kind=_TEXT,
            position=label.position,
            scale=(0.0, 0.0, label.size_m),
            color=label.color,
            text=label.text,
        )
    return typestore.types[MARKER_ARRAY](markers=m.items)
