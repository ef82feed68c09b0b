"""Road network geometry and the ground raster."""

from __future__ import annotations

import math

import numpy as np
import pytest

from redrive.sim.ground import rasterize
from redrive.sim.roads import (
    HighwayLayout,
    RoadSegment,
    UrbanLayout,
    highway_network,
    urban_network,
)
from redrive.sim.scene import GroundLabel


def test_arc_segment_inverse_and_lane_length() -> None:
    seg = RoadSegment(
        name="arc", start_xy=(3.0, -2.0), start_heading_rad=0.3, length_m=120.0,
        curvature_1pm=-1 / 80.0, lanes_forward=2, lanes_backward=1,
    )  # fmt: skip
    s = np.array([0.0, 10.0, 60.0, 119.0])
    d = np.array([-3.0, 1.0, 0.0, -6.5])
    x, y, heading = seg.pose_at(s, d)
    s2, d2 = seg.local_coords(x, y)
    np.testing.assert_allclose(s2, s, atol=1e-9)
    np.testing.assert_allclose(d2, d, atol=1e-9)
    np.testing.assert_allclose(heading, 0.3 - s / 80.0)


def test_urban_routes_connect_and_turn() -> None:
    net = urban_network(UrbanLayout(lanes_per_direction=2))
    straight = net.routes["west_east_1"]
    pts = straight.points
    assert np.all(np.hypot(*np.diff(pts, axis=0).T) < 0.51)
    np.testing.assert_allclose(pts[:, 1], -1.5 * 3.5)  # lane 1 is 1.5 lane widths right
    assert len(straight.stop_lines) == 1
    x, _, _ = straight.pose_at(straight.stop_lines[0].s_m)
    assert x < -net.intersection_half_m  # type: ignore[operator]
    left = net.routes["west_north_0"]
    assert left.heading_rad[-1] == pytest.approx(math.pi / 2)
    right = net.routes["west_south_1"]
    assert right.heading_rad[-1] == pytest.approx(-math.pi / 2)
    # consecutive lanes join without a jump; arclength matches the chord sum on the arc
    for route in (left, right):
        steps = np.hypot(*np.diff(route.points, axis=0).T)
        assert steps.max() < 0.51
        assert route.length_m == pytest.approx(steps.sum(), rel=1e-4)


def test_route_projection_and_pose() -> None:
    route = highway_network(HighwayLayout()).routes["forward_0"]
    for s_true, d_true in ((50.0, 0.7), (260.0, -1.2), (400.0, 0.0)):
        x, y, _ = route.pose_at(s_true, d_true)
        s, d = route.project([[x, y]], s_min_m=0.0, s_max_m=route.length_m)
        assert s[0] == pytest.approx(s_true, abs=1e-3)
        assert d[0] == pytest.approx(d_true, abs=1e-3)


def test_route_near_keeps_every_point_within_the_radius() -> None:
    """Route.near is a cheap superset: whatever project() finds within the radius of the piece
    passes, points far off are dropped (urban turns and highway curve, random points)."""
    rng = np.random.default_rng(3)
    routes = [
        urban_network(UrbanLayout()).routes["west_north_0"],
        highway_network(HighwayLayout()).routes["forward_0"],
    ]
    for route in routes:
        for s_min in (0.0, 40.0, route.length_m / 2):
            s_max = s_min + 80.0
            x0, y0, _ = route.pose_at(s_min + 40.0)
            on_route = [route.pose_at(s_min + k * 8.0, 0.4)[:2] for k in range(10)]
            pts = np.concatenate(
                [np.array(on_route), np.array([x0, y0]) + rng.uniform(-90.0, 90.0, size=(390, 2))]
            )
            radius = rng.uniform(0.5, 3.0, size=400)
            _, lat = route.project(pts, s_min_m=s_min, s_max_m=s_max)
            near = route.near(pts, s_min_m=s_min, s_max_m=s_max, radius_m=radius)
            assert np.all(near[np.abs(lat) < radius])
            assert np.all(near[:10])
            assert not np.all(near)


def test_raster_labels() -> None:
    net = urban_network(UrbanLayout())
    ground = rasterize(net)
    assert ground.resolution_m == pytest.approx(0.1)
    probes = {
        GroundLabel.ROAD: (-50.0, -1.75),
        GroundLabel.LANE_MARKING: (-50.0, -3.5),  # solid edge line
        GroundLabel.SIDEWALK: (-50.0, -7.5),
        GroundLabel.STOP_LINE: (-9.25, -1.75),
        GroundLabel.GRASS: (-50.0, -30.0),
    }
    for label, xy in probes.items():
        assert ground.label_at(xy) == label, label
    assert ground.label_at((0.0, 0.0)) == GroundLabel.ROAD  # intersection square
    # dashed lines between same-direction lanes of the highway: some on, some off
    hw = rasterize(highway_network(HighwayLayout(lanes_per_direction=3)))
    xs = np.arange(10.0, 100.0, 0.5)
    labels = hw.label_at(np.stack([xs, np.full_like(xs, -3.75)], axis=1))
    assert 0.2 < np.mean(labels == GroundLabel.LANE_MARKING) < 0.5
    assert set(np.unique(labels).tolist()) == {GroundLabel.ROAD, GroundLabel.LANE_MARKING}


def test_project_point_equals_project_bit_for_bit() -> None:
    """Route.project_point (compiled, the ego's tracking every physics step) answers what
    Route.project does, exactly: random points near and far, short and whole-route pieces,
    points on sample positions (ties between segments) and beyond the ends."""
    rng = np.random.default_rng(11)
    routes = [
        *urban_network(UrbanLayout()).routes.values(),
        highway_network(HighwayLayout()).routes["forward_0"],
    ]
    for route in routes:
        samples = route.points[rng.integers(len(route.points), size=5)]
        for k in range(16):
            s_min = float(rng.uniform(-5.0, route.length_m))
            s_max = s_min + (12.0 if k % 2 else float(rng.uniform(0.0, route.length_m)))
            x0, y0, _ = route.pose_at(s_min + 4.0)
            for x, y in (
                (x0 + rng.normal(0.0, 3.0), y0 + rng.normal(0.0, 3.0)),
                (x0 + rng.uniform(-200.0, 200.0), y0 + rng.uniform(-200.0, 200.0)),
                tuple(samples[k % len(samples)]),
            ):
                s, lat = route.project([[x, y]], s_min_m=s_min, s_max_m=s_max)
                got = route.project_point(float(x), float(y), s_min_m=s_min, s_max_m=s_max)
                assert got == (float(s[0]), float(lat[0]))
    # a lost ego (nan position) stays lost, as with project
    s, lat = routes[0].project([[math.nan, 0.0]], s_min_m=10.0, s_max_m=22.0)
    got = routes[0].project_point(math.nan, 0.0, s_min_m=10.0, s_max_m=22.0)
    assert np.isnan([s[0], lat[0], *got]).all()
