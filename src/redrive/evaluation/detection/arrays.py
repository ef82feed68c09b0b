"""Objects of many frames as one :class:`~redrive.types.ObjectColumns` (what the vectorised
detection metrics read).

Ground truth and detections arrive per frame as tuples of :class:`~redrive.types.DetectedObject`;
the metrics turn them once into columns with :attr:`~redrive.types.ObjectColumns.frame_index`
set (rows sorted by frame, the order inside a frame kept) and never touch Python objects per box
pair again.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.types import CLASS_CODES, DetectedObject, ObjectClass, ObjectColumns

__all__ = ["CLASS_CODES", "boxes_by_frame", "class_codes", "objects_to_arrays"]

_CLASSES: tuple[ObjectClass, ...] = tuple(ObjectClass)

I64 = npt.NDArray[np.int64]


def class_codes(values: Iterable[str | ObjectClass]) -> I64:
    """Codes of ObjectClass members given by member or value (``"vehicle"``)."""
    return np.array([CLASS_CODES[ObjectClass(v)] for v in values], dtype=np.int64)


def boxes_by_frame(
    *,
    frame_index: npt.ArrayLike,
    object_class: npt.ArrayLike | Sequence[ObjectClass],
    center_m: npt.ArrayLike,
    size_m: npt.ArrayLike,
    yaw_rad: npt.ArrayLike,
    velocity_mps: npt.ArrayLike | None = None,
    confidence: npt.ArrayLike | None = None,
    num_lidar_points: npt.ArrayLike | None = None,
) -> ObjectColumns:
    """Columns (``object_class`` as ObjectClass members or :data:`CLASS_CODES` codes,
    ``num_lidar_points`` -1 when unknown) → checked columns sorted by frame (a stable sort)."""
    frames = np.asarray(frame_index, dtype=np.int64).reshape(-1)
    n = frames.shape[0]
    given: list[Any] = list(object_class)  # type: ignore[arg-type]
    classes: list[ObjectClass] = [
        c if isinstance(c, ObjectClass) else _CLASSES[int(c)] for c in given
    ]
    columns = ObjectColumns.of(
        frame_index=frames,
        object_class=classes,
        center_m=np.asarray(center_m, dtype=np.float64).reshape(n, 3),
        size_m=np.asarray(size_m, dtype=np.float64).reshape(n, 3),
        yaw_rad=np.asarray(yaw_rad, dtype=np.float64).reshape(n),
        velocity_mps=None
        if velocity_mps is None
        else np.asarray(velocity_mps, np.float64).reshape(n, 3),
        confidence=None if confidence is None else np.asarray(confidence, np.float64).reshape(n),
        num_lidar_points=None
        if num_lidar_points is None
        else np.asarray(num_lidar_points, np.int64).reshape(n),
    )
    order = np.argsort(frames, kind="stable")
    if n and np.any(order != np.arange(n)):
        columns = columns.take(order)
    return columns


def objects_to_arrays(
    per_frame: Mapping[int, Sequence[DetectedObject]], frames: Iterable[int]
) -> ObjectColumns:
    """The objects of ``frames`` (in increasing frame order; absent frames contribute none)."""
    rows: list[DetectedObject] = []
    frame_of: list[int] = []
    for f in sorted(set(frames)):
        objs = per_frame.get(f, ())
        rows.extend(objs)
        frame_of.extend([f] * len(objs))
    return ObjectColumns.from_objects(rows, frame_index=frame_of)


def class_name(code: int) -> str:
    """The ObjectClass value of a code."""
    return _CLASSES[code].value
