"""IDM car following, red lights, pedestrians, lane changes."""

from __future__ import annotations

import numpy as np
import pytest

from redrive.motion import IdmParams, idm_acceleration
from redrive.sim.agents import LaneChange, Obstacles, Walker
from redrive.sim.lights import LightTiming, TrafficLights
from redrive.sim.roads import HighwayLayout, UrbanLayout, highway_network, urban_network
from redrive.types import LightState, ObjectClass
from tests.sim._reference_agents import ReferenceFollower

CAR = (4.5, 1.8, 1.5)


def _obstacles(*agents: ReferenceFollower) -> Obstacles:
    poses = [a.pose() for a in agents]
    return Obstacles(
        ids=np.array([a.agent_id for a in agents], dtype=np.int64),
        centers=np.array([p[:2] for p in poses]),
        lengths=np.array([a.size_lwh_m[0] for a in agents]),
        widths=np.array([a.size_lwh_m[1] for a in agents]),
        velocities=np.array([a.velocity() for a in agents]),
    )


def _car(agent_id: int, route: object, s_m: float, speed: float, **kw: object) -> ReferenceFollower:
    return ReferenceFollower(
        agent_id, ObjectClass.VEHICLE, route=route, s_m=s_m, speed_mps=speed,  # type: ignore[arg-type]
        idm=IdmParams(desired_speed_mps=speed), size_lwh_m=CAR, color_rgb=(1, 2, 3), **kw,  # type: ignore[arg-type]
    )  # fmt: skip


def test_idm_free_road_and_equilibrium() -> None:
    p = IdmParams(desired_speed_mps=20.0)
    assert idm_acceleration(p, 0.0) == pytest.approx(p.max_accel_mps2)
    assert idm_acceleration(p, 20.0) == pytest.approx(0.0, abs=1e-12)
    assert idm_acceleration(p, 10.0, gap_m=1.0, leader_speed_mps=0.0) == -p.max_decel_mps2


def test_follower_behind_hard_braking_lead_never_collides() -> None:
    route = highway_network(HighwayLayout()).routes["forward_1"]
    lights = TrafficLights((), LightTiming())
    lead = _car(1, route, 60.0, 20.0, brake_time_s=2.0, brake_decel_mps2=6.0)
    follower = _car(2, route, 20.0, 20.0)
    dt, min_gap = 0.01, np.inf
    for k in range(1500):
        obs = _obstacles(lead, follower)
        lead.plan(k * dt, obs, lights)
        follower.plan(k * dt, obs, lights)
        lead.advance(dt)
        follower.advance(dt)
        min_gap = min(min_gap, lead.s_m - follower.s_m - CAR[0])
    assert lead.speed_mps == 0.0
    assert follower.speed_mps < 0.05
    assert min_gap >= 1.0  # s0 = 2 m; never closer than ~s0
    assert min_gap < 10.0  # and it did close up


def test_vehicle_stops_before_red_stop_line() -> None:
    net = urban_network(UrbanLayout())
    route = net.routes["west_east_0"]
    lights = TrafficLights(net.signals, LightTiming(green_s=8.0, yellow_s=1.0, offset_s=9.0))
    assert lights.state(0, 0.0) is LightState.RED
    assert lights.state(0, 10.9) is LightState.RED
    assert lights.state(0, 11.1) is LightState.GREEN
    car = _car(1, route, 60.0, 12.0)
    stop_s = route.stop_lines[0].s_m
    for k in range(2000):  # 20 s; red until 11 s
        t = k * 0.01
        car.plan(t, _obstacles(car), lights)
        car.advance(0.01)
        if t < 11.0:
            assert car.s_m + CAR[0] / 2 <= stop_s
    assert car.s_m > stop_s  # and drives on at green


def test_yellow_too_close_goes_through() -> None:
    net = urban_network(UrbanLayout())
    route = net.routes["west_east_0"]
    lights = TrafficLights(net.signals, LightTiming(green_s=1.0, yellow_s=3.0, offset_s=0.0))
    stop_s = route.stop_lines[0].s_m
    car = _car(1, route, stop_s - 12.0, 12.0)  # yellow at 1 s, 0 m left — cannot stop
    for k in range(300):
        car.plan(1.0 + k * 0.01, _obstacles(car), lights)
        car.advance(0.01)
    assert car.s_m > stop_s + 10.0


def test_pedestrian_crosses() -> None:
    walker = Walker(5, start_xy=(0.0, -6.0), end_xy=(0.0, 6.0), speed_mps=1.5, start_time_s=2.0)
    walker.set_time(1.0)
    assert walker.pose()[:2] == (0.0, -6.0)
    assert walker.velocity() == (0.0, 0.0)
    walker.set_time(6.0)
    assert walker.pose()[1] == pytest.approx(0.0)
    assert walker.velocity()[1] == pytest.approx(1.5)
    walker.set_time(20.0)
    assert walker.pose()[1] == pytest.approx(6.0)


def test_lane_change_reaches_target_lane_smoothly() -> None:
    net = highway_network(HighwayLayout())
    lights = TrafficLights((), LightTiming())
    car = _car(1, net.routes["forward_2"], 30.0, 20.0, lane_change=LaneChange(target=net.routes["forward_1"], start_time_s=1.0, duration_s=3.0))  # fmt: skip
    ys = []
    for k in range(600):
        car.plan(k * 0.01, _obstacles(car), lights)
        car.advance(0.01)
        ys.append(car.pose()[1])
    assert ys[50] == pytest.approx(-2.5 * 3.75)
    assert ys[-1] == pytest.approx(-1.5 * 3.75, abs=1e-6)
    assert np.max(np.abs(np.diff(ys))) < 0.03  # no jump
