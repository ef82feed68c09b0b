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
