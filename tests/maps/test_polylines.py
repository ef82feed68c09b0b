"""redrive.maps.polylines: the compiled distances and projections are shapely's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from redrive.maps.polylines import packed, polyline_distances, polyline_locate
from redrive.sim.roadmap import road_map
from redrive.sim.roads import UrbanLayout, build_network


def _lines() -> list[np.ndarray]:
    """Curved and straight centrelines of a synthetic town, a zig-zag with repeated vertices
    and a polyline whose two vertices are one point."""
    lanes = road_map(build_network(UrbanLayout(lanes_per_direction=2))).lanes
    odd = [
        np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 1.0], [1.0, 1.0], [2.0, 0.0], [3.0, 1e-9]]),
        np.array([[5.0, 5.0], [5.0, 5.0]]),
    ]
    return [lane.centerline for lane in lanes] + odd


def _pairs(lines: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Every vertex (exactly on its line), vertices moved by 0.5 m and 20 m noise, each against
    its own line or a random one."""
    rng = np.random.default_rng(3)
    vertices = np.concatenate(lines)
    own = np.repeat(np.arange(len(lines)), [len(line) for line in lines])
    points = np.concatenate([vertices, vertices + rng.normal(0, 0.5, vertices.shape)] * 2)
    points = np.concatenate([points, vertices + rng.normal(0, 20.0, vertices.shape)])
    which = np.concatenate([own, own, rng.integers(0, len(lines), 2 * len(vertices)), own[::-1]])
    return points, which


def test_locate_and_distance_equal_shapely() -> None:
    lines = _lines()
    points, which = _pairs(lines)
    geoms = [shapely.LineString(line) for line in lines]
    chosen = [geoms[k] for k in which]
    pts = shapely.points(points)
    s, d = polyline_locate(points, which, *packed(lines))
    assert np.array_equal(s, shapely.line_locate_point(chosen, pts))
    assert np.array_equal(d, shapely.distance(chosen, pts))
    assert np.array_equal(polyline_distances(points, which, *packed(lines)), d)


def test_one_vertex_polyline_is_a_point() -> None:
    coords, offsets = packed([np.array([[1.0, 2.0]]), np.array([[0.0, 0.0], [4.0, 0.0]])])
    d = polyline_distances([[4.0, 6.0], [2.0, 3.0]], [0, 1], coords, offsets)
    assert np.array_equal(d, [5.0, 3.0])


def test_no_points_and_mismatched_arguments() -> None:
    coords, offsets = packed([np.array([[0.0, 0.0], [1.0, 0.0]])])
    s, d = polyline_locate(np.zeros((0, 2)), [], coords, offsets)
    assert s.shape == d.shape == (0,)
    with pytest.raises(ValueError, match="2 points but 1"):
        polyline_distances([[0.0, 0.0], [1.0, 1.0]], [0], coords, offsets)


def test_runs_along_one_polyline_keep_the_first_nearest_segment() -> None:
    """Points in a run on one polyline start from the previous point's segment; a tie with an
    earlier segment still goes to the earlier one (GEOS's order), in either direction."""
    u_turn = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 2.0], [0.0, 2.0]])
    rng = np.random.default_rng(5)
    walk = np.column_stack([np.linspace(0.0, 10.0, 41), rng.uniform(-0.5, 2.5, 41)])
    ties = np.array([[5.0, 1.5], [5.0, 1.0], [2.0, 1.0], [5.0, 0.5], [5.0, 1.0]])
    points = np.concatenate([walk, walk[::-1], ties, ties[::-1]])
    coords, offsets = packed([u_turn, u_turn[::-1]])
    line = shapely.LineString(u_turn)
    pts = shapely.points(points)
    for which, geom in ((0, line), (1, shapely.LineString(u_turn[::-1]))):
        of = np.full(points.shape[0], which)
        s, d = polyline_locate(points, of, coords, offsets)
        assert np.array_equal(s, shapely.line_locate_point(geom, pts))
        assert np.array_equal(d, shapely.distance(geom, pts))
        assert np.array_equal(polyline_distances(points, of, coords, offsets), d)
    assert polyline_locate([[5.0, 1.5], [5.0, 1.0]], [0, 0], coords, offsets)[0][1] == 5.0
