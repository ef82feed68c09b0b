"""redrive.sim.roadmap: the synthetic road network as the RoadMap a run stores."""

from __future__ import annotations

import numpy as np
import pytest

from redrive.errors import ConfigError
from redrive.sim.roadmap import (
    HIGHWAY_SPEED_LIMIT_MPS,
    URBAN_SPEED_LIMIT_MPS,
    road_map,
    scenario_road_map,
)
from redrive.sim.roads import HighwayLayout, UrbanLayout, build_network
from redrive.sim.scenario import load_scenario, parse_scenario


def test_urban_map_has_every_lane_the_intersection_and_50_kmh() -> None:
    network = build_network(UrbanLayout())
    m = road_map(network)
    assert [lane.lane_id for lane in m.lanes] == list(network.lanes)
    for lane in m.lanes:
        assert np.array_equal(lane.centerline, network.lanes[lane.lane_id].points)
        assert lane.width_m == network.lanes[lane.lane_id].width_m
        assert lane.speed_limit_mps == pytest.approx(50 / 3.6)
    (area,) = m.areas
    assert area.kind == "intersection"
    half = network.intersection_half_m
    assert half is not None
    assert np.abs(area.polygon).max() == half


def test_highway_default_and_override() -> None:
    network = build_network(HighwayLayout())
    assert {lane.speed_limit_mps for lane in road_map(network).lanes} == {HIGHWAY_SPEED_LIMIT_MPS}
    assert road_map(network).areas == ()
    assert {lane.speed_limit_mps for lane in road_map(network, speed_limit_mps=20.0).lanes} == {
        20.0
    }
    with pytest.raises(ConfigError, match="speed_limit_mps must be > 0"):
        road_map(network, speed_limit_mps=0.0)


def test_a_scenario_says_its_speed_limit() -> None:
    assert {lane.speed_limit_mps for lane in scenario_road_map(load_scenario("urban")).lanes} == {
        URBAN_SPEED_LIMIT_MPS
    }
    sc = parse_scenario(
        {
            "name": "slow",
            "road": {"layout": "highway", "speed_limit_mps": 22.2},
            "ego": {"route": "forward_0"},
        }
    )
    assert {lane.speed_limit_mps for lane in scenario_road_map(sc).lanes} == {22.2}


@pytest.mark.parametrize(
    "layout", [UrbanLayout(), UrbanLayout(lanes_per_direction=3), HighwayLayout()], ids=str
)
def test_lane_graph_follows_the_routes_and_segments(layout: UrbanLayout | HighwayLayout) -> None:
    network = build_network(layout)
    m = road_map(network)
    for route in network.routes.values():  # every route is a chain of successors
        for a, b in zip(route.lane_ids, route.lane_ids[1:], strict=False):
            assert b in m.lane(a).successors
            assert a in m.lane(b).predecessors
    for lane in m.lanes:
        for nxt in lane.successors:  # the graph is symmetric and its lanes join end to start
            assert lane.lane_id in m.lane(nxt).predecessors
            assert np.hypot(*(m.lane(nxt).centerline[0] - lane.centerline[-1])) < 1e-6
        for side, other in (("left", "right"), ("right", "left")):
            nb = getattr(lane, f"{side}_neighbor")
            if nb is not None:
                assert getattr(m.lane(nb), f"{other}_neighbor") == lane.lane_id
                assert lane.roadblock_id == m.lane(nb).roadblock_id
                # a neighbour is one lane width to that side
                d = m.lane(nb).centerline[0] - lane.centerline[0]
                assert np.hypot(*d) == pytest.approx(lane.width_m)
        assert lane.roadblock_id is not None
        assert lane.lane_id in m.roadblock(lane.roadblock_id).lane_ids
    assert sorted(i for b in m.roadblocks for i in b.lane_ids) == sorted(network.lanes)


def test_urban_map_has_intersection_stop_lines_and_lights() -> None:
    network = build_network(UrbanLayout(lanes_per_direction=2))
    m = road_map(network)
    (inter,) = m.intersections
    connectors = {i for i in network.lanes if "_in_" not in i and "_out_" not in i}
    assert set(inter.lane_ids) == connectors
    for lane in m.lanes:
        assert (lane.intersection_id == inter.intersection_id) == (lane.lane_id in connectors)
        if lane.lane_id in connectors:
            assert (lane.left_boundary_type, lane.right_boundary_type) == ("virtual", "virtual")
    assert m.lane("west_in_0").left_boundary_type == "solid"  # the centre line
    assert m.lane("west_in_0").right_boundary_type == "dashed"
    assert m.lane("west_in_1").right_boundary_type == "solid"  # the edge line
    assert len(m.traffic_lights) == len(network.signals) == 4
    for light, sig in zip(m.traffic_lights, network.signals, strict=True):
        assert light.light_id == str(sig.light_id)
        assert np.array_equal(light.position, sig.position[:2])
        assert light.lane_ids == (f"{sig.approach}_in_0", f"{sig.approach}_in_1")
        stop = next(s for s in m.stop_lines if s.stop_line_id == light.stop_line_id)
        assert stop.lane_ids == light.lane_ids
        # the stop line crosses its lanes where the lane's stop_line_s_m says
        for lane_id in stop.lane_ids:
            lane = network.lanes[lane_id]
            assert lane.stop_line_s_m is not None
            i = int(np.searchsorted(lane.s_m, lane.stop_line_s_m))
            p = lane.points[i]
            a, b = stop.line
            cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
            assert abs(cross) / np.hypot(*(b - a)) < 0.5  # within one sample (0.5 m)
    highway = road_map(build_network(HighwayLayout()))
    assert (highway.intersections, highway.stop_lines, highway.traffic_lights) == ((), (), ())
    assert highway.source == "synthetic:highway"
