"""Simulated LiDAR: returns on surfaces, preset elevations, falloff with distance, motion skew."""

from __future__ import annotations

import math

import numpy as np
import pytest

from redrive.geometry import compose, invert, transform_points
from redrive.sim.lidar import LidarModel
from redrive.sim.lidar_presets import LIDAR_PRESETS, lidar_preset
from redrive.sim.mesh import box_triangles
from redrive.sim.rig import default_rig
from redrive.sim.scene import GroundLabel, GroundMap, ObjectLooks, Scene
from redrive.types import ObjectClass, ObjectColumns


def make_scene(
    boxes: list[tuple[float, float, float, float, float, float, float]],
    *,
    map_from_base: np.ndarray | None = None,
    stamp_ns: int = 1_000_000_000,
    labels: np.ndarray | None = None,
    colors: list[tuple[int, int, int]] | None = None,
) -> Scene:
    """Boxes (cx, cy, cz, length, width, height, yaw) with ids 1.. on a road raster."""
    n = len(boxes)
    arr = np.array(boxes, dtype=np.float64).reshape(n, 7)
    objects = ObjectColumns.of(
        object_id=np.arange(1, n + 1, dtype=np.int64),
        object_class=(ObjectClass.VEHICLE,) * n,
        center_m=arr[:, :3],
        size_m=arr[:, 3:6],
        yaw_rad=arr[:, 6],
    )
    looks = ObjectLooks(
        colors_rgb=np.array(colors or [(200, 30, 30)] * n, dtype=np.uint8).reshape(n, 3),
        reflectivity=np.full(n, 0.6, dtype=np.float32),
        is_ground_truth=np.ones(n, dtype=bool),
    )
    if labels is None:
        labels = np.full((200, 200), GroundLabel.ROAD, dtype=np.uint8)
    ground = GroundMap(origin_xy=np.array([-100.0, -100.0]), resolution_m=1.0, labels=labels)
    return Scene(
        stamp_ns=stamp_ns,
        ground=ground,
        objects=objects,
        looks=looks,
        traffic_lights=(),
        map_from_base=np.eye(4) if map_from_base is None else map_from_base,
    )


def _mount(z: float = 1.8) -> np.ndarray:
    m = np.eye(4)
    m[2, 3] = z
    return m


def _distance_to_box(points: np.ndarray, box: tuple[float, ...]) -> np.ndarray:
    """Distance of map points to the surface of an upright box."""
    cx, cy, cz, length, width, height, yaw = box
    c, s = math.cos(yaw), math.sin(yaw)
    d = points - np.array([cx, cy, cz])
    local = np.c_[d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c, d[:, 2]]
    half = np.array([length, width, height]) / 2
    q = np.abs(local) - half
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    inside = np.minimum(q.max(axis=1), 0.0)
    return outside + np.abs(inside)


def test_presets_match_published_tables() -> None:
    vlp = lidar_preset("VLP-16")
    assert vlp.elevations_deg[:4] == (-15.0, 1.0, -13.0, 3.0)
    assert sorted(vlp.elevations_deg) == [float(e) for e in range(-15, 16, 2)]
    hdl32 = lidar_preset("HDL-32E")
    assert hdl32.num_lasers == 32
    assert min(hdl32.elevations_deg) == -30.67
    assert max(hdl32.elevations_deg) == 10.67
    assert hdl32.columns == 1800
    assert hdl32.azimuth_resolution_deg == pytest.approx(0.2)
    hdl64 = lidar_preset("HDL-64E")
    assert hdl64.num_lasers == 64
    assert max(hdl64.elevations_deg) == 2.0
    assert hdl64.elevations_deg[31] == pytest.approx(-8.33)
    assert min(hdl64.elevations_deg) == pytest.approx(-24.33)
    assert hdl64.azimuth_resolution_deg == pytest.approx(0.1728, abs=1e-3)
    os1 = lidar_preset("OS1-64")
    assert os1.columns in (1024, 2048)
    assert os1.elevations_deg[0] == 22.5
    assert os1.elevations_deg[-1] == -22.5
    assert np.allclose(np.diff(os1.elevations_deg), -45 / 63)
    for preset in LIDAR_PRESETS.values():
        rings = preset.rings()
        assert sorted(rings.tolist()) == list(range(preset.num_lasers))
    with pytest.raises(KeyError, match="known"):
        lidar_preset("HDL-128")


