"""The checks of :class:`~redrive.types.objects.ObjectColumns`' public constructors (moved out
of objects.py to keep it under the project's 600-line limit): columns checked as
``DetectedObject(...)`` checks one object, copied and frozen."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.types._arrays import (
    column1,
    column3,
    finite,
    finite_nonnegative,
    in_unit,
    int_column,
    length_msg,
    minus_ones,
    ones,
    zeros,
)
from redrive.types.enums import ObjectClass

__all__ = ["checked_column_values"]


def checked_column_values(
    where: str,
    *,
    object_class: Sequence[ObjectClass],
    center_m: npt.ArrayLike,
    size_m: npt.ArrayLike,
    yaw_rad: npt.ArrayLike,
    object_id: npt.ArrayLike | None = None,
    confidence: npt.ArrayLike | None = None,
    velocity_mps: npt.ArrayLike | None = None,
    acceleration_mps2: npt.ArrayLike | None = None,
    orientation_rad: npt.ArrayLike | None = None,
    num_lidar_points: Sequence[int | None] | npt.NDArray[np.int64] | None = None,
    visible: Sequence[bool | None] | None = None,
    frame_index: npt.ArrayLike | None = None,
) -> tuple[Any, ...]:
    """The columns checked as ``DetectedObject(...)`` checks one object (ValueError naming
    ``where``, the column and the first bad row), copied and frozen: the values of
    :class:`~redrive.types.objects.ObjectColumns`' fields in their order."""
    n = len(object_class)
    centers = column3(center_m, "center_m", n, where)
    sizes = column3(size_m, "size_m", n, where)
    # The common case in C-level reductions (no numpy Python wrappers; a few objects' values
    # as Python floats, cheaper than numpy's reductions on tiny arrays); the rows are looked
    # at only when there is a bad value, to name the first.
    if n and not finite_nonnegative(sizes):
        bad = ~np.isfinite(sizes).all(axis=1) | (sizes < 0).any(axis=1)
        i = int(np.flatnonzero(bad)[0])
        msg = f"{where}: size_m[{i}] must be finite and non-negative, got {sizes[i].tolist()}"
        raise ValueError(msg)
    yaws = column1(yaw_rad, "yaw_rad", n, where)
    if n and not finite(yaws):
        i = int(np.flatnonzero(~np.isfinite(yaws))[0])
        msg = f"{where}: yaw_rad[{i}] must be finite, got {yaws[i]}"
        raise ValueError(msg)
    ids = minus_ones(n) if object_id is None else int_column(object_id, "object_id", n, where)
    conf = ones(n)
    if confidence is not None:
        conf = column1(confidence, "confidence", n, where)
        if n and not in_unit(conf):
            bad = ~((conf >= 0.0) & (conf <= 1.0))
            i = int(np.flatnonzero(bad)[0])
            msg = f"{where}: confidence[{i}] must lie in [0, 1], got {conf[i]}"
            raise ValueError(msg)
    points = minus_ones(n)
    if isinstance(num_lidar_points, np.ndarray):  # -1: unknown, the column's own convention
        points = int_column(num_lidar_points, "num_lidar_points", n, where)
        if n and int(points.min()) < -1:
            i = int(np.flatnonzero(points < -1)[0])
            msg = f"{where}: num_lidar_points[{i}] must be ≥ 0, got {points[i]}"
            raise ValueError(msg)
    elif num_lidar_points is not None:  # None: unknown
        raw = list(num_lidar_points)
        if len(raw) != n:
            raise ValueError(length_msg("num_lidar_points", len(raw), n, where))
        for i, p in enumerate(raw):
            if p is not None and p < 0:
                msg = f"{where}: num_lidar_points[{i}] must be ≥ 0, got {p}"
                raise ValueError(msg)
        points = int_column([-1 if p is None else p for p in raw], "num_lidar_points", n, where)
    seen: tuple[bool | None, ...] = (None,) * n
    if visible is not None:
        if len(visible) != n:
            raise ValueError(length_msg("visible", len(visible), n, where))
        seen = tuple(visible)
    frames = (
        minus_ones(n) if frame_index is None else int_column(frame_index, "frame_index", n, where)
    )
    vectors = [
        zeros(n) if column is None else column3(column, column_name, n, where)
        for column_name, column in (
            ("velocity_mps", velocity_mps),
            ("acceleration_mps2", acceleration_mps2),
            ("orientation_rad", orientation_rad),
        )
    ]
    return (
        ids,
        tuple(object_class),
        conf,
        centers,
        sizes,
        yaws,
        *vectors,
        (None,) * n,
        points,
        seen,
        frames,
    )
