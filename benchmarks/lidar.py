"""LiDAR and camera simulation benchmark: redrive's Embree LiDAR against Open3D's ray caster.

The scene is a street block: ``num_boxes`` vehicles driving at 5–15 m/s, a few buildings and
the ground, seen by an HDL-32E (32 × 1800 rays) on a moving ego.  Every redrive sweep moves the
vehicles, builds a new :class:`~redrive.sim.scene.Scene`, re-meshes it and casts the full sweep
with ego-motion skew, noise and intensity (:meth:`redrive.sim.lidar.LidarModel.scan`).  The
baseline, when ``open3d`` is importable (it is never a dependency of redrive), is Open3D's
``o3d.t.geometry.RaycastingScene`` casting the same rays at the same scene, kept *static* and
built once, single-threaded: a ceiling for "just cast the rays".  The ratio is redrive sweeps/s
over Open3D sweeps/s.  Both run pinned to one CPU core (``sched_setaffinity``) so Embree's
builder threads cannot borrow others.  The camera figure is frames/s of
:meth:`redrive.sim.camera.CameraModel.render` at 1280 × 720 on the first scene of the run.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
import os
import statistics
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.sim.camera import CameraModel
from redrive.sim.lidar import LidarModel
from redrive.sim.mesh import box_triangles
from redrive.sim.rig import default_rig
from redrive.sim.scene import GroundLabel, GroundMap, ObjectLooks, Scene
from redrive.types import ObjectClass, ObjectColumns

__all__ = ["TARGET_RATIO", "LidarBenchResult", "bench_lidar", "bench_scene"]

#: redrive sweeps/s over Open3D's (scene update included on our side only).
TARGET_RATIO = 0.5
_SWEEP_NS = 100_000_000
_EGO_SPEED_MPS = 10.0


@dataclass(frozen=True, slots=True, kw_only=True)
class LidarBenchResult:
    """What :func:`bench_lidar` measured (medians over the repeats)."""

    preset: str
    rays_per_scan: int
    boxes: int
    triangles: int
    scans: int
    scans_per_s: float
    points_per_scan: float
    real_time_factor: float
    open3d_version: str | None
    open3d_scans_per_s: float | None
    open3d_note: str
    ratio: float | None
    camera_frames: int
    camera_fps: float
    camera_resolution: tuple[int, int]
    one_core: bool

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def bench_scene(
    rng: np.random.Generator, *, num_boxes: int = 60, num_buildings: int = 4, stamp_ns: int = 0
) -> Scene:
    """A street block: a cross of 14 m wide roads, vehicles on them, buildings in the corners."""
    labels = np.full((400, 400), GroundLabel.GRASS, dtype=np.uint8)  # 0.5 m cells, ±100 m
    labels[186:214, :] = GroundLabel.ROAD
    labels[:, 186:214] = GroundLabel.ROAD
    labels[180:186, :] = GroundLabel.SIDEWALK
    labels[214:220, :] = GroundLabel.SIDEWALK
    labels[199:201, ::6] = GroundLabel.LANE_MARKING
    labels[::6, 199:201] = GroundLabel.LANE_MARKING
    ground = GroundMap(origin_xy=np.array([-100.0, -100.0]), resolution_m=0.5, labels=labels)
    # keep 10 m clear around the ego (at the origin): nothing may stand on the sensor
    along = rng.uniform(10.0, 80.0, num_boxes) * rng.choice([-1.0, 1.0], num_boxes)
    on_x = rng.random(num_boxes) < 0.6
    # the ego drives along x in lane y = −1.75: no vehicle shares it (none may run into it)
    lane = np.where(
        on_x,
        rng.choice([-5.25, 1.75, 5.25], num_boxes),
        rng.choice([-5.25, -1.75, 1.75, 5.25], num_boxes),
    )
    xy = np.where(on_x[:, None], np.c_[along, lane], np.c_[lane, along])
    forward = np.where(lane > 0, -1.0, 1.0)
    yaw = np.where(
        on_x,
        np.where(forward > 0, 0.0, math.pi),
        np.where(forward > 0, 0.5 * math.pi, -0.5 * math.pi),
    )
    sizes = np.tile([4.6, 1.9, 1.6], (num_boxes, 1)) * rng.uniform(0.9, 1.3, (num_boxes, 1))
    speed = rng.uniform(5.0, 15.0, num_boxes)
    corners = np.array([[30.0, 30.0], [-30.0, 30.0], [-30.0, -30.0], [30.0, -30.0]])
    b_xy = np.resize(corners, (num_buildings, 2)) * rng.uniform(1.0, 1.5, (num_buildings, 1))
    b_size = np.c_[rng.uniform(20, 30, (num_buildings, 2)), rng.uniform(8, 25, num_buildings)]
    n = num_boxes + num_buildings
    centers = np.zeros((n, 3))
    centers[:num_boxes, :2] = xy
    centers[:num_boxes, 2] = sizes[:, 2] / 2
    centers[num_boxes:, :2] = b_xy
    centers[num_boxes:, 2] = b_size[:, 2] / 2
    velocities = np.zeros((n, 3))
    velocities[:num_boxes, 0] = speed * np.cos(yaw)
    velocities[:num_boxes, 1] = speed * np.sin(yaw)
    colors = rng.integers(30, 230, (n, 3)).astype(np.uint8)
    colors[num_boxes:] = (150, 140, 130)
    objects = ObjectColumns.of(
        object_id=np.arange(1, n + 1, dtype=np.int64),
        object_class=(ObjectClass.VEHICLE,) * num_boxes + (ObjectClass.STATIC,) * num_buildings,
        center_m=centers,
        size_m=np.r_[sizes, b_size],
        yaw_rad=np.r_[yaw, np.zeros(num_buildings)],
        velocity_mps=velocities,
    )
    looks = ObjectLooks(
        colors_rgb=colors,
        reflectivity=rng.uniform(0.2, 0.9, n).astype(np.float32),
        is_ground_truth=np.r_[np.ones(num_boxes, bool), np.zeros(num_buildings, bool)],
    )
    pose = np.eye(4)
    pose[1, 3] = -1.75
    return Scene(
        stamp_ns=stamp_ns,
        ground=ground,
        objects=objects,
        looks=looks,
        traffic_lights=(),
        map_from_base=pose,
    )


def _advance(scene: Scene, dt_ns: int) -> Scene:
    """The scene ``dt_ns`` later: vehicles and ego moved (a new Scene, as a world would make)."""
    objs = scene.objects
    dt_s = dt_ns * 1e-9
    pose = scene.map_from_base.copy()
    pose[0, 3] += _EGO_SPEED_MPS * dt_s
    moved = dataclasses.replace(objs, center_m=objs.center_m + objs.velocity_mps * dt_s)
    return Scene(
        stamp_ns=scene.stamp_ns + dt_ns,
        ground=scene.ground,
        objects=moved,
        looks=scene.looks,
        traffic_lights=(),
        map_from_base=pose,
    )


@contextmanager
def _one_core(enabled: bool) -> Iterator[bool]:
    if not enabled or not hasattr(os, "sched_setaffinity"):
        yield False
        return
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(before)})
    try:
        yield True
    finally:
        os.sched_setaffinity(0, before)


def _open3d_rays(model: LidarModel, scene: Scene) -> npt.NDArray[np.float32]:
    pose = scene.map_from_base @ model.base_from_sensor
    dirs = model.directions.reshape(-1, 3) @ pose[:3, :3].T
    origins = np.broadcast_to(pose[:3, 3], dirs.shape)
    return np.ascontiguousarray(np.c_[origins, dirs], dtype=np.float32)


def _open3d_caster(
    model: LidarModel, scene: Scene
) -> tuple[str | None, Callable[[], object] | None, str]:
    """(version, cast-one-sweep callable, note); the callable is None without open3d."""
    try:
        # imported by name: open3d is never a dependency, so it stays untyped (Any) here
        o3d: Any = importlib.import_module("open3d")
    except (ImportError, OSError) as err:
        return None, None, f"open3d not importable ({err}); pip install open3d to compare"
    objs = scene.objects
    tris = box_triangles(objs.center_m, objs.size_m, objs.yaw_rad).reshape(-1, 3)
    ground = np.array(
        [[-1e3, -1e3, 0], [1e3, -1e3, 0], [1e3, 1e3, 0], [-1e3, 1e3, 0]], dtype=np.float32
    )
    verts = np.r_[tris, ground].astype(np.float32)
    n = tris.shape[0]
    quad = np.array([[n, n + 1, n + 2], [n, n + 2, n + 3]], np.uint32)
    faces = np.r_[np.arange(n, dtype=np.uint32).reshape(-1, 3), quad]
    mesh = o3d.t.geometry.TriangleMesh()
    mesh.vertex.positions = o3d.core.Tensor(verts)
    mesh.triangle.indices = o3d.core.Tensor(faces)
    rc = o3d.t.geometry.RaycastingScene(nthreads=1)
    rc.add_triangles(mesh)
    rays = o3d.core.Tensor(_open3d_rays(model, scene))
    rc.cast_rays(rays, nthreads=1)  # builds the BVH lazily: not timed

    def cast() -> object:
        return rc.cast_rays(rays, nthreads=1)

    note = "static scene built once, cast_rays(nthreads=1), timed alternately with redrive"
    return str(o3d.__version__), cast, note


def bench_lidar(
    *,
    scans: int = 50,
    camera_frames: int = 10,
    preset: str = "HDL-32E",
    num_boxes: int = 60,
    seed: int = 0,
    one_core: bool = True,
    open3d: bool = True,
    progress: Callable[[str], None] | None = None,
) -> LidarBenchResult:
    """Time ``scans`` moving-scene sweeps, the Open3D baseline and ``camera_frames`` renders."""
    say = progress or (lambda _text: None)
    rng = np.random.default_rng(seed)
    rig = default_rig()
    lidar_spec = rig["lidar_top"]
    model = LidarModel(
        preset, base_from_sensor=lidar_spec.base_from_sensor(), rate_hz=lidar_spec.rate_hz
    )
    camera = CameraModel.from_spec(rig["camera_front"])
    scene = first = bench_scene(rng, num_boxes=num_boxes)

    def ego_pose(sweep: Scene) -> Callable[[int], npt.NDArray[np.float64]]:
        def pose_at(stamp_ns: int) -> npt.NDArray[np.float64]:
            pose = sweep.map_from_base.copy()
            pose[0, 3] += _EGO_SPEED_MPS * (stamp_ns - sweep.stamp_ns) * 1e-9
            return pose

        return pose_at

    with _one_core(one_core) as pinned:
        version, o3d_cast, note = (None, None, "disabled (--no-open3d)")
        if open3d:
            say("Open3D scene")
            version, o3d_cast, note = _open3d_caster(model, scene)
        say("LiDAR")
        model.scan(scene, rng)  # warm-up
        times, o3d_times, points = [], [], []
        for _ in range(scans):
            # alternate the two sides so that both see the same machine load
            t0 = time.perf_counter()
            scene = _advance(scene, _SWEEP_NS)
            scan = model.scan(scene, rng, map_from_base_at=ego_pose(scene))
            times.append(time.perf_counter() - t0)
            points.append(len(scan.cloud))
            if o3d_cast is not None:
                t0 = time.perf_counter()
                o3d_cast()
                o3d_times.append(time.perf_counter() - t0)
        ours = 1.0 / statistics.median(times)
        theirs = 1.0 / statistics.median(o3d_times) if o3d_times else None
        say("camera")
        camera.render(first)
        cam_times = []
        for _ in range(camera_frames):
            t0 = time.perf_counter()
            camera.render(first)
            cam_times.append(time.perf_counter() - t0)
    intr = camera.intrinsics
    return LidarBenchResult(
        preset=model.preset.name,
        rays_per_scan=model.directions.shape[0] * model.directions.shape[1],
        boxes=len(scene.objects),
        triangles=12 * len(scene.objects),
        scans=scans,
        scans_per_s=ours,
        points_per_scan=float(np.mean(points)),
        real_time_factor=ours / model.rate_hz,
        open3d_version=version,
        open3d_scans_per_s=theirs,
        open3d_note=note,
        ratio=None if theirs is None else ours / theirs,
        camera_frames=camera_frames,
        camera_fps=1.0 / statistics.median(cam_times) if cam_times else float("nan"),
        camera_resolution=(intr.width, intr.height),
        one_core=pinned,
    )
