"""Objects: 3D boxes and detected (or ground-truth) objects."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

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
