"""Camera: projected ground-truth boxes match the rendered pixels; occlusion; street look."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from redrive.errors import SimulationError
from redrive.geometry import box_corners, project_points
from redrive.sim.camera import GROUND_COLORS, CameraModel
from redrive.sim.rig import CameraIntrinsics, default_rig, rig_from_mapping
from redrive.sim.scenario import load_scenario
from redrive.sim.scene import GroundLabel, Scene
from redrive.sim.world import World
from redrive.types import Box3D
from tests.sim.test_lidar import make_scene

RED, BLUE = (220, 20, 20), (20, 20, 220)


def _camera() -> CameraModel:
    return CameraModel.from_spec(default_rig()["camera_front"])


def _mask(pixels: np.ndarray, rgb: tuple[int, int, int]) -> np.ndarray:
    """Pixels whose hue matches ``rgb`` (shading scales it, fog blends it)."""
    p = pixels.astype(np.int32)
    c = 0 if rgb == RED else 2
    others = np.delete(p, c, axis=2).max(axis=2)
    return (p[..., c] > 2 * others) & (p[..., c] > 30)


def _rect(mask: np.ndarray) -> tuple[int, int, int, int]:
    rows, cols = np.nonzero(mask)
    return int(cols.min()), int(rows.min()), int(cols.max()), int(rows.max())


@pytest.mark.parametrize(
    "box", [(12.0, 1.0, 0.8, 4.5, 1.9, 1.6, 0.4), (25.0, -4.0, 1.5, 8.0, 2.5, 3.0, -0.9)]
)
def test_projected_box_matches_rendered_pixels(box: tuple[float, ...]) -> None:
    scene = make_scene([box], colors=[RED])
    cam = _camera()
    frame = cam.render(scene)
    assert frame.image.encoding == "rgb8"
    assert frame.image.pixels.shape == (720, 1280, 3)
    corners = box_corners(Box3D(center=box[:3], size=box[3:6], yaw_rad=box[6]))
    uv, depth = project_points(cam.image_from_map(scene.map_from_base), corners)
    assert np.all(depth > 0)
    want = (uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max())
    got = _rect(_mask(frame.image.pixels, RED))
    assert np.allclose(got, want, atol=2.0)
    assert frame.pixels_per_object[1] == _mask(frame.image.pixels, RED).sum()
    # depth of the box pixels lies between the nearest and farthest corner
    hit = _mask(frame.image.pixels, RED)
    assert depth.min() - 1e-3 <= frame.depth_m[hit].min()
    assert frame.depth_m[hit].max() <= depth.max() + 1e-3


def test_near_box_occludes_far_box_and_ground() -> None:
    near = (10.0, 0.0, 1.0, 2.0, 2.0, 2.0, 0.0)
    far = (20.0, 0.0, 2.0, 2.0, 6.0, 4.0, 0.0)
    scene = make_scene([far, near], colors=[BLUE, RED])
    frame = _camera().render(scene)
    red, blue = _mask(frame.image.pixels, RED), _mask(frame.image.pixels, BLUE)
    r0, r1 = _rect(red), _rect(blue)
    # the far (bigger) box frames the near one on both sides, but none of it shows through
    assert r1[0] < r0[0]
    assert r1[2] > r0[2]
    centre_row = (r0[1] + r0[3]) // 2
    assert red[centre_row, (r0[0] + r0[2]) // 2]
    assert not blue[r0[1] + 2 : r0[3] - 1, r0[0] + 2 : r0[2] - 1].any()
    assert frame.pixels_per_object[2] == red.sum()
    assert frame.pixels_per_object[1] == blue.sum()
    # ground below the near box is hidden where the box is
    assert np.all(frame.depth_m[red] < 11.5)


def test_street_looks_like_a_street() -> None:
    labels = np.full((200, 200), GroundLabel.GRASS, dtype=np.uint8)
    labels[93:107, :] = GroundLabel.ROAD  # y ∈ [-7, 7)
    labels[99:100, ::4] = GroundLabel.LANE_MARKING  # dashed centre line at y ∈ [-1, 0)
    scene = make_scene([], labels=labels)
    frame = _camera().render(scene)
    px = frame.image.pixels.astype(np.int32)
    h, w = 720, 1280
    # sky above the horizon: blue, brighter toward the horizon
    assert px[10, w // 2, 2] > px[10, w // 2, 0]
    assert px[300, w // 2].sum() > px[10, w // 2].sum()
    assert np.isinf(frame.depth_m[:350]).all()
    # just below the camera: asphalt in the middle, grass at the edges
    road = np.array(GROUND_COLORS[GroundLabel.ROAD])
    assert np.abs(px[h - 1, w // 2 + 200] - road).max() < 12
    grass_rows = px[400:, 0]
    assert (grass_rows[:, 1] > grass_rows[:, 0] + 20).any()
    # lane marking paint visible somewhere ahead
    assert (px[360:, :].min(axis=2) > 200).any()


def test_intrinsics_drive_the_image_size() -> None:
    intr = CameraIntrinsics(width=320, height=240, fx=250.0, fy=250.0, cx=159.5, cy=119.5)
    cam = CameraModel(intr, base_from_optical=default_rig()["camera_front"].base_from_optical())
    frame = cam.render(make_scene([(8.0, 0.0, 0.8, 4.5, 1.9, 1.6, 0.0)]))
    assert frame.image.pixels.shape == (240, 320, 3)
    assert frame.depth_m.shape == (240, 320)


def _urban_scene() -> tuple[Scene, dict[str, object]]:
    scenario = load_scenario("urban")
    world = World(scenario)
    world.step_to(world.time_ns + 3_000_000_000)
    return world.scene(), dict(scenario.rig)


@pytest.mark.parametrize("rpy", [(0.0, 0.0, 0.0), (0.3, 0.05, -0.2)])
def test_image_does_not_depend_on_the_threads_drawing_it(rpy: tuple[float, float, float]) -> None:
    """Bands of rows on 1, 2 or 3 threads: the same pixels, depth and per-object counts — also
    for a rolled camera, whose ground and sky are not whole rows."""
    scene, rig_table = _urban_scene()
    spec = dataclasses.replace(
        rig_from_mapping(rig_table, source="urban")["camera_front"], rpy_rad=rpy
    )
    frames = []
    for workers in (1, 2, 3):
        cam = CameraModel(spec.camera, base_from_optical=spec.base_from_optical(), workers=workers)
        frames.append(cam.render(scene))
    one = frames[0]
    assert len(set(one.pixels_per_object.values())) > 2  # boxes were drawn
    assert (one.depth_m == np.inf).any()  # sky
    assert np.isfinite(one.depth_m).any()  # ground
    for other in frames[1:]:
        assert np.array_equal(other.image.pixels, one.image.pixels)
        assert np.array_equal(other.depth_m, one.depth_m)
        assert other.pixels_per_object == one.pixels_per_object


def test_workers_must_be_positive() -> None:
    spec = default_rig()["camera_front"]
    with pytest.raises(SimulationError, match="workers must be >= 1"):
        CameraModel(spec.camera, base_from_optical=spec.base_from_optical(), workers=0)
