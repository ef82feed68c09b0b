"""Closed loop on recorded traffic with its real HD map (issue 34 items 5–6): the Argoverse 2
sensor log, the Waymo Open Motion scenario and the CommonRoad scenarios of ../shared/data.

- an object-level run is paced by the ground truth (all 156 annotated sweeps of the AV2 log,
  though only 2 of its LiDAR sweeps are present);
- the route is the logged ego path on the lane graph, and idm-planner follows it on the road;
- ``redrive evaluate`` scores drivable area, driving direction, speed limit, collisions and TTC
  on the real map and tracks, none skipped;
- the logged ego replayed as the planner (log-future-planner, nuPlan's LogFuturePlanner) drives
  legally on its own map;
- a planner that leaves the road fails drivable area at the frame the footprint leaves it,
  checked against the map file's own polygons (not redrive's index);
- ``--agents reactive``: the logged vehicles behind a stopped ego stop behind it along their
  lanes instead of driving into it.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from redrive.algorithms import StageOutputs
from redrive.cli.main import main
from redrive.evaluation.base import MetricResult
from redrive.evaluation.evaluator import evaluate_run
from redrive.io import open_log
from redrive.io.content import log_road_map
from redrive.maps.index import DRIVABLE_LANE_KINDS, RoadMapIndex, lane_polygon
from redrive.maps.route import route_along_path
from redrive.results import open_run

AV2 = "av2_sensor_val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede"
WOMD = "womd/motion_data_one_scenario.tfrecord"
PLUGINS = "tests.closedloop.plugins"
EXPERT = "redrive.algorithms.reference.log_future:LogFuturePlanner"
#: the map metrics of the issue's must-show, by metric name → its headline value
MAP_METRICS = {
    "drivable_area": "drivable_area_compliance",
    "driving_direction": "driving_direction_compliance",
    "speed_limit": "speed_limit_compliance",
    "at_fault_collisions": "no_at_fault_collisions",
    "time_to_collision": "ttc_within_bound",
}

pytestmark = pytest.mark.shared_data


def _closed(out: Path, log: Path, planner: str, *extra: str) -> None:
    argv = ["run", str(log), "--closed-loop", "--planning", planner, "-o", str(out), *extra]
    assert main(argv) == 0


def _scores(out: Path) -> tuple[dict[str, dict[str, float]], dict[str, str]]:
    """metric → its values, and metric → why it was skipped (the run-level metrics)."""
    values, skipped, _ = _scored(out)
    return values, skipped


def _scored(
    out: Path,
) -> tuple[dict[str, dict[str, float]], dict[str, str], dict[str, MetricResult]]:
    from redrive.evaluation.closedloop import (
        AtFaultCollisions,
        DrivableAreaCompliance,
        DrivingDirectionCompliance,
        SpeedLimitCompliance,
        TimeToCollision,
    )

    metrics = [
        DrivableAreaCompliance(),
        DrivingDirectionCompliance(),
        SpeedLimitCompliance(),
        AtFaultCollisions(),
        TimeToCollision(),
    ]
    summary = evaluate_run(out, metrics=metrics)
    assert not summary.failed, summary.failed
    values = {s.metric.name: dict(s.result.values) for s in summary.scored}
    skipped = {o.metric: o.reason for o in summary.skipped}
    return values, skipped, {s.metric.name: s.result for s in summary.scored}


@pytest.fixture(scope="module")
def av2_idm(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The issue's command: the AV2 log, closed loop, idm-planner."""
    out = tmp_path_factory.mktemp("av2") / "idm"
    _closed(out, shared_data / AV2, "idm-planner")
    return out


def test_av2_object_level_run_is_paced_by_the_ground_truth(av2_idm: Path) -> None:
    run = open_run(av2_idm)
    described = run.manifest.closed_loop
    assert described["paced_by"] == "ground truth (/annotations)"
    assert "no stage reads a sensor" in described["pace_reason"]
    # 156 annotated sweeps at 10 Hz: 155 steps (the last frame has no next one), 15.4 s
    frames = sorted(run.ego())
    assert len(frames) == 155
    stamps = [run.ego()[i].stamp_ns for i in frames]
    assert (stamps[-1] - stamps[0]) / 1e9 == pytest.approx(15.4, abs=0.06)


