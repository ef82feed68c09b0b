"""The scenery of a synthetic world: buildings or walls, poles and light posts, as STATIC boxes."""

from __future__ import annotations

import numpy as np

from redrive.sim.roads import RoadNetwork, RoadSegment
from redrive.sim.scenario import Scenario
from redrive.sim.scene import ObjectLooks
from redrive.types import ObjectClass, ObjectColumns

__all__ = ["SCENERY_ID0", "build_scenery"]

#: the first scenery box's object id (the agents' ids count up from 1)
SCENERY_ID0 = 100_000


def build_scenery(
    network: RoadNetwork, scenario: Scenario, rng: np.random.Generator
) -> tuple[ObjectColumns, ObjectLooks]:
    """Buildings (urban) or walls (highway), poles and light posts as STATIC boxes, drawn from
    ``rng`` (the world's generator, before its agents), and their looks."""
    boxes: list[tuple[float, float, float, float, float, float, float]] = []  # x y z l w h yaw
    looks: list[tuple[int, int, int, float]] = []
    urban = network.intersection_half_m is not None
    for seg in network.segments:
        for side in (-1.0, 1.0):
            edge = seg.right_edge_m if side < 0 else seg.left_edge_m
            if scenario.scenery and urban:
                s = 5.0
                while s < seg.length_m - 22.0:
                    length, depth = rng.uniform(10.0, 25.0), rng.uniform(8.0, 14.0)
                    length = min(length, seg.length_m - 22.0 - s)
                    height = rng.uniform(6.0, 20.0)
                    d = edge + side * (seg.sidewalk_width_m + 1.0 + depth / 2)
                    _box(boxes, seg, s + length / 2, d, (length, depth, height))
                    grey = int(rng.integers(90, 200))
                    looks.append((grey, grey - 10, grey - 25, float(rng.uniform(0.2, 0.5))))
                    s += length + rng.uniform(2.0, 8.0)
            elif scenario.scenery:
                for s in np.arange(5.0, seg.length_m - 5.0, 10.0):
                    d = edge + side * (seg.sidewalk_width_m + 0.5)
                    _box(boxes, seg, float(s), d, (10.0, 0.3, 3.5))
                    looks.append((150, 150, 140, 0.35))
            for s in np.arange(10.0, seg.length_m - 5.0, 30.0):
                _box(boxes, seg, float(s), edge + side * 0.5, (0.25, 0.25, 7.0))
                looks.append((110, 110, 110, 0.6))
    for sig in network.signals:
        boxes.append((sig.position[0], sig.position[1], 2.6, 0.3, 0.3, 5.2, 0.0))
        looks.append((60, 60, 60, 0.6))
    arr = np.array(boxes, dtype=np.float64).reshape(-1, 7)
    n = len(arr)
    objects = ObjectColumns.of(
        object_id=SCENERY_ID0 + np.arange(n, dtype=np.int64),
        object_class=(ObjectClass.STATIC,) * n,
        center_m=arr[:, 0:3],
        size_m=arr[:, 3:6],
        yaw_rad=arr[:, 6],
    )
    appearance = ObjectLooks(
        colors_rgb=np.array([lk[:3] for lk in looks], dtype=np.uint8).reshape(-1, 3),
        reflectivity=np.array([lk[3] for lk in looks], dtype=np.float32),
        is_ground_truth=np.zeros(n, dtype=bool),
    )
    return objects, appearance


def _box(
    boxes: list[tuple[float, float, float, float, float, float, float]],
    seg: RoadSegment,
    s_m: float,
    d_m: float,
    size: tuple[float, float, float],
) -> None:
    x, y, heading = seg.pose_at(s_m, d_m)
    boxes.append((float(x), float(y), size[2] / 2, size[0], size[1], size[2], float(heading)))
