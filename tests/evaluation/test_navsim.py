"""NAVSIM's PDMS (v1.1) and EPDMS (v2): the scorer on small hand-derived cases, the LQR and
bicycle simulation, the two-frame extended comfort, and the pseudo-simulation of an open-loop
run of a synthetic log through ``redrive evaluate``."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import shapely

from redrive.evaluation.closedloop.navsim_comfort import two_frame_extended_comfort
from redrive.evaluation.closedloop.navsim_run import V1_KEYS, V2_KEYS, SceneScore, _finalise
from redrive.evaluation.closedloop.navsim_scene import (
    interpolate_observation,
    map_context,
    red_light_polygons,
)
from redrive.evaluation.closedloop.navsim_score import score_proposals
from redrive.evaluation.closedloop.navsim_sim import SIM_DEFAULTS, simulate_proposals
from redrive.types import LightState, MapLane, ObjectClass, ObjectColumns, RoadMap

DT = 0.1
N = 41
#: the redrive ego (4.7 m × 1.9 m, rear overhang 0.95 m): rear axle → centre 1.4 m, → front 3.75 m
VEHICLE = {"half_length_m": 2.35, "half_width_m": 0.95, "rear_axle_to_center_m": 1.4}
#: a straight two-lane road along +x: "east" (y = 0) and "west" (y = 3.5, the other way)
ROAD = RoadMap(
    lanes=(
        MapLane(lane_id="east", centerline=np.array([[-100.0, 0.0], [400.0, 0.0]]), width_m=3.5),
        MapLane(lane_id="west", centerline=np.array([[400.0, 3.5], [-100.0, 3.5]]), width_m=3.5),
    )
)
CTX = map_context(ROAD, ego_xy=np.zeros(2), ego_heading_rad=0.0, visited_lane_ids=["east"])


def straight(speed_mps: float, *, y: float = 0.0) -> np.ndarray:
    """(N, 11) NAVSIM states driving along +x from x = 0 at a constant speed."""
    s = np.zeros((N, 11))
    s[:, 0] = speed_mps * np.arange(N) * DT
    s[:, 1] = y
    s[:, 3] = speed_mps
    return s


def boxes(*items: tuple[float, float, ObjectClass, float]) -> ObjectColumns:
    """Boxes 4.5 × 1.9 m heading +x at (x, y), of a class, moving at vx."""
    return ObjectColumns.of(
        object_class=[c for _, _, c, _ in items],
        center_m=[[x, y, 0.8] for x, y, _, _ in items],
        size_m=[[4.5, 1.9, 1.5]] * len(items),
        yaw_rad=[0.0] * len(items),
        object_id=list(range(1, len(items) + 1)),
        velocity_mps=[[vx, 0.0, 0.0] for _, _, _, vx in items],
    )


def score(version: str, *states: np.ndarray, objs: ObjectColumns | None = None, **kw: object):
    steps = 51 if version == "v1" else N
    samples = [objs] * (steps // 5 + 1) if objs is not None else [None] * (steps // 5 + 1)
    obs, unique = interpolate_observation(samples, n_steps=steps)
    return score_proposals(
        np.stack(states),
        obs=obs,
        unique=unique,
        ctx=CTX,
        version=version,
        vehicle=VEHICLE,
        interval_s=DT,
        **kw,  # type: ignore[arg-type]
    )


# -- hand-derived cases: [PDM-Closed's reference, the planner] -------------------------------


def test_never_moving_ego() -> None:
    """The reference drives 40 m, the planner stands: EP 0, TTC ignores a stopped ego, comfort
    holds: PDMS = (5·0 + 5·1 + 2·1)/12, EPDMS = (5·0 + 5·1 + 2·1 + 2·1)/14."""
    v1 = score("v1", straight(10.0), straight(0.0))
    assert {k: v1[k][1] for k in ("nc", "dac", "ep", "ttc", "c")} == {
        "nc": 1.0,
        "dac": 1.0,
        "ep": 0.0,
        "ttc": 1.0,
        "c": 1.0,
    }
    assert v1["score"][1] == pytest.approx(7 / 12)
    assert v1["score"][0] == pytest.approx(1.0)
    v2 = score("v2", straight(10.0), straight(0.0))
    assert {k: v2[k][1] for k in ("nc", "dac", "ddc", "tlc", "ep", "ttc", "lk", "hc")} == {
        "nc": 1.0,
        "dac": 1.0,
        "ddc": 1.0,
        "tlc": 1.0,
        "ep": 0.0,
        "ttc": 1.0,
        "lk": 1.0,
        "hc": 1.0,
    }
    assert v2["score"][1] == pytest.approx(9 / 14)


def test_at_fault_collision_with_an_agent_scores_zero() -> None:
    """10 m/s into a stopped car 30 m ahead (its rear at 27.75 m, reached at 2.4 s): a
    stopped-track collision, at fault, with an agent: NC 0."""
    car = boxes((30.0, 0.0, ObjectClass.VEHICLE, 0.0))
    for version in ("v1", "v2"):
        res = score(version, straight(10.0), straight(10.0), objs=car)
        assert res["nc"][1] == 0.0
        assert res["ttc"][1] == 0.0
        assert res["score"][1] == 0.0


def test_at_fault_collision_with_an_object_halves() -> None:
    """The same into a static object: NC 0.5 (NAVSIM keeps the minimum: 0.5 however many);
    both proposals alike, so each passes half its raw progress and EP is 1.
    PDMS = 0.5·(5·1 + 5·0 + 2·1)/12, EPDMS = 0.5·(5·1 + 5·0 + 2·1 + 2·1)/14."""
    cone = boxes((30.0, 0.0, ObjectClass.STATIC, 0.0))
    v1 = score("v1", straight(10.0), straight(10.0), objs=cone)
    assert (v1["nc"][1], v1["ttc"][1], v1["ep"][1]) == (0.5, 0.0, 1.0)
    assert v1["score"][1] == pytest.approx(0.5 * 7 / 12)
    v2 = score("v2", straight(10.0), straight(10.0), objs=cone)
    assert v2["score"][1] == pytest.approx(0.5 * 9 / 14)


def test_a_collision_the_ego_is_not_at_fault_for_is_ignored() -> None:
    """A car driving into the back of the ego (active rear): no fault, NC 1."""
    chaser = boxes((-8.0, 0.0, ObjectClass.VEHICLE, 20.0))  # 20 m/s from 8 m behind
    res = score("v1", straight(5.0), straight(5.0), objs=chaser)
    assert res["nc"][1] == 1.0


def test_off_road_step_fails_drivable_area() -> None:
    """One step 3 m right of the lane (corners below the road's y = −1.75 edge): DAC 0."""
    off = straight(10.0)
    off[20, 1] = -3.0
    for version in ("v1", "v2"):
        res = score(version, straight(10.0), off)
        assert res["dac"][1] == 0.0
        assert res["score"][1] == 0.0


def test_slow_but_safe() -> None:
    """Half the reference's progress: EP 0.5. PDMS = (5·0.5 + 5 + 2)/12,
    EPDMS = (5·0.5 + 5 + 2 + 2)/14."""
    v1 = score("v1", straight(10.0), straight(5.0))
    assert v1["ep"][1] == pytest.approx(0.5)
    assert v1["score"][1] == pytest.approx(9.5 / 12)
    v2 = score("v2", straight(10.0), straight(5.0))
    assert v2["score"][1] == pytest.approx(11.5 / 14)


def test_progress_below_threshold_is_not_normalised() -> None:
    """Neither proposal passes 5 m: v1.1 and v2 both give EP 1 (v1.1 would give 0 to one that
    fails a multiplicative metric)."""
    res = score("v1", straight(1.0), straight(0.5))
    assert res["ep"].tolist() == [1.0, 1.0]


def test_running_a_red_light_scores_zero() -> None:
    """The lane from x = 30 m is under a red light: a planner that drives into it gets TLC 0 and
    EPDMS 0; one that stops before it keeps TLC 1."""
    red_lane = shapely.box(30.0, -1.75, 45.0, 1.75)
    red = [[red_lane]] * N
    stop = straight(0.0)
    stop[:, 0] = np.minimum(10.0 * np.arange(N) * DT, 20.0)  # stops with its front at 23.75 m
    res = score("v2", stop, straight(10.0), red_lights=red)
    assert res["tlc"].tolist() == [1.0, 0.0]
    assert res["score"][1] == 0.0
    assert res["score"][0] > 0.0


def test_red_light_polygons_follow_the_map_and_the_states() -> None:
    """Red lights cover the on-route lanes they control; green ones and off-route lanes none.
    As in nuPlan's maps the lights sit on lanes inside an intersection (the connectors); a light
    on an approach lane that leads nowhere covers nothing (no connector is beyond its line)."""
    from redrive.types import Intersection, MapTrafficLight

    square = np.array([[-100.0, -5.0], [400.0, -5.0], [400.0, 8.0], [-100.0, 8.0]])
    road = RoadMap(
        lanes=(
            *(dataclasses.replace(lane, intersection_id="X") for lane in ROAD.lanes),
            MapLane(lane_id="spur", centerline=np.array([[0.0, -20.0], [0.0, -10.0]]), width_m=3.5),
        ),
        intersections=(
            Intersection(intersection_id="X", polygon=square, lane_ids=("east", "west")),
        ),
        traffic_lights=(
            MapTrafficLight(light_id="L1", position=np.zeros(2), lane_ids=("east",)),
            MapTrafficLight(light_id="L2", position=np.zeros(2), lane_ids=("west",)),
            MapTrafficLight(light_id="L3", position=np.zeros(2), lane_ids=("spur",)),
        ),
    )
    states = [
        {"L1": LightState.RED, "L2": LightState.RED, "L3": LightState.RED},
        {"L1": LightState.GREEN},
        None,
    ]
    got = red_light_polygons(road, CTX, states)
    assert [len(p) for p in got] == [1, 0, 0]  # "west" is not on the route, "spur" leads nowhere
    assert got[0][0].equals(CTX.lane_polygon_by_id["east"])


def test_epdms_aggregate_with_and_without_extended_comfort() -> None:
    """EC is weight 2 of 16; the first proposal of a sequence has none (weights 14)."""
    parts = dict.fromkeys(V2_KEYS, 1.0) | {"ep": 0.5}
    sim = straight(10.0)
    scenes = [
        SceneScore(frame=f, stamp_ns=f * 100_000_000, parts=parts, score=0.0, simulated=sim)
        for f in (0, 5)
    ]
    out = _finalise(scenes, version="v2", dt=DT)
    assert np.isnan(out[0].parts["ec"])
    assert out[0].score == pytest.approx((2.5 + 5 + 2 + 2) / 14)
    assert out[1].parts["ec"] == 1.0
    assert out[1].score == pytest.approx((2.5 + 5 + 2 + 2 + 2) / 16)
    v1 = _finalise(
        [
            SceneScore(
                frame=0, stamp_ns=0, parts=dict.fromkeys(V1_KEYS, 1.0), score=0.0, simulated=sim
            )
        ],
        version="v1",
        dt=DT,
    )
    assert v1[0].score == 1.0


def test_two_frame_extended_comfort() -> None:
    """Identical consecutive plans are comfortable; one that brakes where the last cruised is
    not (its acceleration differs by more than 0.7 m/s² RMS)."""
    cruise = straight(10.0)
    assert two_frame_extended_comfort(cruise, cruise, interval_s=DT, gap_s=0.5) == 1.0
    brake = cruise.copy()
    brake[:, 5] = -3.0
    assert two_frame_extended_comfort(brake, cruise, interval_s=DT, gap_s=0.5) == 0.0


# -- the simulation ------------------------------------------------------------------------


def _poses(x: np.ndarray) -> np.ndarray:
    return np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])[None]


