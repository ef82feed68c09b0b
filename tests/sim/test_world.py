"""The World: determinism, scenes, ego pose history, catalogue scenarios."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from redrive.errors import SimulationError
from redrive.sim import world as world_module
from redrive.sim.scenario import Scenario, list_scenarios, load_scenario
from redrive.sim.scene import Scene
from redrive.sim.world import World
from redrive.types import ObjectClass


def _scene_arrays(scene: Scene) -> list[np.ndarray]:
    o = scene.objects
    return [
        o.object_id,
        o.center_m,
        o.size_m,
        o.yaw_rad,
        o.velocity_mps,
        scene.looks.colors_rgb,
        scene.map_from_base,
    ]


def _run(scenario: Scenario, seconds: float) -> World:
    world = World(scenario)
    world.step(seconds)
    return world


def test_same_seed_identical_different_seed_differs() -> None:
    sc = load_scenario("urban")
    a, b = _run(sc, 1.5), _run(sc, 1.5)
    for x, y in zip(_scene_arrays(a.scene()), _scene_arrays(b.scene()), strict=True):
        assert np.array_equal(x, y)
    sa, sb = a.ego_state(), b.ego_state()
    for name in ("position", "velocity", "acceleration"):
        assert np.array_equal(getattr(sa, name), getattr(sb, name))
    assert (sa.heading_rad, sa.yaw_rate_rad_s) == (sb.heading_rad, sb.yaw_rate_rad_s)
    c = _run(dataclasses.replace(sc, seed=sc.seed + 1), 1.5)
    assert any(
        x.shape != y.shape or not np.array_equal(x, y)
        for x, y in zip(_scene_arrays(a.scene()), _scene_arrays(c.scene()), strict=True)
    )


@pytest.mark.parametrize("name", list_scenarios())
def test_catalogue_scenario_runs_two_seconds(name: str) -> None:
    sc = load_scenario(name)
    world = World(sc)
    t0 = world.time_ns
    for _ in range(20):
        world.step(0.1)
    assert world.time_ns - t0 == 2_000_000_000
    scene = world.scene()  # its speed is measured by `redrive bench closed-loop`, not here
    assert scene.stamp_ns == world.time_ns
    objs = scene.objects
    assert len(objs) > 0
    assert 0 not in objs.object_id.tolist()  # the ego's own box is not in the scene
    static = np.array([c is ObjectClass.STATIC for c in objs.object_class])
    assert not np.any(scene.looks.is_ground_truth[static])
    assert np.all(scene.looks.is_ground_truth[~static])
    state = world.ego_state()
    assert state.speed_mps > 1.0
    np.testing.assert_allclose(world.map_from_base()[:2, 3], state.position[:2])


def test_ego_pose_history_interpolates() -> None:
    world = World(load_scenario("highway"))
    world.step(0.5)
    now = world.time_ns
    np.testing.assert_array_equal(world.map_from_base_at(now), world.map_from_base())
    mid = world.map_from_base_at(now - 50_000_000 - 5_000_000)  # between physics steps
    earlier = world.map_from_base_at(now - 60_000_000)
    later = world.map_from_base_at(now - 50_000_000)
    np.testing.assert_allclose(mid[:3, 3], (earlier[:3, 3] + later[:3, 3]) / 2)
    speed = world.ego_state().speed_mps
    assert np.linalg.norm(world.map_from_base()[:2, 3] - world.map_from_base_at(now - 100_000_000)[:2, 3]) == pytest.approx(0.1 * speed, rel=0.02)  # fmt: skip
    with pytest.raises(SimulationError, match="pose history"):
        world.map_from_base_at(now - 1_000_000_000)
    with pytest.raises(SimulationError, match="before the current time"):
        world.step_to(now - 1)


def test_lights_in_scene_and_red_light_stop() -> None:
    world = World(load_scenario("red_light"))
    world.step(14.0)
    states = {t.light_id: t.state for t in world.scene().traffic_lights}
    assert len(states) == 4
    route = world.network.routes[world.scenario.ego.route]
    front_x = world.ego_state().position[0] + world.ego_geometry.front_offset_m
    stop_x, _, _ = route.pose_at(route.stop_lines[0].s_m)
    assert front_x < stop_x
    assert world.ego_state().speed_mps < 1.0


def test_pedestrian_from_occlusion_starts_and_ego_yields() -> None:
    world = World(load_scenario("pedestrian_from_occlusion"))
    scene0 = world.scene()
    ped = [i for i, c in enumerate(scene0.objects.object_class) if c is ObjectClass.PEDESTRIAN]
    assert len(ped) == 1
    y0 = scene0.objects.center_m[ped[0], 1]
    min_speed = np.inf
    for _ in range(100):
        world.step(0.1)
        min_speed = min(min_speed, world.ego_state().speed_mps)
    y1 = world.scene().objects.center_m[ped[0], 1]
    assert y1 - y0 > 5.0  # crossed the lane to the left
    assert min_speed < 5.0  # the ego braked for it


def test_ground_is_cached_and_plausible() -> None:
    world = World(load_scenario("urban"))
    assert world.scene().ground is world.scene().ground
    assert world.ground.labels.shape[0] * world.ground.resolution_m < 400.0


@pytest.mark.parametrize("name", ["cut_in", "lead_vehicle_hard_brake"])
def test_ego_keeps_a_gap_to_cut_in_and_braking_leads(name: str) -> None:
    world = World(load_scenario(name))
    geo = world.ego_geometry
    min_gap = np.inf
    for _ in range(100):  # 10 s
        world.step(0.1)
        scene = world.scene()
        objs = scene.objects
        state = world.ego_state()
        heading = np.array([np.cos(state.heading_rad), np.sin(state.heading_rad)])
        rel = objs.center_m[:, :2] - state.position[:2]
        ahead = rel @ heading
        lateral = np.abs(rel @ np.array([-heading[1], heading[0]]))
        in_lane = scene.looks.is_ground_truth & (lateral < 1.5) & (ahead > 0)
        if np.any(in_lane):
            gaps = ahead[in_lane] - objs.size_m[in_lane, 0] / 2 - geo.front_offset_m
            min_gap = min(min_gap, float(gaps.min()))
    assert 1.0 < min_gap < 15.0


def test_ground_truth_objects_are_the_ground_truth_rows_of_objects() -> None:
    """ground_truth_objects() (the object-level observation's source) lists exactly the
    ground-truth rows of objects(), in order — also with scenery marked as ground truth."""
    world = _run(load_scenario("urban"), 1.0)
    for marked in (False, True):
        if marked:  # mark two scenery boxes as ground truth, as a scenario could
            static, looks = world._static
            flags = looks.is_ground_truth.copy()
            flags[[3, 7]] = True
            world._static = (static, dataclasses.replace(looks, is_ground_truth=flags))
            world._static_truth = world_module._subset(world._static, flags)
        (full, full_looks), truth = world.objects(), world.ground_truth_objects()
        keep = np.flatnonzero(full_looks.is_ground_truth)
        assert len(truth) == len(keep) > 0
        assert truth.object_class == tuple(full.object_class[i] for i in keep)
        for name in ("object_id", "center_m", "size_m", "yaw_rad", "velocity_mps"):
            assert np.array_equal(getattr(truth, name), getattr(full, name)[keep])


@pytest.mark.parametrize(
    ("name", "start_s", "end_s"), [("pedestrian_from_occlusion", 0.0, 6.0), ("highway", 21.5, 22.5)]
)
def test_ground_truth_columns_equal_ground_truth_objects(
    name: str, start_s: float, end_s: float
) -> None:
    """ground_truth_columns() (the closed loop's observation) has ground_truth_objects()'s
    rows and values every frame: walkers starting, parked cars, followers leaving, scenery
    marked as ground truth, the agents dropped."""
    sc = load_scenario(name)
    world = World(sc)
    world.step(start_s)
    names = ("object_id", "center_m", "size_m", "yaw_rad", "velocity_mps")
    frame = 0
    while world.time_s < end_s:
        if frame == 3:  # scenery marked as ground truth joins the columns
            static, looks = world._static
            flags = looks.is_ground_truth.copy()
            flags[[2, 5]] = True
            world._static = (static, dataclasses.replace(looks, is_ground_truth=flags))
            world._static_truth = world_module._subset(world._static, flags)
            world._truth_cache = None
        truth, columns = world.ground_truth_objects(), world.ground_truth_columns()
        assert columns.object_class == truth.object_class
        for attr in names:
            assert np.array_equal(getattr(columns, attr), getattr(truth, attr)), attr
        world.step(0.1)
        frame += 1
    world.drop_agents()
    truth, columns = world.ground_truth_objects(), world.ground_truth_columns()
    assert len(columns) == len(truth) == 2
    for attr in names:
        assert np.array_equal(getattr(columns, attr), getattr(truth, attr)), attr
