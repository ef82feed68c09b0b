"""Shapes → ``visualization_msgs/msg/MarkerArray`` (ROS 2), for RViz users.

The same :class:`~redrive.interop.shapes.ShapeSet` a SceneUpdate is made of: a ``DELETEALL``
marker first (the array replaces what the topic showed), then a ``CUBE`` per box (namespace
``boxes``), an ``ARROW`` per moving box (``velocity``: from the box centre along its velocity,
``scale.x`` its speed in m/s as metres), a ``LINE_STRIP`` per line (``lines``) and a
``TEXT_VIEW_FACING`` per label (``labels``) and a ``TRIANGLE_LIST`` per filled surface
(``triangles``, ``scale`` 1).  Marker ids count up within each array.

:func:`marker_array` gives the message as an object of a ``rosbags`` typestore;
:func:`marker_array_cdr` gives its CDR bytes directly — the same bytes ``serialize_cdr`` makes of
that object (a test compares them), written without the 20-odd message objects per marker, which
cost most of the export's time in scene messages.
"""

from __future__ import annotations

import struct
from typing import Any, NamedTuple

import numpy as np
from rosbags.typesys.store import Typestore

from redrive.interop.shapes import (
    Color,
    ShapeSet,
    arrow_yaw_pitch,
    yaw_pitch_quaternion,
    yaw_quaternion,
)

__all__ = ["MARKER_ARRAY", "marker_array", "marker_array_cdr"]

MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
_CUBE, _ARROW, _LINE_STRIP, _TEXT, _DELETEALL, _TRIANGLE_LIST = 1, 0, 4, 9, 3, 11
_EMPTY_BYTES = np.zeros(0, dtype=np.uint8)


class _Marker(NamedTuple):
    ns: str
    kind: int
    action: int = 0
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quaternion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    color: Color = (1.0, 1.0, 1.0, 1.0)
    points: tuple[tuple[float, float, float], ...] = ()
    text: str = ""


def _markers(shapes: ShapeSet) -> list[_Marker]:
    """What the array holds, marker by marker (ids are the positions in the list)."""
    out = [_Marker(ns="", kind=_CUBE, action=_DELETEALL)]
    for box in shapes.boxes:
        out.append(
            _Marker(
                ns="boxes",
                kind=_CUBE,
                position=box.center,
                quaternion=yaw_quaternion(box.yaw_rad),
                scale=box.size,
                color=box.color,
            )
        )
        if box.velocity is not None:
            length, yaw, pitch = arrow_yaw_pitch(box.velocity)
            if length > 0.1:
                out.append(
                    _Marker(
                        ns="velocity",
                        kind=_ARROW,
                        position=box.center,
                        quaternion=yaw_pitch_quaternion(yaw, pitch),
                        scale=(length, 0.15, 0.3),
                        color=(box.color[0], box.color[1], box.color[2], 1.0),
                    )
                )
    for line in shapes.lines:
        out.append(
            _Marker(
                ns="lines",
                kind=_LINE_STRIP,
                scale=(line.width_m, 0.0, 0.0),
                color=line.color,
                points=line.points,
            )
        )
    for surface in shapes.triangles:
        out.append(
            _Marker(ns="triangles", kind=_TRIANGLE_LIST, color=surface.color, points=surface.points)
        )
    for label in shapes.labels:
        out.append(
            _Marker(
                ns="labels",
                kind=_TEXT,
                position=label.position,
                scale=(0.0, 0.0, label.size_m),
                color=label.color,
                text=label.text,
            )
        )
    return out


