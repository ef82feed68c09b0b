"""Unit quaternions in ROS order ``(x, y, z, w)``: rotation matrices, Euler angles, slerp.

All functions take array-likes of shape (4,) and return float64 values; quaternions need not be
normalised on input (they are normalised first).  Angles are radians, REP-103 axes.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = [
    "euler_from_quaternion",
    "quaternion_normalized",
    "quaternion_slerp",
    "rotation_matrix_from_quaternion",
    "yaw_from_quaternion",
]

_EPS = 1e-12


def quaternion_normalized(q_xyzw: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """``q`` scaled to unit norm.

    Raises:
        ValueError: ``q`` is not 4 finite numbers with a non-zero norm.
    """
    q = np.asarray(q_xyzw, dtype=np.float64).reshape(-1)
    norm = float(np.linalg.norm(q)) if q.shape == (4,) else 0.0
    if not math.isfinite(norm) or norm < _EPS:
        msg = f"not a usable quaternion (x, y, z, w): {q.tolist()}"
        raise ValueError(msg)
    return q / norm


def rotation_matrix_from_quaternion(q_xyzw: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The 3×3 rotation matrix of a quaternion (``parent_from_child`` when ``q`` is)."""
    x, y, z, w = quaternion_normalized(q_xyzw)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def euler_from_quaternion(q_xyzw: npt.ArrayLike) -> tuple[float, float, float]:
    """``(roll_rad, pitch_rad, yaw_rad)`` of the intrinsic z-y'-x'' (yaw, pitch, roll) sequence."""
    x, y, z, w = quaternion_normalized(q_xyzw)
    sin_pitch = max(-1.0, min(1.0, 2 * (w * y - z * x)))
    pitch_rad = math.asin(sin_pitch)
    if abs(sin_pitch) > 1.0 - 1e-14:  # gimbal lock: only yaw - roll is defined; roll := 0
        return 0.0, pitch_rad, math.atan2(2 * (w * z - x * y), 1 - 2 * (x * x + z * z))
    roll_rad = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    yaw_rad = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll_rad, pitch_rad, yaw_rad


def yaw_from_quaternion(q_xyzw: npt.ArrayLike) -> float:
    """Heading about +z in radians, in (-π, π]."""
    return euler_from_quaternion(q_xyzw)[2]


def quaternion_slerp(
    q0_xyzw: npt.ArrayLike, q1_xyzw: npt.ArrayLike, fraction: float
) -> npt.NDArray[np.float64]:
    """Spherical linear interpolation: ``q0`` at ``fraction`` 0, ``q1`` at 1 (shortest arc)."""
    q0 = quaternion_normalized(q0_xyzw)
    q1 = quaternion_normalized(q1_xyzw)
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1 = -q1
        dot = -dot
    if dot > 1.0 - 1e-9:
        out = q0 + fraction * (q1 - q0)
        return out / np.linalg.norm(out)
    theta = math.acos(min(1.0, dot))
    sin_theta = math.sin(theta)
    w0 = math.sin((1.0 - fraction) * theta) / sin_theta
    w1 = math.sin(fraction * theta) / sin_theta
    out = w0 * q0 + w1 * q1
    return out / np.linalg.norm(out)