def test_lqr_tracks_a_straight_cruise() -> None:
    t = np.arange(N) * DT
    init = straight(10.0)[0]
    sim = simulate_proposals(_poses(10.0 * t), init, p=SIM_DEFAULTS)[0]
    assert np.abs(sim[:, 0] - 10.0 * t).max() < 0.05
    assert np.abs(sim[:, 1]).max() < 1e-9
    assert sim[-1, 3] == pytest.approx(10.0, abs=0.05)


def test_lqr_starts_from_rest() -> None:
    """A plan accelerating from rest at 2 m/s² (16 m in 4 s): the reference speed 1 s ahead is
    above the 0.2 m/s stopping band, so the LQR drives off."""
    t = np.arange(N) * DT
    sim = simulate_proposals(_poses(t**2), np.zeros(11), p=SIM_DEFAULTS)[0]
    assert sim[-1, 3] > 4.0
    assert sim[-1, 0] > 8.0


def test_stopped_plan_from_rest_stays_put() -> None:
    sim = simulate_proposals(_poses(np.zeros(N)), np.zeros(11), p=SIM_DEFAULTS)[0]
    assert np.abs(sim[:, :4]).max() == 0.0


def test_lqr_follows_a_lane_change() -> None:
    """A 3.5 m lateral move over 4 s at 10 m/s is followed within half a metre at the end."""
    t = np.arange(N) * DT
    y = 3.5 * (1 - np.cos(np.pi * t / 4.0)) / 2
    heading = np.arctan2(np.gradient(y, t), 10.0)
    poses = np.column_stack([10.0 * t, y, heading])[None]
    sim = simulate_proposals(poses, straight(10.0)[0], p=SIM_DEFAULTS)[0]
    assert abs(sim[-1, 1] - 3.5) < 0.5