def marker_array(shapes: ShapeSet, typestore: Typestore) -> Any:
    """The MarkerArray (a message object of ``typestore``, a ROS 2 store) of ``shapes``."""
    types = typestore.types
    sec, nanosec = divmod(int(shapes.stamp_ns), 1_000_000_000)
    header = types["std_msgs/msg/Header"](
        stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
        frame_id=shapes.frame_id,
    )

    def vector(msgtype: str, xyz: tuple[float, float, float]) -> Any:
        return types[msgtype](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))

    items = []
    for i, m in enumerate(_markers(shapes)):
        q, c = m.quaternion, m.color
        pose = types["geometry_msgs/msg/Pose"](
            position=vector("geometry_msgs/msg/Point", m.position),
            orientation=types["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        )
        items.append(
            types["visualization_msgs/msg/Marker"](
                header=header,
                ns=m.ns,
                id=i,
                type=m.kind,
                action=m.action,
                pose=pose,
                scale=vector("geometry_msgs/msg/Vector3", m.scale),
                color=types["std_msgs/msg/ColorRGBA"](r=c[0], g=c[1], b=c[2], a=c[3]),
                lifetime=types["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
                frame_locked=False,
                points=[vector("geometry_msgs/msg/Point", p) for p in m.points],
                colors=[],
                texture_resource="",
                texture=types["sensor_msgs/msg/CompressedImage"](
                    header=types["std_msgs/msg/Header"](
                        stamp=types["builtin_interfaces/msg/Time"](sec=0, nanosec=0),
                        frame_id="",
                    ),
                    format="",
                    data=_EMPTY_BYTES,
                ),
                uv_coordinates=[],
                text=m.text,
                mesh_resource="",
                mesh_file=types["visualization_msgs/msg/MeshFile"](filename="", data=_EMPTY_BYTES),
                mesh_use_embedded_materials=False,
            )
        )
    return types[MARKER_ARRAY](markers=items)


# -- CDR (little endian, XCDR1 as ROS 2 writes it): the layout of visualization_msgs/msg/Marker --
# Alignment counts from after the 4-byte encapsulation header; a field of n bytes starts at a
# multiple of n.  What is the same in every marker is packed once below.

_U32 = struct.Struct("<I")
_I32X3 = struct.Struct("<iii")  # id, type, action
# pose (position, orientation), scale, color, lifetime (sec, nanosec), frame_locked: no padding
_BODY = struct.Struct("<10d4fiI?")
_POINT = struct.Struct("<3d")
_ZEROS = bytes(8)


def _string(text: str) -> bytes:
    data = text.encode("utf-8")
    return _U32.pack(len(data) + 1) + data + b"\0"


_EMPTY_STRING = _string("")
_EMPTY_SEQ = _U32.pack(0)
# from colors (4-aligned) to text: colors [], texture_resource "", texture (header stamp 0 0,
# frame_id "", format "", data []), uv_coordinates []
_MIDDLE = b"".join(
    (
        _EMPTY_SEQ,
        _EMPTY_STRING + _ZEROS[:3],
        _U32.pack(0) + _U32.pack(0),
        _EMPTY_STRING + _ZEROS[:3],
        _EMPTY_STRING + _ZEROS[:3],
        _EMPTY_SEQ,
        _EMPTY_SEQ,
    )
)
# from mesh_resource (4-aligned) to the end: mesh_resource "", mesh_file ("", []),
# mesh_use_embedded_materials False
_TAIL = _EMPTY_STRING + _ZEROS[:3] + _EMPTY_STRING + _ZEROS[:3] + _EMPTY_SEQ + b"\0"


def marker_array_cdr(shapes: ShapeSet) -> bytes:
    """The CDR bytes of :func:`marker_array`'s message (ROS 2, little endian)."""
    sec, nanosec = divmod(int(shapes.stamp_ns), 1_000_000_000)
    head = struct.pack("<iI", sec, nanosec) + _string(shapes.frame_id)
    namespaces: dict[str, bytes] = {}
    markers = _markers(shapes)
    buf = bytearray(b"\x00\x01\x00\x00")  # CDR_LE, options 0
    buf += _U32.pack(len(markers))
    for i, m in enumerate(markers):
        buf += _ZEROS[: -(len(buf) - 4) % 4]
        buf += head
        buf += _ZEROS[: -(len(buf) - 4) % 4]
        ns = namespaces.get(m.ns)
        if ns is None:
            ns = namespaces[m.ns] = _string(m.ns)
        buf += ns
        buf += _ZEROS[: -(len(buf) - 4) % 4]
        buf += _I32X3.pack(i, m.kind, m.action)
        buf += _ZEROS[: -(len(buf) - 4) % 8]
        p, q, sc, c = m.position, m.quaternion, m.scale, m.color
        buf += _BODY.pack(
            float(p[0]), float(p[1]), float(p[2]), q[0], q[1], q[2], q[3],
            float(sc[0]), float(sc[1]), float(sc[2]), c[0], c[1], c[2], c[3], 0, 0, False,
        )  # fmt: skip
        buf += _ZEROS[: -(len(buf) - 4) % 4]
        buf += _U32.pack(len(m.points))
        if m.points:
            buf += _ZEROS[: -(len(buf) - 4) % 8]
            for point in m.points:
                buf += _POINT.pack(float(point[0]), float(point[1]), float(point[2]))
        buf += _MIDDLE
        buf += _string(m.text)
        buf += _ZEROS[: -(len(buf) - 4) % 4]
        buf += _TAIL
    return bytes(buf)
