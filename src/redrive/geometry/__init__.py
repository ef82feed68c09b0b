"""Geometry (layer L1): rotations, rigid transforms, boxes.  numpy + redrive.types/errors only."""

from __future__ import annotations

from redrive.geometry.boxes import (
    box_corners,
    points_in_box,
    transform_box,
    transform_columns,
    transform_object,
)
from redrive.geometry.projection import project_points
from redrive.geometry.se3 import (
    compose,
    invert,
    matrix_from_transform,
    normalize_angle,
    quaternion_from_euler,
    quaternion_from_rotation_matrix,
    quaternion_from_yaw,
    rotation_matrix_from_yaw,
    se3_from_rotation_translation,
    transform_from_matrix,
    transform_points,
    transform_vectors,
    yaw_from_rotation_matrix,
    yaw_pitch_roll_from_rotation_matrices,
)

__all__ = [
    "box_corners",
    "compose",
    "invert",
    "matrix_from_transform",
    "normalize_angle",
    "points_in_box",
    "project_points",
    "quaternion_from_euler",
    "quaternion_from_rotation_matrix",
    "quaternion_from_yaw",
    "rotation_matrix_from_yaw",
    "se3_from_rotation_translation",
    "transform_box",
    "transform_columns",
    "transform_from_matrix",
    "transform_object",
    "transform_points",
    "transform_vectors",
    "yaw_from_rotation_matrix",
    "yaw_pitch_roll_from_rotation_matrices",
]
