"""The compiled ground truth in base_link (sim.truth_kernels): CPython's ``math.remainder``
operation for operation, and :func:`boxes_in_base` / :meth:`World.ground_truth_in_base` the
rows and values of the numpy code they replaced, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from redrive.geometry import invert, transform_points
from redrive.geometry.se3 import transform_vectors, yaw_from_rotation_matrix
from redrive.sim.ego import pose_matrix
from redrive.sim.ground_truth import objects_in_base
from redrive.sim.scenario import load_scenario
from redrive.sim.truth_kernels import remainder
from redrive.sim.world import World
from redrive.types import DetectedObject, ObjectClass, ObjectColumns

_NAMES = (
    "object_id", "confidence", "center_m", "size_m", "yaw_rad", "velocity_mps",
    "acceleration_mps2", "orientation_rad", "num_lidar_points", "frame_index",
)  # fmt: skip


def _bits(a: npt.ArrayLike) -> bytes:
    arr = np.asarray(a)
    return arr.dtype.str.encode() + str(arr.shape).encode() + arr.tobytes()


def _numpy_in_base(  # noqa: PLR0917 - the code boxes_in_base replaced
    objs: ObjectColumns,
    map_from_base: npt.NDArray[np.float64],
    keep: npt.NDArray[np.bool_] | None,
    lidar_hits: dict[int, int] | None,
    camera_pixels: dict[int, int] | None,
    range_m: float = 120.0,
) -> ObjectColumns:
    base_from_map = invert(map_from_base)
    yaw_ego = yaw_from_rotation_matrix(map_from_base[:3, :3])
    centers = transform_points(base_from_map, objs.center_m)
    velocities = transform_vectors(base_from_map, objs.velocity_mps)
    idx = np.arange(len(objs)) if keep is None else np.flatnonzero(keep)
    idx = idx[~(np.hypot(centers[idx, 0], centers[idx, 1]) > range_m)]
    object_ids = objs.object_id[idx]
    n = len(idx)
    if lidar_hits is None:
        points = np.full(n, -1, dtype=np.int64)
    else:
        points = np.array([int(lidar_hits.get(i, 0)) for i in object_ids.tolist()], np.int64)
    visible: tuple[bool | None, ...] = (None,) * n
    if lidar_hits is not None or camera_pixels is not None:
        pixels = [
            0 if camera_pixels is None else int(camera_pixels.get(i, 0))
            for i in object_ids.tolist()
        ]
        visible = tuple((p or q) > 0 for p, q in zip(points.tolist(), pixels, strict=True))
    yaws = np.array(
        [math.remainder(y - yaw_ego, math.tau) for y in objs.yaw_rad[idx].tolist()], np.float64
    )
    orientations = np.zeros((n, 3))
    orientations[:, 0] = yaws
    return ObjectColumns.trusted(
        object_id=object_ids,
        object_class=tuple([objs.object_class[i] for i in idx.tolist()]),
        center_m=centers[idx],
        size_m=objs.size_m[idx],
        yaw_rad=yaws,
        velocity_mps=velocities[idx],
        orientation_rad=orientations,
        num_lidar_points=points,
        visible=visible,
    )


def _assert_same(got: tuple[DetectedObject, ...], want: ObjectColumns) -> None:
    columns = ObjectColumns.shared_by(got)
    assert columns is not None
    assert columns.object_class == want.object_class
    assert columns.visible == want.visible
    for name in _NAMES:
        assert _bits(getattr(columns, name)) == _bits(getattr(want, name)), name
    assert [repr(o) for o in got] == [repr(o) for o in want.objects()]


def test_remainder_is_cpythons_bit_for_bit() -> None:
    rng = np.random.default_rng(3)
    edges = [0.0, -0.0, math.pi, -math.pi, 3 * math.pi, -3 * math.pi, math.tau, 5e-324, 1e300]
    values = [*rng.uniform(-8.0, 8.0, 20000).tolist(), *rng.normal(0, 1e4, 2000).tolist(), *edges]
    for x in values:
        got, want = remainder(x, math.tau), math.remainder(x, math.tau)
        assert got == want, x
        assert math.copysign(1.0, got) == math.copysign(1.0, want), x


def test_boxes_in_base_equal_the_numpy_code() -> None:
    rng = np.random.default_rng(4)
    classes = list(ObjectClass)
    for trial in range(200):
        n = int(rng.integers(0, 30))
        centers = np.column_stack([rng.uniform(-400, 400, (n, 2)), rng.uniform(0, 2, n)])
        objs = ObjectColumns.trusted(
            object_id=rng.permutation(1000)[:n].astype(np.int64),
            object_class=tuple(classes[k] for k in rng.integers(0, len(classes), n)),
            center_m=centers,
            size_m=rng.uniform(0.3, 9.0, (n, 3)),
            yaw_rad=rng.uniform(-9.0, 9.0, n),
            velocity_mps=np.column_stack([rng.normal(0, 8, (n, 2)), np.zeros(n)]),
        )
        pose = pose_matrix(*rng.uniform(-200, 200, 2).tolist(), float(rng.uniform(-4, 4)))
        keep = None if trial % 3 else rng.random(n) < 0.7
        if keep is not None:
            keep.flags.writeable = False
        ids = objs.object_id.tolist()
        hits = None if trial % 2 else {i: int(rng.integers(0, 3)) for i in ids[::2]}
        pixels = None if trial % 4 < 2 else {i: int(rng.integers(0, 2)) for i in ids[1::2]}
        got = objects_in_base(objs, pose, keep=keep, lidar_hits=hits, camera_pixels=pixels)
        _assert_same(got, _numpy_in_base(objs, pose, keep, hits, pixels))


def test_world_ground_truth_in_base_equals_its_columns_moved() -> None:
    for name, start_s in (("urban", 0.0), ("pedestrian_from_occlusion", 2.0)):
        world, ego = World(load_scenario(name)), World(load_scenario(name))
        world.step(start_s)
        ego.step(start_s + 1.0)
        for _ in range(20):
            pose = ego.map_from_base()
            got = world.ground_truth_in_base(pose)
            _assert_same(got, _numpy_in_base(world.ground_truth_columns(), pose, None, None, None))
            world.step(0.1)
            ego.step(0.1)
