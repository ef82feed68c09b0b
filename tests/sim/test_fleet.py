"""The world's lane followers as arrays (LaneFleet, compiled) move as ReferenceFollower objects do,
bit for bit: red and yellow lights, queues, cyclists beside the lane, scripted braking, lane
changes, leaving at the route's end."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from redrive.motion import IdmParams
from redrive.sim.agents import LaneChange, Obstacles
from redrive.sim.fleet import LaneFleet
from redrive.sim.gaps import GapSearch
from redrive.sim.lights import LightTiming, TrafficLights
from redrive.sim.roads import (
    HighwayLayout,
    RoadNetwork,
    UrbanLayout,
    highway_network,
    urban_network,
)
from redrive.types import ObjectClass
from tests.sim._reference_agents import ReferenceFollower
from tests.sim._reference_step import start_plan

#: an obstacle far from every road, in the place of the world's ego (the snapshot's first row)
FAR = (1e6, 1e6, 4.7, 1.9, 0.0, 0.0)


def _agent(
    agent_id: int, route: object, s_m: float, speed: float, **kw: object
) -> ReferenceFollower:
    cyclist = kw.pop("cyclist", False)
    return ReferenceFollower(
        agent_id,
        ObjectClass.BICYCLE if cyclist else ObjectClass.VEHICLE,
        route=route,  # type: ignore[arg-type]
        s_m=s_m,
        speed_mps=speed,
        idm=IdmParams(desired_speed_mps=speed + 2.0, max_accel_mps2=1.0 if cyclist else 1.5),
        size_lwh_m=(1.8, 0.6, 1.7) if cyclist else (4.5, 1.85, 1.5),
        color_rgb=(1, 2, 3),
        lateral_offset_m=-0.9 if cyclist else 0.0,
        **kw,  # type: ignore[arg-type]
    )


def _urban(net: RoadNetwork) -> list[ReferenceFollower]:
    r = net.routes
    return [
        _agent(1, r["west_east_0"], 75.0, 12.0),  # meets the yellow light
        _agent(2, r["west_east_0"], 50.0, 13.0),
        _agent(3, r["west_north_0"], 70.0, 14.0),
        _agent(4, r["west_east_0"], 60.0, 5.0, cyclist=True),
        _agent(5, r["south_north_0"], 125.0, 11.0),  # stops at the red light (stop line 148.5 m)
        _agent(9, r["south_north_0"], 110.0, 11.0),  # queues behind it
        _agent(6, r["east_west_0"], 290.0, 14.0),  # leaves at the route's end
        _agent(7, r["north_south_0"], 40.0, 13.0, brake_time_s=3.0, brake_decel_mps2=5.0),
        _agent(8, r["north_south_0"], 20.0, 13.0),
    ]


def _highway(net: RoadNetwork) -> list[ReferenceFollower]:
    r = net.routes
    return [
        _agent(1, r["forward_1"], 80.0, 25.0, brake_time_s=4.0, brake_decel_mps2=6.0),
        _agent(2, r["forward_1"], 40.0, 27.0),
        _agent(
            3,
            r["forward_0"],
            50.0,
            26.0,
            lane_change=LaneChange(target=r["forward_1"], start_time_s=1.5, duration_s=3.0),
        ),
        _agent(
            4,
            r["forward_2"],
            30.0,
            24.0,
            lane_change=LaneChange(target=r["forward_1"], start_time_s=2.0, duration_s=2.5),
        ),
        _agent(5, r["backward_0"], 100.0, 25.0),
    ]


def _reference_step(
    followers: list[ReferenceFollower], t: float, dt: float, lights: TrafficLights
) -> Obstacles:
    """What the world did with ReferenceFollower objects: one snapshot, every plan, every advance."""
    poses = [f.pose() for f in followers]
    vels = [f.velocity() for f in followers]
    obstacles = Obstacles(
        ids=np.array([0, *(f.agent_id for f in followers)], dtype=np.int64),
        centers=np.array([FAR[:2], *(p[:2] for p in poses)]),
        lengths=np.array([FAR[2], *(f.size_lwh_m[0] for f in followers)]),
        widths=np.array([FAR[3], *(f.size_lwh_m[1] for f in followers)]),
        velocities=np.array([FAR[4:], *vels]),
    )
    for f in followers:
        f.plan(t, obstacles, lights)
    for f in followers:
        f.advance(dt)
    followers[:] = [f for f in followers if f.active]
    return obstacles


@pytest.mark.parametrize(
    ("network", "build", "timing"),
    [
        (urban_network(UrbanLayout()), _urban, LightTiming(green_s=4.0, yellow_s=2.0)),
        (highway_network(HighwayLayout()), _highway, LightTiming()),
    ],
    ids=["urban", "highway"],
)
def test_fleet_moves_as_lane_followers_do(
    network: RoadNetwork,
    build: Callable[[RoadNetwork], list[ReferenceFollower]],
    timing: LightTiming,
) -> None:
    lights = TrafficLights(network.signals, timing)
    search = GapSearch(network.routes.values())
    reference = build(network)
    fleet = LaneFleet(build(network), search, lights)
    dt = 0.05
    stopped, changed = set(), set()
    for k in range(200):
        t = k * dt
        ids, obst = fleet.snapshot(np.array([0], dtype=np.int64), np.array([FAR]))
        want = _reference_step(reference, t, dt, lights)
        # the snapshot: exactly the objects' poses and velocities
        assert ids.tolist() == want.ids.tolist()
        assert obst[0:2].T.tolist() == want.centers.tolist()
        assert obst[2].tolist() == want.lengths.tolist()
        assert obst[4:6].T.tolist() == want.velocities.tolist()
        start_plan(fleet, t)
        q_int, q_float = fleet.queries(search.horizon_m, None)
        gaps, speeds = search.gaps_of(q_int, q_float, ids, obst)
        fleet.finish_and_advance(t, dt, gap_m=gaps, leader_speed_mps=speeds)
        stopped |= {f.agent_id for f in reference if f.speed_mps < 0.5}
        changed |= {
            f.agent_id for f in reference if f.lane_change and f.route is f.lane_change.target
        }
    # after 10 s: the same agents left, at the same poses, bit for bit
    assert fleet.ids.tolist() == [f.agent_id for f in reference]
    poses = fleet.poses()
    assert poses[0:3].T.tolist() == [list(f.pose()) for f in reference]
    assert poses[3:5].T.tolist() == [list(f.velocity()) for f in reference]
    # what the case covers: a queue at a red light and a follower leaving its route (urban),
    # lane changes and braking to a stop (highway)
    if network.signals:
        assert {5, 7, 9} <= stopped
        assert 6 not in fleet.ids.tolist()
    else:
        assert changed == {3, 4}
        assert 1 in stopped
