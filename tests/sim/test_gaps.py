"""The batched gap search equals gap_ahead bit for bit, query by query."""

from __future__ import annotations

import math

import numpy as np
import pytest

from redrive.sim.agents import Obstacles
from redrive.sim.gaps import GapQuery, GapSearch
from redrive.sim.roads import HighwayLayout, Route, UrbanLayout, highway_network, urban_network
from redrive.sim.scenario import load_scenario
from redrive.sim.world import World
from tests.sim._reference_agents import gap_ahead


def _obstacles_on(routes: list[Route], rng: np.random.Generator, n: int) -> Obstacles:
    """``n`` obstacles near random points of the routes (some in the lane, some beside it)."""
    centers, ids = [], []
    for k in range(n):
        route = routes[int(rng.integers(len(routes)))]
        x, y, _ = route.pose_at(
            float(rng.uniform(-5.0, route.length_m + 5.0)), float(rng.normal(0.0, 2.0))
        )
        centers.append((x, y))
        ids.append(k + 1)
    return Obstacles(
        ids=np.array(ids, dtype=np.int64),
        centers=np.array(centers),
        lengths=rng.uniform(0.5, 8.0, n),
        widths=rng.uniform(0.5, 2.5, n),
        velocities=rng.normal(0.0, 8.0, (n, 2)),
    )


@pytest.mark.parametrize("layout", ["urban", "highway"])
def test_batch_equals_gap_ahead_per_query(layout: str) -> None:
    net = urban_network(UrbanLayout()) if layout == "urban" else highway_network(HighwayLayout())
    routes = list(net.routes.values())
    search = GapSearch(routes)
    rng = np.random.default_rng(7)
    found = 0
    for _ in range(60):
        obstacles = _obstacles_on(routes, rng, int(rng.integers(1, 25)))
        queries = []
        for _ in range(int(rng.integers(1, 12))):
            route = routes[int(rng.integers(len(routes)))]
            s = float(rng.uniform(-10.0, route.length_m + 10.0))
            queries.append(
                GapQuery(
                    route=route,
                    s_center_m=s,
                    s_front_m=s + float(rng.uniform(0.2, 4.0)),
                    width_m=float(rng.uniform(0.5, 2.5)),
                    # sometimes one of the obstacles: its own box is never its leader
                    self_id=int(rng.integers(0, len(obstacles.ids) + 1)),
                )
            )
        batch = search.gaps(queries, obstacles)
        for q, got in zip(queries, batch, strict=True):
            want = gap_ahead(
                q.route,
                obstacles,
                s_center_m=q.s_center_m,
                s_front_m=q.s_front_m,
                width_m=q.width_m,
                self_id=q.self_id,
            )
            assert got == want  # exactly: the same floats, not approximately
            found += math.isfinite(want[0])
    assert found > 50  # the cases cover leaders found, not only free roads


def test_block_skipping_keeps_the_first_closest_segment() -> None:
    """Obstacles on the route's samples (two segments at distance 0: the first one wins) and on
    block boundaries, on a curved route: the projection that skips far blocks of segments
    (``GapSearch.blocks``) picks what gap_ahead's over every segment picks."""
    net = urban_network(UrbanLayout())
    routes = [r for r in net.routes.values() if abs(r.heading_rad[-1] - r.heading_rad[0]) > 0.5]
    assert routes  # a turning route: blocks' boxes overlap, distances tie
    route = routes[0]
    search = GapSearch([route])
    picks = range(1, len(route.s_m) - 1, 3)
    centers = np.array([route.points[i] for i in picks])
    n = len(centers)
    obstacles = Obstacles(
        ids=np.arange(1, n + 1, dtype=np.int64),
        centers=centers,
        lengths=np.full(n, 0.5),
        widths=np.full(n, 0.5),
        velocities=np.ones((n, 2)),
    )
    queries = [
        GapQuery(route=route, s_center_m=s, s_front_m=s + 2.0, width_m=1.8, self_id=0)
        for s in np.arange(0.0, route.length_m, 3.7).tolist()
    ]
    found = 0
    for q, got in zip(queries, search.gaps(queries, obstacles), strict=True):
        want = gap_ahead(
            route, obstacles, s_center_m=q.s_center_m, s_front_m=q.s_front_m, width_m=1.8, self_id=0
        )
        assert got == want
        found += math.isfinite(want[0])
    assert found > 10


def test_no_obstacles_or_no_queries() -> None:
    route = urban_network(UrbanLayout()).routes["west_east_0"]
    search = GapSearch([route])
    empty = Obstacles(
        ids=np.zeros(0, dtype=np.int64),
        centers=np.zeros((0, 2)),
        lengths=np.zeros(0),
        widths=np.zeros(0),
        velocities=np.zeros((0, 2)),
    )
    query = GapQuery(route=route, s_center_m=10.0, s_front_m=12.0, width_m=1.8, self_id=0)
    assert search.gaps([query], empty) == [(math.inf, 0.0)]
    assert search.gaps([], empty) == []


def test_world_with_dropped_agents_moves_its_driven_ego_alike() -> None:
    """A closed loop with replayed agents drops the driven world's own: they never changed how
    its ego moves, and its objects are the scenery only."""
    sc = load_scenario("urban")
    full, bare = World(sc), World(sc)
    bare.drop_agents()

    def drive(model: object, dt_s: float) -> None:
        model.step(dt_s, accel_mps2=0.4, steer_rad=0.01)  # type: ignore[attr-defined]

    full.drive_ego(drive)
    bare.drive_ego(drive)
    full.step(3.0)
    bare.step(3.0)
    assert np.array_equal(full.map_from_base(), bare.map_from_base())
    assert full.ego_state().velocity.tolist() == bare.ego_state().velocity.tolist()
    objects, looks = bare.objects()
    assert not looks.is_ground_truth.any()
    full_objects, full_looks = full.objects()
    assert len(objects.object_id) == len(full_objects.object_id) - int(
        full_looks.is_ground_truth.sum()
    )
