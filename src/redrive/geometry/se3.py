"""Rigid transforms in 3D as 4×4 homogeneous float64 matrices.

A matrix named ``dst_from_src`` maps points expressed in ``src`` into ``dst``:
``p_dst = dst_from_src @ p_src``.  Composition reads right to left:
``a_from_c = compose(a_from_b, b_from_c)``.  Quaternions are ROS order ``(x, y, z, w)``
(see :mod:`redrive.geometry.quaternion` for matrix-from-quaternion, Euler angles and slerp).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.geometry.quaternion import rotation_matrix_from_quaternion
from redrive.types import Transform

__all__ = [
    "compose",
    "identity_matrix",
    "invert",
    "matrix_from_transform",
    "normalize_angle",
    "quaternion_from_euler",
    "quaternion_from_rotation_matrix",
    "quaternion_from_yaw",
    "rotation_matrix_from_yaw",
    "se3_from_rotation_translation",
    "transform_from_matrix",
    "transform_points",
    "transform_vectors",
    "yaw_from_rotation_matrix",
    "yaw_pitch_roll_from_rotation_matrices",
]

Matrix = npt.NDArray[np.float64]

_EYE4 = np.eye(4)
_EYE4.flags.writeable = False


def identity_matrix() -> Matrix:
    """A new 4×4 float64 identity, ``np.eye(4)``'s array: a copy of one made once (a fifth of
    ``np.eye``'s cost, for per-frame poses)."""
    return _EYE4.copy()


def normalize_angle(angle_rad: float) -> float:
    """``angle_rad`` wrapped into [-π, π)."""
    wrapped = math.fmod(angle_rad + math.pi, 2.0 * math.pi)
    if wrapped < 0.0:
        wrapped += 2.0 * math.pi
    return wrapped - math.pi


def _check_se3(matrix: npt.ArrayLike, name: str) -> Matrix:
    mat = np.asarray(matrix, dtype=np.float64)
    if mat.shape != (4, 4):
        msg = f"{name}: expected a 4x4 homogeneous matrix, got shape {mat.shape}"
        raise ValueError(msg)
    return mat


def se3_from_rotation_translation(
    rotation: npt.ArrayLike, translation: npt.ArrayLike | None = None
) -> Matrix:
    """A 4×4 matrix from a 3×3 rotation and an optional (3,) translation (metres)."""
    rot = np.asarray(rotation, dtype=np.float64)
    if rot.shape != (3, 3):
        msg = f"rotation: expected shape (3, 3), got {rot.shape}"
        raise ValueError(msg)
    out = identity_matrix()
    out[:3, :3] = rot
    if translation is not None:
        trans = np.asarray(translation, dtype=np.float64).reshape(-1)
        if trans.shape != (3,):
            msg = f"translation: expected shape (3,), got {trans.shape}"
            raise ValueError(msg)
        out[:3, 3] = trans
    return out


def compose(*transforms: npt.ArrayLike) -> Matrix:
    """The product ``t0 @ t1 @ …``: ``compose(a_from_b, b_from_c) == a_from_c``."""
    if not transforms:
        return identity_matrix()
    out = _check_se3(transforms[0], "compose[0]").copy()
    for i, item in enumerate(transforms[1:], start=1):
        out = out @ _check_se3(item, f"compose[{i}]")
    return out


def invert(dst_from_src: npt.ArrayLike) -> Matrix:
    """``src_from_dst`` of a rigid transform (closed form: Rᵀ, −Rᵀt)."""
    mat = _check_se3(dst_from_src, "invert")
    rot_t = mat[:3, :3].T
    out = identity_matrix()
    out[:3, :3] = rot_t
    out[:3, 3] = -rot_t @ mat[:3, 3]
    return out


def transform_points(dst_from_src: npt.ArrayLike, points: npt.NDArray[Any]) -> npt.NDArray[Any]:
    """Points (N, 3) in ``src`` → (N, 3) in ``dst``, in the dtype of ``points``.

    float32 clouds are transformed in float64 and rounded once, so a large translation (map
    coordinates) does not lose precision on the way.
    """
    mat = _check_se3(dst_from_src, "transform_points")
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        msg = f"transform_points: points must have shape (N, 3), got {pts.shape}"
        raise ValueError(msg)
    dtype = pts.dtype if pts.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    out = pts.astype(np.float64, copy=False) @ mat[:3, :3].T + mat[:3, 3]
    return np.ascontiguousarray(out, dtype=dtype)


def transform_vectors(dst_from_src: npt.ArrayLike, vectors: npt.ArrayLike) -> Matrix:
    """Direction vectors (..., 3) (velocities, normals): rotation only, no translation."""
    mat = _check_se3(dst_from_src, "transform_vectors")
    vec = np.asarray(vectors, dtype=np.float64)
    if vec.shape[-1:] != (3,):
        msg = f"transform_vectors: vectors must have shape (..., 3), got {vec.shape}"
        raise ValueError(msg)
    out: Matrix = vec @ mat[:3, :3].T
    return out


