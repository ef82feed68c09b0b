"""The ground truth a synthetic log records: the scene's objects near the ego, in its
``base_link``, with how many LiDAR returns and camera pixels each got."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from redrive.geometry import invert
from redrive.sim.scene import Scene
from redrive.sim.truth_kernels import rows_in_base_packed
from redrive.types import DetectedObject, ObjectClass, ObjectColumns

__all__ = ["GROUND_TRUTH_RANGE_M", "boxes_in_base", "ground_truth_objects", "objects_in_base"]

#: Objects farther than this from the ego are left out of the ground truth, metres.
GROUND_TRUTH_RANGE_M = 120.0
#: ``keep`` for every row (rows_in_base's empty mask)
_EVERY = np.zeros(0, dtype=np.bool_)
_EVERY.flags.writeable = False  # (as a scene's flags are: one compiled signature for both)


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
    return boxes_in_base(
        objs.object_id,
        objs.object_class,
        objs.center_m,
        objs.size_m,
        objs.yaw_rad,
        objs.velocity_mps,
        map_from_base,
        keep=keep,
        lidar_hits=lidar_hits,
        camera_pixels=camera_pixels,
        range_m=range_m,
    )


def boxes_in_base(  # noqa: PLR0917 - the boxes' columns, then the pose
    object_ids: npt.NDArray[np.int64],
    classes: tuple[ObjectClass, ...],
    centers_m: npt.NDArray[np.float64],
    sizes_m: npt.NDArray[np.float64],
    yaws_rad: npt.NDArray[np.float64],
    velocities_mps: npt.NDArray[np.float64],
    map_from_base: npt.NDArray[np.float64],
    *,
    keep: npt.NDArray[np.bool_] | None = None,
    lidar_hits: dict[int, int] | None = None,
    camera_pixels: dict[int, int] | None = None,
    range_m: float = GROUND_TRUTH_RANGE_M,
) -> tuple[DetectedObject, ...]:
    """:func:`objects_in_base` of boxes given as columns (map frame, float64; the centres, sizes
    and velocities (N, 3)), without an :class:`ObjectColumns` of them."""
    base_from_map = invert(map_from_base)
    yaw_ego = math.atan2(float(map_from_base[1, 0]), float(map_from_base[0, 0]))
    # transform_points' and transform_vectors' products (the same numpy calls, unchecked)
    rotation_t = base_from_map[:3, :3].T
    centers = centers_m @ rotation_t + base_from_map[:3, 3]
    velocities = velocities_mps @ rotation_t
    # (the kernel's seven arrays packed in two: unpacked as C-contiguous views)
    m, ints, floats = rows_in_base_packed(
        centers, velocities, object_ids, sizes_m, yaws_rad,
        _EVERY if keep is None else keep, yaw_ego, range_m,
    )  # fmt: skip
    m3 = 3 * m
    idx, ids = ints[:m], ints[m:]
    centers = floats[:m3].reshape(m, 3)
    sizes = floats[m3 : 2 * m3].reshape(m, 3)
    yaws = floats[2 * m3 : 2 * m3 + m]
    velocities = floats[2 * m3 + m : 3 * m3 + m].reshape(m, 3)
    orientations = floats[3 * m3 + m : 13 * m].reshape(m, 3)
    # the rows are the world's (trusted: finite, non-negative sizes) moved into base_link: the
    # columns are built as DetectedObject.many would check and build them, without the checks
    points: npt.NDArray[np.int64] | None = None
    visible: tuple[bool | None, ...] | None = None
    if lidar_hits is not None or camera_pixels is not None:
        rows = ids.tolist()
        # (without LiDAR a row's points are -1: `(-1 or pixels) > 0` is false, as it was)
        hits = [-1 if lidar_hits is None else int(lidar_hits.get(i, 0)) for i in rows]
        pixels = [0 if camera_pixels is None else int(camera_pixels.get(i, 0)) for i in rows]
        visible = tuple((p or q) > 0 for p, q in zip(hits, pixels, strict=True))
        if lidar_hits is not None:
            points = np.array(hits, dtype=np.int64)
    return tuple(
        ObjectColumns.trusted(
            object_id=ids,
            object_class=(
                classes if len(idx) == len(classes) else tuple([classes[i] for i in idx.tolist()])
            ),
            center_m=centers,
            size_m=sizes,
            yaw_rad=yaws,
            velocity_mps=velocities,
            orientation_rad=orientations,
            num_lidar_points=points,
            visible=visible,
        ).objects()
    )