def test_av2_route_is_the_logged_path_on_the_lane_graph(shared_data: Path) -> None:
    with open_log(shared_data / AV2) as log:
        road = log_road_map(log)
        assert road is not None
        from redrive.assembly.frames import FrameAssembler

        states = list(FrameAssembler(log).ego_states())
    index = RoadMapIndex(road, lane_kinds=DRIVABLE_LANE_KINDS)
    xy = np.array([s.position[:2] for s in states])
    yaw = np.array([s.heading_rad for s in states])
    lanes, line = route_along_path(index, xy, yaw)
    assert len(lanes) >= 3
    # every step of the chain is a successor or a lane change to a neighbour
    for a, b in itertools.pairwise(lanes):
        lane = road.lane(a)
        assert b in lane.successors or b in (lane.left_neighbor, lane.right_neighbor), (a, b)
    # every logged pose lies in a lane of the route, and the reference line (the lanes'
    # centrelines) runs within a lane width of it (the log ends pulled 1.8 m to the right)
    route_lanes = shapely.union_all([lane_polygon(road.lane(i)) for i in lanes])
    assert bool(np.all(shapely.intersects(route_lanes, shapely.points(xy))))
    offsets = shapely.distance(shapely.LineString(line), shapely.points(xy))
    assert float(np.median(offsets)) < 0.5
    assert float(np.max(offsets)) < 2.0


def test_av2_idm_planner_scores_every_map_metric_on_the_road(av2_idm: Path) -> None:
    values, skipped = _scores(av2_idm)
    for metric, headline in MAP_METRICS.items():
        assert metric not in skipped, skipped
        assert headline in values[metric], values
    route = open_run(av2_idm).manifest.closed_loop["route"]
    assert route["lanes"]
    assert route["length_m"] > 75.0
    # it follows the route through the turn: on the road, the right way, no one hit
    assert values["drivable_area"]["drivable_area_compliance"] == 1.0
    assert values["driving_direction"]["driving_direction_compliance"] == 1.0
    assert values["at_fault_collisions"]["no_at_fault_collisions"] == 1.0
    assert values["time_to_collision"]["min_ttc_s"] > 0.0
    # the AV2 vector map has no speed limits (its schema has none): every frame complies, as
    # nuPlan scores a lane without a limit
    assert values["speed_limit"]["speed_limit_compliance"] == 1.0


@pytest.mark.parametrize("which", [AV2, WOMD])
def test_the_logged_ego_as_the_planner_drives_legally_on_its_own_map(
    which: str, shared_data: Path, tmp_path: Path
) -> None:
    out = tmp_path / "expert"
    _closed(out, shared_data / which, EXPERT)
    values, skipped = _scores(out)
    assert not {m for m in MAP_METRICS if m in skipped}, skipped
    assert values["at_fault_collisions"]["no_at_fault_collisions"] == 1.0
    assert values["drivable_area"]["drivable_area_compliance"] == 1.0
    assert values["driving_direction"]["driving_direction_compliance"] == 1.0
    summary = open_run(out).manifest.summary
    assert summary is not None
    assert summary.closed_loop["deviated_frames"] == 0  # the tracker keeps it on the log


def _av2_drivable(shared_data: Path) -> object:
    """The AV2 map file's drivable area, read here with json + shapely: its drivable-area
    polygons and its vehicle/bus lanes' polygons between their boundaries."""
    (path,) = (shared_data / AV2 / "map").glob("log_map_archive_*.json")
    doc = json.loads(path.read_text())
    polys = [
        shapely.Polygon([(p["x"], p["y"]) for p in a["area_boundary"]])
        for a in doc["drivable_areas"].values()
    ]
    for lane in doc["lane_segments"].values():
        if lane["lane_type"] not in ("VEHICLE", "BUS"):
            continue
        left = [(p["x"], p["y"]) for p in lane["left_lane_boundary"]]
        right = [(p["x"], p["y"]) for p in lane["right_lane_boundary"]]
        polys.append(shapely.make_valid(shapely.Polygon(left + right[::-1])))
    return shapely.union_all([shapely.make_valid(p) for p in polys])


def test_a_planner_that_leaves_the_road_fails_drivable_area_at_that_step(
    shared_data: Path, tmp_path: Path
) -> None:
    out = tmp_path / "offroad"
    _closed(out, shared_data / AV2, f"{PLUGINS}:OffRoad")
    values, _, results = _scored(out)
    assert values["drivable_area"]["drivable_area_compliance"] == 0.0
    # the step: the first frame a footprint corner is 0.3 m (nuPlan's max_violation) or more
    # outside the map file's drivable area, from the stored ego states
    drivable = _av2_drivable(shared_data)
    run = open_run(out)
    ego = run.ego()
    first = None
    for index in sorted(ego):
        s = ego[index]
        c, sn = math.cos(s.heading_rad), math.sin(s.heading_rad)
        corners = [
            (float(s.position[0]) + c * dx - sn * dy, float(s.position[1]) + sn * dx + c * dy)
            for dx, dy in ((3.75, 0.95), (-0.95, 0.95), (-0.95, -0.95), (3.75, -0.95))
        ]
        outside = max(shapely.distance(drivable, shapely.Point(p)) for p in corners)
        if outside >= 0.3:
            first = index
            break
    assert first is not None
    assert first > 5  # it starts on the road, leaves it later
    frames, outside_m = results["drivable_area"].per_frame["outside_m"]
    failing = [int(f) for f, d in zip(frames, outside_m, strict=True) if d >= 0.3]
    assert failing[0] == first