def test_returns_lie_on_the_surfaces_they_hit() -> None:
    boxes = [(10.0, 0.0, 0.8, 4.5, 1.9, 1.6, 0.3), (-6.0, 8.0, 1.0, 3.0, 2.0, 2.0, -1.0)]
    pose = np.eye(4)
    pose[:3, 3] = [2.0, -1.0, 0.0]
    scene = make_scene(boxes, map_from_base=pose)
    std = 0.01
    model = LidarModel("HDL-32E", base_from_sensor=_mount(), range_std_m=std)
    scan = model.scan(scene, np.random.default_rng(1))
    assert len(scan.cloud) > 20_000
    map_pts = transform_points(compose(pose, _mount()), scan.cloud.xyz.astype(np.float64))
    ground = scan.object_ids == -1
    # the sensor stands still: every point is at its true place, within the range noise
    assert np.abs(map_pts[ground, 2]).max() < 6 * std
    for obj_id, box in enumerate(boxes, start=1):
        mine = scan.object_ids == obj_id
        assert mine.sum() == scan.hits_per_object[obj_id] > 50
        assert _distance_to_box(map_pts[mine], box).max() < 6 * std
    assert set(scan.cloud.channels) == {"intensity", "ring", "t_offset_ns"}
    assert scan.cloud.channels["ring"].dtype == np.uint16
    assert scan.cloud.channels["t_offset_ns"].max() < 100_000_000
    assert np.all(np.diff(scan.cloud.channels["t_offset_ns"].astype(np.int64)) >= 0)


def test_mesh_normals_point_outwards() -> None:
    tris = box_triangles(np.zeros((1, 3)), np.array([[4.0, 2.0, 1.0]]), np.array([0.7]))
    t = tris.astype(np.float64)
    normals = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    assert np.all(np.einsum("ij,ij->i", normals, t.mean(axis=1)) > 0)


@pytest.mark.parametrize("name", ["VLP-16", "HDL-32E", "HDL-64E", "OS1-64"])
def test_beam_elevations_match_the_preset(name: str) -> None:
    # a closed room: every beam hits something
    walls = [
        (0.0, 30.0, 20.0, 60.0, 1.0, 40.0, 0.0),
        (0.0, -30.0, 20.0, 60.0, 1.0, 40.0, 0.0),
        (30.0, 0.0, 20.0, 1.0, 60.0, 40.0, 0.0),
        (-30.0, 0.0, 20.0, 1.0, 60.0, 40.0, 0.0),
    ]
    scene = make_scene(walls)
    preset = lidar_preset(name)
    model = LidarModel(preset, base_from_sensor=_mount(), range_std_m=0.0)
    cloud = model.scan(scene, np.random.default_rng(0)).cloud
    xyz = cloud.xyz.astype(np.float64)
    elev = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
    ring = cloud.channels["ring"]
    want = np.sort(np.asarray(preset.elevations_deg))
    assert np.unique(ring).size == preset.num_lasers
    assert np.abs(elev - want[ring]).max() < 1e-3


def test_points_on_an_object_fall_with_distance() -> None:
    counts = []
    for x in (8.0, 16.0, 32.0):
        scene = make_scene([(x, 0.0, 0.8, 4.5, 1.9, 1.6, math.pi / 2)])
        model = LidarModel("HDL-32E", base_from_sensor=_mount(), range_std_m=0.0)
        counts.append(model.scan(scene, np.random.default_rng(0)).hits_per_object[1])
    assert counts[0] > counts[1] > counts[2] > 0


def test_dropout_and_determinism() -> None:
    scene = make_scene([(10.0, 0.0, 0.8, 4.5, 1.9, 1.6, 0.0)])
    full = LidarModel("VLP-16", base_from_sensor=_mount()).scan(scene, np.random.default_rng(3))
    model = LidarModel("VLP-16", base_from_sensor=_mount(), dropout=0.5)
    a = model.scan(scene, np.random.default_rng(3))
    b = model.scan(scene, np.random.default_rng(3))
    assert np.array_equal(a.cloud.xyz, b.cloud.xyz)
    assert 0.4 < len(a.cloud) / len(full.cloud) < 0.6


def test_intensity_paint_brighter_than_asphalt() -> None:
    labels = np.full((200, 200), GroundLabel.ROAD, dtype=np.uint8)
    labels[:, 100:102] = GroundLabel.LANE_MARKING  # x in [0, 2) m
    scene = make_scene([], labels=labels)
    model = LidarModel("HDL-32E", base_from_sensor=_mount(), range_std_m=0.0)
    cloud = model.scan(scene, np.random.default_rng(0)).cloud
    x = cloud.xyz[:, 0]
    near = np.hypot(cloud.xyz[:, 0], cloud.xyz[:, 1]) < 15
    paint = near & (x > 0.2) & (x < 1.8)
    road = near & (x > 4)
    assert cloud.channels["intensity"][paint].mean() > 3 * cloud.channels["intensity"][road].mean()


