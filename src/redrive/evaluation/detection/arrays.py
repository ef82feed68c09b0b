"""Objects of many frames as one set of columns (what the vectorised detection metrics read).

Ground truth and detections arrive per frame as tuples of :class:`~redrive.types.DetectedObject`;
the metrics turn them once into :class:`ObjectArrays` (one array per field, rows sorted by frame,
the order inside a frame kept) and never touch Python objects per box pair again.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.types import DetectedObject, ObjectClass

__all__ = ["CLASS_CODES", "ObjectArrays", "class_codes", "objects_to_arrays"]

#: ObjectClass → small int code (the order of the enum); ``ObjectArrays.object_class`` holds these.
CLASS_CODES: Mapping[ObjectClass, int] = {c: i for i, c in enumerate(ObjectClass)}
_CLASSES: tuple[ObjectClass, ...] = tuple(ObjectClass)

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


def class_codes(values: Iterable[str | ObjectClass]) -> I64:
    """Codes of ObjectClass members given by member or value (``"vehicle"``)."""
    return np.array([CLASS_CODES[ObjectClass(v)] for v in values], dtype=np.int64)


@dataclass(frozen=True, slots=True, kw_only=True)
class ObjectArrays:
    """N objects of many frames, one array per field, rows sorted by frame (stable).

    Attributes:
        frame: (N,) int64 frame index of each object.
        object_class: (N,) int64 code of its ObjectClass (:data:`CLASS_CODES`).
        center: (N, 3) float64 box centre, metres, base_link of its frame (x forward, y left).
        size: (N, 3) float64 length, width, height, metres.
        yaw_rad: (N,) float64 heading about +z, radians.
        velocity: (N, 3) float64 m/s, same frame.
        score: (N,) float64 confidence in [0, 1] (1 for ground truth).
        num_points: (N,) int64 LiDAR points on the object; -1 when unknown.
    """

    frame: I64
    object_class: I64
    center: F64
    size: F64
    yaw_rad: F64
    velocity: F64
    score: F64
    num_points: I64

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    @property
    def ego_distance_m(self) -> F64:
        """BEV distance of each centre from the base_link origin, metres (nuScenes ``ego_dist``)."""
        return np.asarray(np.hypot(self.center[:, 0], self.center[:, 1]), dtype=np.float64)

    def subset(self, mask_or_index: npt.NDArray[np.bool_] | I64) -> ObjectArrays:
        """The rows selected by a boolean mask or increasing index array (order kept)."""
        m = mask_or_index
        return ObjectArrays(
            frame=self.frame[m],
            object_class=self.object_class[m],
            center=self.center[m],
            size=self.size[m],
            yaw_rad=self.yaw_rad[m],
            velocity=self.velocity[m],
            score=self.score[m],
            num_points=self.num_points[m],
        )

    @classmethod
    def empty(cls) -> ObjectArrays:
        return cls.from_columns(
            frame=np.zeros(0, np.int64),
            object_class=np.zeros(0, np.int64),
            center=np.zeros((0, 3)),
            size=np.zeros((0, 3)),
            yaw_rad=np.zeros(0),
        )

    @classmethod
    def from_columns(
        cls,
        *,
        frame: npt.ArrayLike,
        object_class: npt.ArrayLike,
        center: npt.ArrayLike,
        size: npt.ArrayLike,
        yaw_rad: npt.ArrayLike,
        velocity: npt.ArrayLike | None = None,
        score: npt.ArrayLike | None = None,
        num_points: npt.ArrayLike | None = None,
    ) -> ObjectArrays:
        """Columns → arrays (checked, copied, sorted by frame with a stable sort)."""
        f = np.asarray(frame, dtype=np.int64).reshape(-1)
        n = f.shape[0]
        c = np.asarray(center, dtype=np.float64).reshape(n, 3)
        s = np.asarray(size, dtype=np.float64).reshape(n, 3)
        y = np.asarray(yaw_rad, dtype=np.float64).reshape(n)
        v = np.zeros((n, 3)) if velocity is None else np.asarray(velocity, np.float64).reshape(n, 3)
        sc = np.ones(n) if score is None else np.asarray(score, np.float64).reshape(n)
        npts = (
            np.full(n, -1, np.int64)
            if num_points is None
            else np.asarray(num_points, np.int64).reshape(n)
        )
        oc = np.asarray(object_class, dtype=np.int64).reshape(n)
        order = np.argsort(f, kind="stable")
        if n and np.any(order != np.arange(n)):
            f, oc, npts = f[order], oc[order], npts[order]
            c, s, y, v, sc = c[order], s[order], y[order], v[order], sc[order]
        return cls(
            frame=f,
            object_class=oc,
            center=c,
            size=s,
            yaw_rad=y,
            velocity=v,
            score=sc,
            num_points=npts,
        )


def objects_to_arrays(
    per_frame: Mapping[int, Sequence[DetectedObject]], frames: Iterable[int]
) -> ObjectArrays:
    """The objects of ``frames`` (in increasing frame order; absent frames contribute none)."""
    rows: list[DetectedObject] = []
    frame_of: list[int] = []
    for f in sorted(set(frames)):
        objs = per_frame.get(f, ())
        rows.extend(objs)
        frame_of.extend([f] * len(objs))
    n = len(rows)
    if n == 0:
        return ObjectArrays.empty()
    center = np.empty((n, 3))
    size = np.empty((n, 3))
    velocity = np.empty((n, 3))
    for i, o in enumerate(rows):
        center[i] = o.box.center
        size[i] = o.box.size
        velocity[i] = o.velocity
    return ObjectArrays.from_columns(
        frame=frame_of,
        object_class=[CLASS_CODES[o.object_class] for o in rows],
        center=center,
        size=size,
        yaw_rad=[o.box.yaw_rad for o in rows],
        velocity=velocity,
        score=[o.confidence for o in rows],
        num_points=[-1 if o.num_lidar_points is None else o.num_lidar_points for o in rows],
    )


def class_name(code: int) -> str:
    """The ObjectClass value of a code."""
    return _CLASSES[code].value