# -- pseudo-simulation of an open-loop run -------------------------------------------------


def test_evaluate_reports_navsim_pdms_per_proposal(demo_run: Path, tmp_path: Path) -> None:
    """``redrive evaluate`` of the open-loop run of the synthetic ``urban`` log: navsim_pdms of
    every 0.5-s proposal (frames 5 apart at 10 Hz) and their mean; EPDMS likewise."""
    from redrive.cli.main import main
    from redrive.results.evaluation import read_evaluation

    run = tmp_path / "run"
    shutil.copytree(demo_run, run)
    args = ["evaluate", str(run)]
    for cls in ("NavsimPdms", "NavsimEpdms"):
        args += ["--metric", f"redrive.evaluation.closedloop.pdm:{cls}"]
    assert main(args) == 0
    ev = read_evaluation(run)
    rows = [r for r in ev.per_frame.to_pylist() if r["metric"] == "navsim_pdms"]
    series = sorted((r["frame_index"], r["value"]) for r in rows if r["series"] == "navsim_pdms")
    frames = [f for f, _ in series]
    assert len(frames) >= 10  # 10 s of log, 4 s of future each: ≥ 12 proposals
    assert set(np.diff(frames).tolist()) == {5}
    values = [v for _, v in series]
    assert all(0.0 <= v <= 1.0 for v in values)
    assert ev.value("navsim_pdms", "navsim_pdms", algorithm="planner") == pytest.approx(
        float(np.mean(values))
    )
    assert ev.value("navsim_pdms", "proposals", algorithm="planner") == len(frames)
    assert 0.0 <= ev.value("navsim_epdms", "navsim_epdms", algorithm="planner") <= 1.0