def quaternion_from_rotation_matrix(rotation: npt.ArrayLike) -> Matrix:
    """The unit quaternion (x, y, z, w), w ≥ 0, of a 3×3 rotation matrix (Shepperd's method)."""
    rot = np.asarray(rotation, dtype=np.float64)
    if rot.shape == (4, 4):
        rot = rot[:3, :3]
    if rot.shape != (3, 3):
        msg = f"rotation: expected shape (3, 3), got {rot.shape}"
        raise ValueError(msg)
    m00, m11, m22 = rot[0, 0], rot[1, 1], rot[2, 2]
    trace = m00 + m11 + m22
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [
            (rot[2, 1] - rot[1, 2]) / s,
            (rot[0, 2] - rot[2, 0]) / s,
            (rot[1, 0] - rot[0, 1]) / s,
            s / 4,
        ]
    elif m00 >= m11 and m00 >= m22:
        s = 2.0 * math.sqrt(max(1.0 + m00 - m11 - m22, 0.0))
        q = [
            s / 4,
            (rot[0, 1] + rot[1, 0]) / s,
            (rot[0, 2] + rot[2, 0]) / s,
            (rot[2, 1] - rot[1, 2]) / s,
        ]
    elif m11 >= m22:
        s = 2.0 * math.sqrt(max(1.0 + m11 - m00 - m22, 0.0))
        q = [
            (rot[0, 1] + rot[1, 0]) / s,
            s / 4,
            (rot[1, 2] + rot[2, 1]) / s,
            (rot[0, 2] - rot[2, 0]) / s,
        ]
    else:
        s = 2.0 * math.sqrt(max(1.0 + m22 - m00 - m11, 0.0))
        q = [
            (rot[0, 2] + rot[2, 0]) / s,
            (rot[1, 2] + rot[2, 1]) / s,
            s / 4,
            (rot[1, 0] - rot[0, 1]) / s,
        ]
    out = np.array(q, dtype=np.float64)
    out /= np.linalg.norm(out)
    if out[3] < 0.0:
        out = -out
    return out


def quaternion_from_yaw(yaw_rad: float) -> Matrix:
    """The quaternion (x, y, z, w) of a rotation by ``yaw_rad`` about +z."""
    half = 0.5 * yaw_rad
    return np.array([0.0, 0.0, math.sin(half), math.cos(half)])


def quaternion_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Matrix:
    """The quaternion (x, y, z, w) of intrinsic z-y'-x'' (yaw, then pitch, then roll) angles.

    The inverse of :func:`redrive.geometry.quaternion.euler_from_quaternion`.
    """
    cr, sr = math.cos(0.5 * roll_rad), math.sin(0.5 * roll_rad)
    cp, sp = math.cos(0.5 * pitch_rad), math.sin(0.5 * pitch_rad)
    cy, sy = math.cos(0.5 * yaw_rad), math.sin(0.5 * yaw_rad)
    return np.array(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ]
    )


def rotation_matrix_from_yaw(yaw_rad: float) -> Matrix:
    """The 3×3 rotation by ``yaw_rad`` about +z."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def yaw_from_rotation_matrix(rotation: npt.ArrayLike) -> float:
    """Heading of the rotated +x axis projected on the xy plane, radians in (-π, π]."""
    rot = np.asarray(rotation, dtype=np.float64)
    return math.atan2(float(rot[1, 0]), float(rot[0, 0]))


def yaw_pitch_roll_from_rotation_matrices(rotations: npt.ArrayLike) -> Matrix:
    """(N, 3) yaw, pitch, roll (radians) of rotations (N, 3, 3) as ``R = Rz(yaw) Ry(pitch)
    Rx(roll)`` (intrinsic z-y'-x''; pitch in [-π/2, π/2]); yaw is :func:`yaw_from_rotation_matrix`'s,
    the nuScenes devkit evaluation's ``quaternion_yaw``."""
    rot = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    yaw = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
    pitch = np.arcsin(np.clip(-rot[:, 2, 0], -1.0, 1.0))
    roll = np.arctan2(rot[:, 2, 1], rot[:, 2, 2])
    return np.stack([yaw, pitch, roll], axis=1)


def matrix_from_transform(transform: Transform) -> Matrix:
    """The 4×4 ``parent_from_child`` matrix of a :class:`~redrive.types.Transform`."""
    return se3_from_rotation_translation(
        rotation_matrix_from_quaternion(transform.rotation), transform.translation
    )


def transform_from_matrix(
    parent_from_child: npt.ArrayLike,
    *,
    parent_frame: str,
    child_frame: str,
    stamp_ns: int = 0,
) -> Transform:
    """A :class:`~redrive.types.Transform` from a 4×4 matrix (the rotation part must be proper).

    A rotation block that is only nearly orthonormal (calibration files with 6 decimals) is
    projected onto the closest rotation through the quaternion.
    """
    mat = _check_se3(parent_from_child, "transform_from_matrix")
    return Transform(
        parent_frame=parent_frame,
        child_frame=child_frame,
        translation=mat[:3, 3].copy(),
        rotation=quaternion_from_rotation_matrix(mat[:3, :3]),
        stamp_ns=stamp_ns,
    )
