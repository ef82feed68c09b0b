"""A road map re-expressed in another frame: every point turned by a yaw and shifted.

:func:`moved_map` is how a map read in its own frame (a Lanelet2 map's projection, an Argoverse 2
city frame) is placed in a log's frame when the log's tf says where the map frame lies
(``odom ← map``): the points only move; the ids, graph and attributes stay.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from redrive.types import RoadMap

__all__ = ["moved_map"]

F64 = npt.NDArray[np.float64]


def moved_map(
    road_map: RoadMap, *, yaw_rad: float, translation_xy: tuple[float, float], frame_id: str
) -> RoadMap:
    """``road_map`` with every point p replaced by R(yaw) p + t, in frame ``frame_id``.

    The planar part of a ``frame_id ← map`` transform: roll and pitch (a map is planar here)
    and the height are left out."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    rot = np.array([[c, -s], [s, c]], dtype=np.float64)
    shift = np.asarray(translation_xy, dtype=np.float64)

    def move(points: F64) -> F64:
        return np.asarray(points, dtype=np.float64) @ rot.T + shift

    def maybe(points: F64 | None) -> F64 | None:
        return None if points is None else move(points)

    lanes = tuple(
        replace(
            lane,
            centerline=move(lane.centerline),
            left_boundary=maybe(lane.left_boundary),
            right_boundary=maybe(lane.right_boundary),
        )
        for lane in road_map.lanes
    )
    return replace(
        road_map,
        lanes=lanes,
        areas=tuple(replace(a, polygon=move(a.polygon)) for a in road_map.areas),
        intersections=tuple(replace(i, polygon=move(i.polygon)) for i in road_map.intersections),
        crosswalks=tuple(replace(c, polygon=move(c.polygon)) for c in road_map.crosswalks),
        stop_lines=tuple(replace(s, line=move(s.line)) for s in road_map.stop_lines),
        traffic_lights=tuple(
            replace(t, position=move(np.asarray(t.position)[None, :])[0])
            for t in road_map.traffic_lights
        ),
        frame_id=frame_id,
    )