def test_planner_path_in_base_link_or_map_gives_the_same_poses() -> None:
    """A path 10 m/s straight ahead of an ego at (5, 2) heading 90°: the same poses whether the
    waypoints are in base_link or in the map; headings are the direction of travel."""
    from redrive.evaluation.closedloop.navsim_run import planner_poses
    from redrive.types import PlannedPath, VehicleState

    ego = VehicleState(stamp_ns=0, position=np.array([5.0, 2.0, 0.0]), heading_rad=np.pi / 2)
    t = np.arange(1, 9) * 0.5
    local = np.column_stack([10.0 * t, np.zeros(8), np.zeros(8), t])
    world = np.column_stack([np.full(8, 5.0), 2.0 + 10.0 * t, np.zeros(8), t])
    a = planner_poses(PlannedPath(stamp_ns=0, waypoints=local), ego, SIM_DEFAULTS)
    b = planner_poses(PlannedPath(stamp_ns=0, waypoints=world, frame_id="map"), ego, SIM_DEFAULTS)
    assert a is not None
    assert b is not None
    assert a.shape == (N, 3)
    np.testing.assert_allclose(a, b, atol=1e-9)
    np.testing.assert_allclose(a[:, 0], 5.0, atol=1e-9)
    np.testing.assert_allclose(a[:, 1], 2.0 + 10.0 * np.arange(N) * DT, atol=1e-9)
    np.testing.assert_allclose(a[:, 2], np.pi / 2, atol=1e-9)
    odd = PlannedPath(stamp_ns=0, waypoints=local, frame_id="odom")
    assert planner_poses(odd, ego, SIM_DEFAULTS) is None