def test_reactive_agents_stop_behind_a_stopped_ego_along_their_lanes(
    shared_data: Path, tmp_path: Path
) -> None:
    collisions = {}
    for agents in ("replay", "reactive"):
        out = tmp_path / agents
        _closed(out, shared_data / AV2, f"{PLUGINS}:StandStill", "--agents", agents)
        summary = open_run(out).manifest.summary
        assert summary is not None
        collisions[agents] = summary.closed_loop.get("collision_frames", 0)
    # replayed, the logged traffic drives through where the ego stands; reactive, the
    # vehicles it holds up queue behind it
    assert collisions["replay"] > 0
    assert collisions["reactive"] == 0


def test_a_commonroad_scenario_runs_from_its_planning_problem_start(
    shared_data: Path, tmp_path: Path
) -> None:
    # the planning problem's initial state is the ego's only logged state: every frame of the
    # 32 steps is driven from it (no logged ego to deviate from), the obstacles on the lanes
    out = tmp_path / "cr"
    log = shared_data / "commonroad" / "USA_US101-3_3_T-1.xml"
    _closed(out, log, "idm-planner", "--agents", "reactive", "--perception", "noisy-oracle")
    run = open_run(out)
    assert len(run.ego()) == 31
    assert run.manifest.closed_loop["route"]["lanes"]
    values, skipped = _scores(out)
    assert not {m for m in MAP_METRICS if m in skipped}, skipped
    assert values["drivable_area"]["drivable_area_compliance"] == 1.0


def test_a_commonroad_route_leads_to_the_planning_problems_goal(
    shared_data: Path, tmp_path: Path
) -> None:
    """USA_Peach: the start lies on three overlapping junction lanes, and the one the start pose
    is put on (43634) ends there; the route goes through the one that leads to the goal lanelets
    (43474, 43478, 43482, 43616) and the ego turns onto it; a goal in time only (DEU_A9) keeps
    the logged start's route."""
    from redrive.io.content import log_goal_lanes

    log = shared_data / "commonroad" / "USA_Peach-4_8_T-1.xml"
    with open_log(log) as opened:
        goal = log_goal_lanes(opened)
    assert set(goal) == {"43474", "43478", "43482", "43616"}
    out = tmp_path / "peach"
    _closed(out, log, "idm-planner")
    route = open_run(out).manifest.closed_loop["route"]
    assert route["lanes"][0] == "43648"
    assert set(route["lanes"]) & set(goal)
    assert "goal" in route["source"]
    ego = open_run(out).ego()
    last = ego[max(ego)]
    assert last.position[0] < -5.0  # turned left with the route (straight on stays at x ≈ 0)
    assert last.speed_mps > 3.0  # not stopped at a dead end
    with open_log(shared_data / "commonroad" / "DEU_A9-3_1_T-1.xml") as opened:
        assert opened.capabilities.goal
        assert log_goal_lanes(opened) == ()


def test_a_pipeline_that_reads_the_lidar_is_paced_by_the_lidar(shared_data: Path) -> None:
    from redrive.closedloop.logreplay import LogSimulator
    from redrive.closedloop.tracker import LqrTracker

    with open_log(shared_data / AV2) as log:
        by_lidar = LogSimulator(log, tracker=LqrTracker(), reads_sensors=True)
        by_truth = LogSimulator(log, tracker=LqrTracker(), reads_sensors=False)
        # a stage reads a sensor: it gets every sample — the 2 sweeps present, one step
        assert by_lidar.describe()["paced_by"] == "sensor lidar (/lidar)"
        assert "a stage reads a sensor" in by_lidar.describe()["pace_reason"]
        assert by_lidar.done is False
        steps = 0
        while not by_lidar.done:
            by_lidar.step(StageOutputs(), by_lidar.dt_s)
            steps += 1
        assert steps == 1
        assert by_truth.describe()["paced_by"] == "ground truth (/annotations)"
