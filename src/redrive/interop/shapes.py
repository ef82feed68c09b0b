"""What a run draws, as plain shapes: boxes, polylines and labels in a named frame.

One set of shapes per topic per frame becomes a ``foxglove.SceneUpdate`` (:mod:`.foxglove_msgs`)
and a ``visualization_msgs/msg/MarkerArray`` (:mod:`.markers`), so both views show the same
thing.  Rows come from a run's tables (:mod:`redrive.results.schema`): boxes are centred at
``x, y, z`` with ``length, width, height`` along the box's own x, y, z and turned by ``yaw_rad``
about z, in the frame the table says (``base_link`` for detections and ground truth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "BoxShape",
    "Color",
    "LabelShape",
    "LineShape",
    "ShapeSet",
    "TriangleShape",
    "class_color",
]

#: RGBA in [0, 1].
Color = tuple[float, float, float, float]

_CLASS_COLORS: dict[str, Color] = {
    "vehicle": (0.20, 0.55, 1.00, 0.45),
    "car": (0.20, 0.55, 1.00, 0.45),
    "truck": (0.10, 0.35, 0.85, 0.45),
    "bus": (0.10, 0.35, 0.85, 0.45),
    "pedestrian": (1.00, 0.60, 0.10, 0.55),
    "bicycle": (0.90, 0.20, 0.80, 0.55),
    "motorcycle": (0.90, 0.20, 0.80, 0.55),
}
_OTHER_CLASS: Color = (0.70, 0.70, 0.70, 0.45)


def class_color(object_class: str, *, alpha: float | None = None) -> Color:
    """The colour objects of ``object_class`` are drawn in (grey for classes not listed)."""
    r, g, b, a = _CLASS_COLORS.get(object_class.lower(), _OTHER_CLASS)
    return (r, g, b, a if alpha is None else alpha)


@dataclass(frozen=True, slots=True, kw_only=True)
class BoxShape:
    """An oriented box: centre (m), size (length, width, height; m), yaw (rad) about z.

    ``velocity`` (vx, vy, vz; m/s, same frame) is drawn as an arrow from the centre when its
    horizontal speed is above 0.1 m/s.
    """

    id: str
    center: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw_rad: float
    color: Color
    velocity: tuple[float, float, float] | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class LineShape:
    """A polyline through ``points`` (m); ``width_m`` is its drawn thickness."""

    id: str
    points: tuple[tuple[float, float, float], ...]
    color: Color
    width_m: float = 0.2


@dataclass(frozen=True, slots=True, kw_only=True)
class TriangleShape:
    """A filled surface: ``points`` (m) taken three at a time as triangles (a polygon's
    triangulation), all in one colour."""

    id: str
    points: tuple[tuple[float, float, float], ...]
    color: Color


@dataclass(frozen=True, slots=True, kw_only=True)
class LabelShape:
    """A text facing the viewer at ``position`` (m)."""

    id: str
    position: tuple[float, float, float]
    text: str
    color: Color = (1.0, 1.0, 1.0, 1.0)
    size_m: float = 0.8


@dataclass(frozen=True, slots=True, kw_only=True)
class ShapeSet:
    """Everything one topic shows at ``stamp_ns``, in ``frame_id``; it replaces what the topic
    showed before (an empty set clears it)."""

    stamp_ns: int
    frame_id: str
    boxes: tuple[BoxShape, ...] = ()
    lines: tuple[LineShape, ...] = ()
    labels: tuple[LabelShape, ...] = ()
    triangles: tuple[TriangleShape, ...] = ()

    @property
    def ids(self) -> tuple[str, ...]:
        shapes: tuple[BoxShape | LineShape | LabelShape | TriangleShape, ...] = (
            *self.boxes,
            *self.lines,
            *self.labels,
            *self.triangles,
        )
        return tuple(s.id for s in shapes)


def yaw_quaternion(yaw_rad: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw_rad`` about z."""
    return (0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0))


def arrow_yaw_pitch(vector: tuple[float, float, float]) -> tuple[float, float, float]:
    """(length, yaw, pitch) of ``vector``: the rotation that turns +x onto it."""
    vx, vy, vz = vector
    horizontal = math.hypot(vx, vy)
    return (
        math.sqrt(horizontal * horizontal + vz * vz),
        math.atan2(vy, vx),
        -math.atan2(vz, horizontal),
    )


def yaw_pitch_quaternion(yaw_rad: float, pitch_rad: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of yaw about z after pitch about y (roll 0)."""
    cy, sy = math.cos(yaw_rad / 2.0), math.sin(yaw_rad / 2.0)
    cp, sp = math.cos(pitch_rad / 2.0), math.sin(pitch_rad / 2.0)
    return (-sy * sp, cy * sp, sy * cp, cy * cp)