def test_light_states_are_read_from_the_run_when_it_has_them() -> None:
    """``light_states``: frame → light id → state from the run's logged lights; None when this
    run cannot say (then no light is red for TLC)."""
    from redrive.evaluation.closedloop.pdm import light_states
    from redrive.types import TrafficLight

    lights = {3: (TrafficLight(id="L1", state=LightState.RED),)}
    with_lights = SimpleNamespace(traffic_lights=lambda: lights, run=None)
    assert light_states(with_lights) == {3: {"L1": LightState.RED}}  # type: ignore[arg-type]
    without = SimpleNamespace(run=SimpleNamespace())
    assert light_states(without) is None  # type: ignore[arg-type]


def test_the_route_goes_on_and_a_red_light_covers_the_connector_past_its_stop_line() -> None:
    """A lane to a stop line at x = 0, a connector across the junction and a lane beyond; the
    light controls the approach.  The route goes on past the log's last lane along the straightest
    successor, and a red light covers the connector (NAVSIM's lane-connector polygon), not the
    approach where the ego waits."""
    from redrive.evaluation.closedloop.navsim_run import _extend_route
    from redrive.types import Intersection, MapTrafficLight

    def lane(lid: str, x0: float, x1: float, **kw: object) -> MapLane:
        return MapLane(lane_id=lid, centerline=np.array([[x0, 0.0], [x1, 0.0]]), width_m=3.5, **kw)  # type: ignore[arg-type]

    road = RoadMap(
        lanes=(
            lane("in", -100.0, 0.0, successors=("conn",)),
            lane("conn", 0.0, 20.0, predecessors=("in",), successors=("out",), intersection_id="j"),
            lane("out", 20.0, 200.0, predecessors=("conn",)),
        ),
        intersections=(
            Intersection(
                intersection_id="j",
                polygon=np.array([[0.0, -10.0], [20.0, -10.0], [20.0, 10.0], [0.0, 10.0]]),
                lane_ids=("conn",),
            ),
        ),
        traffic_lights=(
            MapTrafficLight(light_id="L", position=np.array([0.0, -3.0]), lane_ids=("in",)),
        ),
    )
    route = _extend_route(road, ["in"], length_m=100.0)
    assert route == ["in", "conn", "out"]
    ctx = map_context(
        road, ego_xy=np.array([-30.0, 0.0]), ego_heading_rad=0.0, visited_lane_ids=route
    )
    assert ctx.centerline is not None
    assert ctx.centerline.length == pytest.approx(300.0)
    red = red_light_polygons(road, ctx, [{"L": LightState.RED}, {"L": LightState.GREEN}])
    assert len(red[0]) == 1
    assert red[0][0].equals(ctx.lane_polygon_by_id["conn"])
    assert red[1] == []


def test_parameters_the_simulation_cannot_run_with_are_refused() -> None:
    from redrive.errors import ConfigError
    from redrive.evaluation.closedloop import NavsimEpdms, NavsimPdms

    with pytest.raises(ConfigError, match=r"navsim_pdms.*num_poses must be >= 3"):
        NavsimPdms(num_poses=2)
    with pytest.raises(ConfigError, match=r"navsim_epdms.*scene_interval_s must be > 0"):
        NavsimEpdms(scene_interval_s=0.0)
