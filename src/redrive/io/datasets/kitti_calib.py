"""KITTI calibration files (``calib/NNNNNN.txt``) and label lines (``label_2/NNNNNN.txt``).

Frames of the KITTI coordinate chain (names used on ``/tf_static``):

``imu`` → ``velodyne`` → ``cam0`` (unrectified reference camera) → ``cam0_rect`` (rectified)
→ ``cam1`` … ``cam3`` (the rectified cameras behind ``image_0`` … ``image_3``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from redrive.errors import LogError
from redrive.geometry.se3 import invert, normalize_angle, transform_from_matrix
from redrive.types import Box3D, DetectedObject, ObjectClass, Transform

__all__ = [
    "KITTI_CLASSES",
    "KittiCalibration",
    "camera_box_object",
    "parse_calibration",
    "parse_labels",
]

Matrix = npt.NDArray[np.float64]

#: KITTI object type → redrive class; ``DontCare`` rows are skipped.
KITTI_CLASSES: dict[str, ObjectClass] = {
    "Car": ObjectClass.VEHICLE,
    "Van": ObjectClass.VEHICLE,
    "Truck": ObjectClass.TRUCK,
    "Pedestrian": ObjectClass.PEDESTRIAN,
    "Person_sitting": ObjectClass.PEDESTRIAN,
    "Cyclist": ObjectClass.BICYCLE,
    "Tram": ObjectClass.OTHER,
    "Misc": ObjectClass.OTHER,
}

# key → accepted spellings (object benchmark, then raw/tracking devkit names)
_KEYS: dict[str, tuple[str, ...]] = {
    "P0": ("P0",),
    "P1": ("P1",),
    "P2": ("P2",),
    "P3": ("P3",),
    "R0_rect": ("R0_rect", "R_rect"),
    "Tr_velo_to_cam": ("Tr_velo_to_cam", "Tr_velo_cam"),
    "Tr_imu_to_velo": ("Tr_imu_to_velo", "Tr_imu_velo"),
}
_SHAPES = {"R0_rect": (3, 3)}
# camera axes (x right, y down, z forward) → REP-103 axes (x forward, y left, z up)
_FLU_FROM_RDF = np.array(
    [[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


def _pad4(matrix: Matrix) -> Matrix:
    out = np.eye(4)
    out[: matrix.shape[0], : matrix.shape[1]] = matrix
    return out


@dataclass(frozen=True, slots=True, kw_only=True)
class KittiCalibration:
    """The calibration of one KITTI frame.

    Attributes:
        projections: P0 … P3, (3, 4) float64: rectified cam0 coordinates (m) → pixels of
            ``image_0`` … ``image_3``.
        r0_rect: (3, 3) rectifying rotation, cam0 → cam0_rect.
        cam0_from_velodyne: (4, 4) ``Tr_velo_to_cam``.
        velodyne_from_imu: (4, 4) ``Tr_imu_to_velo``; None when the file has none.
    """

    projections: tuple[Matrix, Matrix, Matrix, Matrix]
    r0_rect: Matrix
    cam0_from_velodyne: Matrix
    velodyne_from_imu: Matrix | None = None

    @property
    def rect_from_velodyne(self) -> Matrix:
        """(4, 4) ``R0_rect @ Tr_velo_to_cam``: velodyne → rectified cam0 (exact, not re-orthonormalised)."""
        out: Matrix = _pad4(self.r0_rect) @ self.cam0_from_velodyne
        return out

    @property
    def rect_flu_from_velodyne(self) -> Matrix:
        """(4, 4) velodyne → ``cam0_rect`` with REP-103 axes (x forward, y left, z up).

        KITTI label boxes are exactly upright in this frame; in the velodyne frame (tilted by
        about half a degree) they are upright only to that accuracy.  Transform boxes and points
        here (:func:`redrive.geometry.boxes.transform_box`) to count points as the devkit does.
        """
        out: Matrix = _FLU_FROM_RDF @ self.rect_from_velodyne
        return out

    @property
    def velodyne_from_rect(self) -> Matrix:
        """(4, 4) the inverse of :attr:`rect_from_velodyne` (a general inverse, as the devkit does)."""
        out: Matrix = np.linalg.inv(self.rect_from_velodyne).astype(np.float64)
        return out

    def image_from_velodyne(self, camera: int = 2) -> Matrix:
        """(3, 4) ``P_camera @ R0_rect @ Tr_velo_to_cam``: velodyne points (m) → pixels."""
        out: Matrix = self.projections[camera] @ self.rect_from_velodyne
        return out

    def camera_offset_m(self, camera: int) -> Matrix:
        """(3,) the origin of rectified camera ``camera`` in cam0_rect, metres."""
        proj = self.projections[camera]
        # P = K [I | t]; the camera centre in cam0_rect is -t.
        centre: Matrix = -np.linalg.solve(proj[:, :3], proj[:, 3]).astype(np.float64)
        return centre

    def transforms(self, *, stamp_ns: int = 0) -> tuple[Transform, ...]:
        """The chain as ``parent_from_child`` transforms (rotations re-orthonormalised).

        ``stamp_ns`` 0 (the default) marks them static, as the tf_static decoder does.
        """
        out: list[Transform] = []
        if self.velodyne_from_imu is not None:
            out.append(
                transform_from_matrix(
                    self.velodyne_from_imu,
                    parent_frame="velodyne",
                    child_frame="imu",
                    stamp_ns=stamp_ns,
                )
            )
        velodyne_from_cam0 = np.linalg.inv(self.cam0_from_velodyne)
        out.append(
            transform_from_matrix(
                velodyne_from_cam0, parent_frame="velodyne", child_frame="cam0", stamp_ns=stamp_ns
            )
        )
        cam0_from_rect = invert(_pad4(self.r0_rect))
        out.append(
            transform_from_matrix(
                cam0_from_rect, parent_frame="cam0", child_frame="cam0_rect", stamp_ns=stamp_ns
            )
        )
        for cam in (1, 2, 3):
            out.append(
                Transform(
                    parent_frame="cam0_rect",
                    child_frame=f"cam{cam}",
                    translation=self.camera_offset_m(cam),
                    stamp_ns=stamp_ns,
                )
            )
        return tuple(out)


def parse_calibration(path: Path) -> KittiCalibration:
    """Read one ``calib/NNNNNN.txt``.

    Raises:
        LogError: the file cannot be read, or a matrix is missing or malformed.
    """
    try:
        text = path.read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as err:
        msg = f"{path}: cannot read the KITTI calibration ({err})"
        raise LogError(msg) from err
    raw: dict[str, list[float]] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        key, sep, values = line.partition(":")
        try:
            raw[key.strip()] = [float(v) for v in values.split()] if sep else []
        except ValueError as err:
            msg = f"{path}:{lineno}: {key.strip()!r} holds a non-number ({err}); restore the original calib file"
            raise LogError(msg) from err
    found: dict[str, Matrix] = {}
    for key, spellings in _KEYS.items():
        spelled = next((raw[s] for s in spellings if s in raw), None)
        if spelled is None:
            continue
        shape = _SHAPES.get(key, (3, 4))
        if len(spelled) != shape[0] * shape[1]:
            msg = (
                f"{path}: {key} has {len(spelled)} numbers, expected {shape[0] * shape[1]}; "
                "restore the original calib file"
            )
            raise LogError(msg)
        found[key] = np.array(spelled, dtype=np.float64).reshape(shape)
    missing = [k for k in _KEYS if k not in found and k != "Tr_imu_to_velo"]
    if missing:
        msg = f"{path}: the KITTI calibration lacks {', '.join(missing)}; restore the original calib file"
        raise LogError(msg)
    imu = found.get("Tr_imu_to_velo")
    return KittiCalibration(
        projections=(found["P0"], found["P1"], found["P2"], found["P3"]),
        r0_rect=found["R0_rect"],
        cam0_from_velodyne=_pad4(found["Tr_velo_to_cam"]),
        velodyne_from_imu=None if imu is None else _pad4(imu),
    )


def parse_labels(path: Path, calibration: KittiCalibration) -> tuple[DetectedObject, ...]:
    """Read one ``label_2/NNNNNN.txt`` into objects in the **velodyne** frame.

    A label row is ``type truncated occluded alpha left top right bottom h w l x y z rotation_y
    [score]`` with (x, y, z) the bottom centre of the box in rectified cam0 coordinates.  The box
    centre is moved to mid-height and into the velodyne frame; size becomes (l, w, h); the yaw is
    ``-rotation_y - π/2`` (the convention of the KITTI devkit and mmdetection3d), wrapped into
    [-π, π).  ``object_id`` is the 0-based row; ``DontCare`` rows are skipped; ``confidence`` is
    1, or the score column clipped to [0, 1].

    Raises:
        LogError: the file cannot be read or a row is malformed (file and line are named).
    """
    try:
        text = path.read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as err:
        msg = f"{path}: cannot read the KITTI label file ({err})"
        raise LogError(msg) from err
    velodyne_from_rect = calibration.velodyne_from_rect
    objects: list[DetectedObject] = []
    for row, line in enumerate(text.splitlines()):
        fields = line.split()
        if not fields or fields[0] == "DontCare":
            continue
        where = f"{path}:{row + 1}"
        if len(fields) not in (15, 16):
            msg = (
                f"{where}: a KITTI label row has 15 fields (16 with a score), this one has "
                f"{len(fields)}: {line.strip()!r}; fix or remove the row"
            )
            raise LogError(msg)
        try:
            nums = [float(v) for v in fields[1:]]
        except ValueError as err:
            msg = f"{where}: a KITTI label row holds a non-number ({err}); fix or remove the row"
            raise LogError(msg) from err
        left, top, right, bottom = nums[3:7]
        height_m, width_m, length_m = nums[7:10]
        if not all(math.isfinite(v) for v in nums) or min(height_m, width_m, length_m) < 0:
            msg = f"{where}: non-finite value or negative box size in {line.strip()!r}; fix or remove the row"
            raise LogError(msg)
        objects.append(
            camera_box_object(
                object_id=row,
                object_class=KITTI_CLASSES.get(fields[0], ObjectClass.UNKNOWN),
                bottom_center_rect=(nums[10], nums[11], nums[12]),
                size_lhw=(length_m, height_m, width_m),
                rotation_y_rad=nums[13],
                velodyne_from_rect=velodyne_from_rect,
                confidence=1.0 if len(nums) == 14 else min(1.0, max(0.0, nums[14])),
                bbox_2d=(left, top, right - left, bottom - top),
            )
        )
    return tuple(objects)


def camera_box_object(
    *,
    object_id: int,
    object_class: ObjectClass,
    bottom_center_rect: tuple[float, float, float],
    size_lhw: tuple[float, float, float],
    rotation_y_rad: float,
    velodyne_from_rect: Matrix,
    confidence: float = 1.0,
    bbox_2d: tuple[float, float, float, float] | None = None,
) -> DetectedObject:
    """A KITTI box given in rectified cam0 coordinates (bottom centre, length/height/width,
    ``rotation_y``) as an object in the velodyne frame: the centre moved to mid-height, size
    (l, w, h), yaw ``-rotation_y - π/2`` wrapped into [-π, π) (the KITTI devkit's and
    mmdetection3d's convention)."""
    x_m, y_m, z_m = bottom_center_rect
    length_m, height_m, width_m = size_lhw
    center_rect = np.array([x_m, y_m - 0.5 * height_m, z_m, 1.0])
    center_velo = (velodyne_from_rect @ center_rect)[:3]
    yaw_rad = normalize_angle(-rotation_y_rad - math.pi / 2)
    return DetectedObject(
        object_id=object_id,
        object_class=object_class,
        confidence=confidence,
        box=Box3D(
            center=center_velo, size=np.array([length_m, width_m, height_m]), yaw_rad=yaw_rad
        ),
        orientation=np.array([yaw_rad, 0.0, 0.0]),
        bbox_2d=bbox_2d,
    )
