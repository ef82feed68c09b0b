"""Objects: 3D boxes and detected (or ground-truth) objects."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import repeat
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.types._arrays import frozen_vector
from redrive.types.enums import ObjectClass

__all__ = ["Box3D", "DetectedObject"]


@dataclass(frozen=True, slots=True, kw_only=True)
class Box3D:
    """An oriented 3D box.

    Attributes:
        center: (3,) float64, metres, the geometric centre of the box in its frame.
        size: (3,) float64, metres, length (along the heading), width, height; all ≥ 0.
        yaw_rad: heading about +z, radians, counter-clockwise from +x.
    """

    center: npt.NDArray[np.float64]
    size: npt.NDArray[np.float64]
    yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", frozen_vector(self.center, name="Box3D.center", size=3))
        size = frozen_vector(self.size, name="Box3D.size", size=3)
        if np.any(size < 0) or not np.all(np.isfinite(size)):
            msg = f"Box3D.size must be finite and non-negative, got {size.tolist()}"
            raise ValueError(msg)
        object.__setattr__(self, "size", size)
        if not math.isfinite(self.yaw_rad):
            msg = f"Box3D.yaw_rad must be finite, got {self.yaw_rad}"
            raise ValueError(msg)
        object.__setattr__(self, "yaw_rad", float(self.yaw_rad))


def _zeros3() -> npt.NDArray[np.float64]:
    return np.zeros(3, dtype=np.float64)


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectedObject:
    """An object found by perception, or given as ground truth.

    Attributes:
        object_id: track / label id; -1 when none is known.
        object_class: what it is.
        confidence: in [0, 1]; 1.0 for ground truth.
        box: the oriented 3D box (frame: the frame of the message or frame it belongs to).
        velocity, acceleration: (3,) m/s and m/s² in the same frame.
        orientation: (3,) yaw, pitch, roll in radians.
        bbox_2d: optional (x, y, w, h) image box in pixels.
        num_lidar_points: ground truth only: LiDAR returns on the object in this frame (nuScenes'
            ``num_lidar_pts``; evaluation drops objects with none); ``None`` when unknown.
        visible: ground truth only: whether any sensor could see the object (not fully occluded
            or out of range); ``None`` when unknown.
    """

    object_id: int = -1
    object_class: ObjectClass = ObjectClass.UNKNOWN
    confidence: float = 1.0
    box: Box3D
    velocity: npt.NDArray[np.float64] = field(default_factory=_zeros3)
    acceleration: npt.NDArray[np.float64] = field(default_factory=_zeros3)
    orientation: npt.NDArray[np.float64] = field(default_factory=_zeros3)
    bbox_2d: tuple[float, float, float, float] | None = None
    num_lidar_points: int | None = None
    visible: bool | None = None

    def __post_init__(self) -> None:
        if self.num_lidar_points is not None and self.num_lidar_points < 0:
            msg = f"DetectedObject.num_lidar_points must be ≥ 0, got {self.num_lidar_points}"
            raise ValueError(msg)
        if not 0.0 <= self.confidence <= 1.0:
            msg = f"DetectedObject.confidence must lie in [0, 1], got {self.confidence}"
            raise ValueError(msg)
        for name in ("velocity", "acceleration", "orientation"):
            vec = frozen_vector(getattr(self, name), name=f"DetectedObject.{name}", size=3)
            object.__setattr__(self, name, vec)
        if self.bbox_2d is not None:
            if len(self.bbox_2d) != 4:
                msg = f"DetectedObject.bbox_2d must be (x, y, w, h), got {self.bbox_2d!r}"
                raise ValueError(msg)
            object.__setattr__(self, "bbox_2d", tuple(float(v) for v in self.bbox_2d))

    @classmethod
    def many(
        cls,
        *,
        object_classes: Sequence[ObjectClass],
        centers: npt.ArrayLike,
        sizes: npt.ArrayLike,
        yaws_rad: npt.ArrayLike,
        object_ids: Sequence[int] | None = None,
        confidences: npt.ArrayLike | None = None,
        velocities: npt.ArrayLike | None = None,
        accelerations: npt.ArrayLike | None = None,
        orientations: npt.ArrayLike | None = None,
        num_lidar_points: Sequence[int | None] | None = None,
        visible: Sequence[bool | None] | None = None,
    ) -> list[DetectedObject]:
        """N objects from columns: object i has ``object_classes[i]``, ``Box3D(center=centers[i],
        size=sizes[i], yaw_rad=yaws_rad[i])``, ``velocities[i]`` … (a column left out takes the
        field's default for every object).

        For code that makes many objects per frame (decoders, simulators, perception): the
        columns are checked once, with the checks ``DetectedObject(...)`` and ``Box3D(...)`` make
        (ValueError naming the column and the object's index), and the objects are the ones those
        constructors would give — float64, read-only (3,) row views of one frozen copy of each
        column — built without a Python ``__post_init__`` per object.
        """
        n = len(object_classes)
        centers_a = _column3(centers, "centers", n)
        sizes_a = _column3(sizes, "sizes", n)
        # The common case in C-level reductions (no numpy Python wrappers); the rows are looked
        # at only when there is a bad value, to name the first.
        if n and not (_ALL(np.isfinite(sizes_a), axis=None) and _MIN(sizes_a, axis=None) >= 0.0):
            bad = ~np.isfinite(sizes_a).all(axis=1) | (sizes_a < 0).any(axis=1)
            i = int(np.flatnonzero(bad)[0])
            msg = (
                f"DetectedObject.many: sizes[{i}] must be finite and non-negative, "
                f"got {sizes_a[i].tolist()}"
            )
            raise ValueError(msg)
        yaws = _column1(yaws_rad, "yaws_rad", n)
        if n and not _ALL(np.isfinite(yaws)):
            i = int(np.flatnonzero(~np.isfinite(yaws))[0])
            msg = f"DetectedObject.many: yaws_rad[{i}] must be finite, got {yaws[i]}"
            raise ValueError(msg)
        ids: Any = repeat(-1, n)
        if object_ids is not None:
            if len(object_ids) != n:
                raise ValueError(_length_msg("object_ids", len(object_ids), n))
            ids = [int(i) for i in object_ids]
        conf: Any = repeat(1.0, n)
        if confidences is not None:
            c = _column1(confidences, "confidences", n)
            if n and not (_MIN(c) >= 0.0 and _MAX(c) <= 1.0):  # NaN fails both
                bad = ~((c >= 0.0) & (c <= 1.0))
                i = int(np.flatnonzero(bad)[0])
                msg = f"DetectedObject.many: confidences[{i}] must lie in [0, 1], got {c[i]}"
                raise ValueError(msg)
            conf = c.tolist()
        points: Any = repeat(None, n)
        if num_lidar_points is not None:
            if len(num_lidar_points) != n:
                raise ValueError(_length_msg("num_lidar_points", len(num_lidar_points), n))
            points = [None if p is None else int(p) for p in num_lidar_points]
            for i, p in enumerate(points):
                if p is not None and p < 0:
                    msg = f"DetectedObject.many: num_lidar_points[{i}] must be ≥ 0, got {p}"
                    raise ValueError(msg)
        seen: Any = repeat(None, n)
        if visible is not None:
            if len(visible) != n:
                raise ValueError(_length_msg("visible", len(visible), n))
            seen = list(visible)
        boxes: list[Box3D] = list(map(object.__new__, repeat(Box3D, n)))
        any(map(_SET_BOX_CENTER, boxes, list(centers_a)))
        any(map(_SET_BOX_SIZE, boxes, list(sizes_a)))
        any(map(_SET_BOX_YAW, boxes, yaws.tolist()))
        objects: list[DetectedObject] = list(map(object.__new__, repeat(cls, n)))
        setters = _OBJECT_SETTERS
        any(map(setters["object_id"], objects, ids))
        any(map(setters["object_class"], objects, object_classes))
        any(map(setters["confidence"], objects, conf))
        any(map(setters["box"], objects, boxes))
        for name, column_name, column in (
            ("velocity", "velocities", velocities),
            ("acceleration", "accelerations", accelerations),
            ("orientation", "orientations", orientations),
        ):
            rows: Any = (
                repeat(_ZEROS3, n) if column is None else list(_column3(column, column_name, n))
            )
            any(map(setters[name], objects, rows))
        any(map(setters["bbox_2d"], objects, repeat(None, n)))
        any(map(setters["num_lidar_points"], objects, points))
        any(map(setters["visible"], objects, seen))
        return objects


def _length_msg(name: str, have: int, n: int) -> str:
    return f"DetectedObject.many: {name} has {have} values for {n} objects"


def _column3(value: Any, name: str, n: int) -> npt.NDArray[np.float64]:
    """``value`` as one read-only float64 (n, 3) array (a copy: the caller keeps its own)."""
    arr = np.array(value, dtype=np.float64)
    if arr.shape != (n, 3):
        msg = f"DetectedObject.many: {name} must have shape ({n}, 3), got {arr.shape}"
        raise ValueError(msg)
    arr.flags.writeable = False
    return arr


def _column1(value: Any, name: str, n: int) -> npt.NDArray[np.float64]:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (n,):
        msg = f"DetectedObject.many: {name} must have shape ({n},), got {arr.shape}"
        raise ValueError(msg)
    return arr


# The slots' own setters: what ``object.__setattr__`` ends in, without its lookup.
_SET_BOX_CENTER = Box3D.__dict__["center"].__set__
_SET_BOX_SIZE = Box3D.__dict__["size"].__set__
_SET_BOX_YAW = Box3D.__dict__["yaw_rad"].__set__
_OBJECT_SETTERS = {
    name: DetectedObject.__dict__[name].__set__
    for name in (
        "object_id",
        "object_class",
        "confidence",
        "box",
        "velocity",
        "acceleration",
        "orientation",
        "bbox_2d",
        "num_lidar_points",
        "visible",
    )
}
_ALL, _MIN, _MAX = np.logical_and.reduce, np.minimum.reduce, np.maximum.reduce
_ZEROS3 = np.zeros(3, dtype=np.float64)
_ZEROS3.flags.writeable = False
