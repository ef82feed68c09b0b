"""The ground truth a synthetic log records: the scene's objects near the ego, in its
``base_link``, with how many LiDAR returns and camera pixels each got."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from redrive.geometry import invert, transform_points
from redrive.geometry.se3 import transform_vectors, yaw_from_rotation_matrix
from redrive.sim.scene import Scene
from redrive.types import DetectedObject, ObjectColumns

__all__ = ["GROUND_TRUTH_RANGE_M", "ground_truth_objects", "objects_in_base"]

#: Objects farther than this from the ego are left out of the ground truth, metres.
GROUND_TRUTH_RANGE_M = 120.0


def ground_truth_objects(
    scene: Scene,
    *,
    lidar_hits: dict[int, int] | None,
    camera_pixels: dict[int, int] | None,
    range_m: float = GROUND_TRUTH_RANGE_M,
) -> tuple[DetectedObject, ...]:
    """The scene's ground-truth objects within ``range_m`` of the ego, in base_link.

    ``num_lidar_points`` comes from ``lidar_hits`` (object id → returns in the sweep);
    ``visible`` is true when the LiDAR or the camera saw any part of the object.
    """
    return objects_in_base(
        scene.objects,
        scene.map_from_base,
        keep=scene.looks.is_ground_truth,
        lidar_hits=lidar_hits,
        camera_pixels=camera_pixels,
        range_m=range_m,
    )


def objects_in_base(
    objs: ObjectColumns,
    map_from_base: npt.NDArray[np.float64],
    *,
    keep: npt.NDArray[np.bool_] | None = None,
    lidar_hits: dict[int, int] | None = None,
    camera_pixels: dict[int, int] | None = None,
    range_m: float = GROUND_TRUTH_RANGE_M,
) -> tuple[DetectedObject, ...]:
    """The rows of ``objs`` (map frame: a world's :meth:`~redrive.sim.world.World.ground_truth_columns`,
    or its scene's objects with ``keep``, their ground-truth flags) within ``range_m`` of an ego
    at ``map_from_base``, in its base_link (see :func:`ground_truth_objects`)."""
    base_from_map = invert(map_from_base)
    yaw_ego = yaw_from_rotation_matrix(map_from_base[:3, :3])
    centers = transform_points(base_from_map, objs.center_m)
    velocities = transform_vectors(base_from_map, objs.velocity_mps)
    idx = np.arange(len(objs)) if keep is None else np.flatnonzero(keep)
    idx = idx[~(np.hypot(centers[idx, 0], centers[idx, 1]) > range_m)]
    # the rows are the world's (trusted: finite, non-negative sizes) moved into base_link: the
    # columns are built as DetectedObject.many would check and build them, without the checks
    object_ids = objs.object_id[idx]
    n = len(idx)
    if lidar_hits is None:
        points = np.full(n, -1, dtype=np.int64)
    else:
        points = np.array(
            [int(lidar_hits.get(object_id, 0)) for object_id in object_ids.tolist()],
            dtype=np.int64,
        )
    if lidar_hits is None and camera_pixels is None:
        visible: tuple[bool | None, ...] = (None,) * n
    else:
        pixels = [
            0 if camera_pixels is None else int(camera_pixels.get(object_id, 0))
            for object_id in object_ids.tolist()
        ]
        visible = tuple((p or q) > 0 for p, q in zip(points.tolist(), pixels, strict=True))
    yaws = np.array(
        [math.remainder(yaw - yaw_ego, math.tau) for yaw in objs.yaw_rad[idx].tolist()],
        dtype=np.float64,
    )
    orientations = np.zeros((n, 3))
    orientations[:, 0] = yaws
    classes = objs.object_class
    return tuple(
        ObjectColumns.trusted(
            object_id=object_ids,
            object_class=tuple([classes[i] for i in idx.tolist()]),
            center_m=centers[idx],
            size_m=objs.size_m[idx],
            yaw_rad=yaws,
            velocity_mps=velocities[idx],
            orientation_rad=orientations,
            num_lidar_points=points,
            visible=visible,
        ).objects()
    )
