"""Oriented 3D boxes: change of frame, corners, which points lie inside.

A :class:`~redrive.types.Box3D` is upright in its frame: it turns by ``yaw_rad`` about +z only.
Moving it into a frame whose z axis is tilted keeps it upright in the new frame (the heading is
the rotated box +x axis projected on the new xy plane); that is what every driving dataset does.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.geometry.se3 import (
    normalize_angle,
    rotation_matrix_from_yaw,
    transform_points,
    transform_vectors,
)
from redrive.types import Box3D, DetectedObject, ObjectColumns

__all__ = [
    "BOX_CORNER_SIGNS",
    "box_corners",
    "points_in_box",
    "transform_box",
    "transform_columns",
    "transform_object",
]


def transform_box(dst_from_src: npt.ArrayLike, box: Box3D) -> Box3D:
    """``box`` (in ``src``) expressed in ``dst``: centre moved, heading turned, size kept."""
    mat = np.asarray(dst_from_src, dtype=np.float64)
    center = transform_points(mat, box.center.reshape(1, 3))[0]
    heading = transform_vectors(mat, [math.cos(box.yaw_rad), math.sin(box.yaw_rad), 0.0])
    yaw_rad = normalize_angle(math.atan2(float(heading[1]), float(heading[0])))
    return Box3D(center=center, size=box.size.copy(), yaw_rad=yaw_rad)


def transform_object(dst_from_src: npt.ArrayLike, obj: DetectedObject) -> DetectedObject:
    """``obj`` expressed in ``dst``: box, velocity, acceleration and yaw of ``orientation``."""
    mat = np.asarray(dst_from_src, dtype=np.float64)
    box = transform_box(mat, obj.box)
    orientation = obj.orientation.copy()
    orientation[0] = normalize_angle(orientation[0] + box.yaw_rad - obj.box.yaw_rad)
    return dataclasses.replace(
        obj,
        box=box,
        velocity=transform_vectors(mat, obj.velocity),
        acceleration=transform_vectors(mat, obj.acceleration),
        orientation=orientation,
    )


def transform_columns(dst_from_src: npt.ArrayLike, columns: ObjectColumns) -> ObjectColumns:
    """:func:`transform_object` of every row of ``columns`` at once: the same transform, one
    matrix product for all rows (equal to the object-by-object one to rounding)."""
    mat = np.asarray(dst_from_src, dtype=np.float64)
    if len(columns) == 0:
        return columns
    rot = mat[:3, :3]
    yaws = columns.yaw_rad.tolist()
    unit = np.zeros((len(yaws), 3))
    unit[:, 0] = [math.cos(y) for y in yaws]
    unit[:, 1] = [math.sin(y) for y in yaws]
    heading = (unit @ rot.T).tolist()
    new_yaw = _normalized(np.array([math.atan2(h[1], h[0]) for h in heading]))
    orientation = columns.orientation_rad.copy()
    orientation[:, 0] = _normalized(orientation[:, 0] + new_yaw - columns.yaw_rad)
    # fresh C-contiguous float64 arrays of the columns' shapes, finite as the rows were: the
    # columns' second check (dataclasses.replace's) would find nothing
    return columns.with_trusted(
        center_m=transform_points(mat, columns.center_m),
        yaw_rad=new_yaw,
        velocity_mps=transform_vectors(mat, columns.velocity_mps),
        acceleration_mps2=transform_vectors(mat, columns.acceleration_mps2),
        orientation_rad=orientation,
    )


def _normalized(angles_rad: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """:func:`~redrive.geometry.se3.normalize_angle` of each angle: the same operations
    elementwise (``fmod`` is exact), so the same doubles."""
    wrapped = np.fmod(angles_rad + math.pi, 2.0 * math.pi)
    wrapped = np.where(wrapped < 0.0, wrapped + 2.0 * math.pi, wrapped)
    return np.asarray(wrapped - math.pi, dtype=np.float64)


#: Corner signs (length, width, height) in :func:`box_corners` order: the bottom face
#: front-left, rear-left, rear-right, front-right, then the top face in the same order.
BOX_CORNER_SIGNS: npt.NDArray[np.float64] = np.array(
    [
        [1, 1, -1],
        [-1, 1, -1],
        [-1, -1, -1],
        [1, -1, -1],
        [1, 1, 1],
        [-1, 1, 1],
        [-1, -1, 1],
        [1, -1, 1],
    ],
    dtype=np.float64,
)


def box_corners(box: Box3D) -> npt.NDArray[np.float64]:
    """(8, 3) float64 corners in the box's frame, metres.

    Order: bottom face (z − h/2) front-left, rear-left, rear-right, front-right, then the top
    face (z + h/2) in the same order; "front" is +x of the box (its heading).
    """
    local = BOX_CORNER_SIGNS * (0.5 * box.size)
    out: npt.NDArray[np.float64] = local @ rotation_matrix_from_yaw(box.yaw_rad).T + box.center
    return out


def points_in_box(
    points: npt.NDArray[Any],
    box: Box3D,
    *,
    margin_m: float = 0.0,
    pitch_rad: float = 0.0,
    roll_rad: float = 0.0,
) -> npt.NDArray[np.bool_]:
    """(N,) bool: which of ``points`` (N, 3), in the box's frame, lie inside ``box``.

    The boundary counts as inside; ``margin_m`` grows (or, negative, shrinks) every half-size.
    ``pitch_rad`` / ``roll_rad`` tilt the box as ``Rz(yaw) Ry(pitch) Rx(roll)`` (a
    :class:`~redrive.types.DetectedObject`'s ``orientation``: a box upright in another frame,
    such as a nuScenes box in the global frame seen from a tilted ego) — the nuScenes devkit's
    ``points_in_box`` on the box's full rotation.
    """
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        msg = f"points_in_box: points must have shape (N, 3), got {pts.shape}"
        raise ValueError(msg)
    d = pts.astype(np.float64, copy=False) - box.center
    half = 0.5 * box.size + margin_m
    if pitch_rad or roll_rad:
        cy, sy = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
        cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
        cr, sr = math.cos(roll_rad), math.sin(roll_rad)
        rotation = np.array(
            [
                [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                [-sp, cp * sr, cp * cr],
            ]
        )
        local = d @ rotation  # box coordinates: rotation.T @ d for every point
        inside: npt.NDArray[np.bool_] = np.all(np.abs(local) <= half, axis=1)
        return inside
    c, s = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
    local_x = d[:, 0] * c + d[:, 1] * s
    local_y = -d[:, 0] * s + d[:, 1] * c
    mask: npt.NDArray[np.bool_] = (
        (np.abs(local_x) <= half[0]) & (np.abs(local_y) <= half[1]) & (np.abs(d[:, 2]) <= half[2])
    )
    return mask