def test_ego_motion_skews_the_sweep() -> None:
    # a wall behind the car, seen at the start (rear-left) and the end (rear-right) of the sweep
    wall = (-15.0, 0.0, 3.0, 1.0, 60.0, 6.0, 0.0)
    speed = 20.0
    stamp = 5_000_000_000
    scene = make_scene([wall], stamp_ns=stamp)

    def pose_at(t_ns: int) -> np.ndarray:
        m = np.eye(4)
        m[0, 3] = speed * (t_ns - stamp) * 1e-9
        return m

    model = LidarModel("HDL-32E", base_from_sensor=_mount(), range_std_m=0.0)
    scan = model.scan(scene, np.random.default_rng(0), map_from_base_at=pose_at)
    on_wall = scan.object_ids == 1
    xyz = scan.cloud.xyz[on_wall].astype(np.float64)
    t = scan.cloud.channels["t_offset_ns"][on_wall].astype(np.int64)
    first = t < 10_000_000
    last = t > 90_000_000
    assert first.sum() > 100
    assert last.sum() > 100
    # in the sensor frame at firing time the wall face is at x = −14.5 − v·t
    displacement = xyz[first, 0].mean() - xyz[last, 0].mean()
    dt_s = (t[last].mean() - t[first].mean()) * 1e-9
    assert displacement == pytest.approx(speed * dt_s, abs=0.02)
    assert np.allclose(xyz[:, 0], -14.5 - speed * t * 1e-9, atol=0.02)
    # a static sensor sees no skew
    still = LidarModel("HDL-32E", base_from_sensor=_mount(), range_std_m=0.0).scan(
        scene, np.random.default_rng(0)
    )
    assert np.allclose(still.cloud.xyz[still.object_ids == 1, 0], -14.5, atol=1e-3)


def test_2d_lidar_scans_a_plane() -> None:
    spec = default_rig()["lidar_2d"]
    model = LidarModel.from_spec(spec)
    assert model.preset.columns == 1081
    # base_link at the origin; the 2D scanner sits at x = 3.7, z = 0.5
    scene = make_scene([(10.0, 0.0, 1.0, 1.0, 20.0, 2.0, 0.0)])
    scan = model.scan(scene, np.random.default_rng(0))
    assert len(scan.cloud) > 100
    assert np.all(scan.cloud.xyz[:, 2] == 0.0)
    x = scan.cloud.xyz[:, 0].astype(np.float64)
    assert np.abs(x[scan.object_ids == 1] - (9.5 - 3.7)).max() < 0.2
    angles = np.degrees(np.arctan2(scan.cloud.xyz[:, 1], scan.cloud.xyz[:, 0]))
    assert angles.min() >= -135.01
    assert angles.max() <= 135.01


def test_world_frame_offsets_keep_precision() -> None:
    pose = np.eye(4)
    pose[:2, 3] = [4000.0, -2500.0]
    boxes = [(4010.0, -2500.0, 0.8, 4.5, 1.9, 1.6, 0.0)]
    labels = np.full((10, 10), GroundLabel.ROAD, dtype=np.uint8)
    scene = make_scene(boxes, map_from_base=pose, labels=labels)
    model = LidarModel("VLP-16", base_from_sensor=_mount(), range_std_m=0.0)
    scan = model.scan(scene, np.random.default_rng(0))
    pts = transform_points(compose(pose, _mount()), scan.cloud.xyz.astype(np.float64))
    assert _distance_to_box(pts[scan.object_ids == 1], boxes[0]).max() < 2e-3
    assert invert(pose).shape == (4, 4)


def test_ground_label_lookup_matches_the_scene_contract() -> None:
    from redrive.sim.lidar import _ground_labels

    labels = np.random.default_rng(0).integers(0, 5, (7, 9)).astype(np.uint8)
    ground = GroundMap(origin_xy=np.array([-3.0, 2.0]), resolution_m=0.5, labels=labels)
    xy = np.random.default_rng(1).uniform(-6.0, 8.0, (5000, 2))
    assert np.array_equal(_ground_labels(ground, xy[:, 0], xy[:, 1]), ground.label_at(xy))


def test_boxes_out_of_reach_are_left_out_and_change_nothing() -> None:
    # a wall whose near face is 0.5 m inside the 2D scanner's 30 m range, and boxes beyond it
    wall = (30.0, 0.0, 1.0, 1.0, 12.0, 2.0, 0.0)
    beyond = [(36.0, 0.0, 1.0, 2.0, 2.0, 2.0, 0.3), (-5.0, 80.0, 5.0, 10.0, 10.0, 10.0, 0.0)]
    model = LidarModel("UTM-30LX", base_from_sensor=_mount(0.5), range_std_m=0.0)
    alone = model.scan(make_scene([wall]), np.random.default_rng(0))
    scene = make_scene([*beyond, wall])  # the wall is box 3: boxes are mapped back past a gap
    assert model._boxes_in_range(scene.objects, np.zeros((2, 3))).tolist() == [2]
    both = model.scan(scene, np.random.default_rng(0))
    assert alone.hits_per_object[1] > 20
    assert both.hits_per_object == {1: 0, 2: 0, 3: alone.hits_per_object[1]}
    assert np.array_equal(both.cloud.xyz, alone.cloud.xyz)
    assert np.array_equal(both.cloud.channels["intensity"], alone.cloud.channels["intensity"])
    assert np.array_equal(both.object_ids, np.where(alone.object_ids == 1, 3, -1))
