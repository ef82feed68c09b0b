"""The mission of a closed loop on a recorded log: the logged ego path mapped onto the log's
lane graph (the route the planner follows) and the logged ego trajectory (for the expert).

nuPlan's simulation hands the planner the route of the scenario (its roadblock ids, from the
expert's driven path) before the first step; here the route is the lanes of the logged ego's
poses, chained along the lane graph (:func:`redrive.maps.route.route_along_path`) — or, for a log
that sets the ego a goal instead of a path (a CommonRoad planning problem), the lanes from its
start to the goal (:func:`redrive.maps.route.route_to_goal`).  Every
algorithm gets the :class:`~redrive.types.Mission` through ``Algorithm.use_mission``.
"""

from __future__ import annotations

import numpy as np

from redrive.assembly.frames import FrameAssembler
from redrive.maps.index import RoadMapIndex
from redrive.maps.route import route_along_path, route_to_goal
from redrive.types import Mission

__all__ = ["HORIZON_AFTER_S", "logged_mission"]

#: how much log after the run's end the logged trajectory keeps (a planner's look-ahead)
HORIZON_AFTER_S = 8.0


def logged_mission(
    assembler: FrameAssembler,
    *,
    index: RoadMapIndex | None,
    start_ns: int,
    duration_s: float | None,
    goal_lane_ids: tuple[str, ...] = (),
) -> Mission | None:
    """The mission of a run from ``start_ns`` (log time) for ``duration_s`` (None: to the log's
    end): the logged ego's states up to :data:`HORIZON_AFTER_S` after the run, and — with a road
    map (``index``) — their route, or the route from the start to the log's goal
    (``goal_lane_ids``, :func:`redrive.io.content.log_goal_lanes`) when it sets one; None when
    the log has no ego state there."""
    stop_ns = None
    if duration_s is not None:
        stop_ns = start_ns + round((duration_s + HORIZON_AFTER_S) * 1e9)
    stamps: list[int] = []
    xy: list[tuple[float, float]] = []
    yaw: list[float] = []
    speed: list[float] = []
    frame_id = "map"
    for state in assembler.ego_states(stop_ns=stop_ns):
        if stamps and state.stamp_ns <= stamps[-1]:
            continue  # a repeated or out-of-order stamp: the first one counts
        stamps.append(state.stamp_ns)
        xy.append((float(state.position[0]), float(state.position[1])))
        yaw.append(state.heading_rad)
        speed.append(state.speed_mps)
        frame_id = state.frame_id
    if not stamps:
        return None
    points = np.array(xy, dtype=np.float64)
    headings = np.array(yaw, dtype=np.float64)
    lanes: tuple[str, ...] = ()
    line = np.zeros((0, 2))
    source = "no road map: no route"
    if index is not None and frame_id != index.road_map.frame_id:
        source = (
            f"the logged ego is in frame {frame_id!r}, the road map in "
            f"{index.road_map.frame_id!r}: no route"
        )
    elif index is not None and goal_lane_ids:
        first = int(np.searchsorted(np.array(stamps, dtype=np.int64), start_ns))
        first = min(first, len(stamps) - 1)
        lanes, line = route_to_goal(index, points[first], float(headings[first]), goal_lane_ids)
        goal = ", ".join(goal_lane_ids)
        source = (
            f"the log's goal (lanes {goal}) reached along the lane graph from the ego's start "
            "(redrive.maps.route.route_to_goal)"
            if lanes
            else f"the log's goal (lanes {goal}) cannot be reached from the ego's start: no route"
        )
    elif index is not None:
        run = np.array(stamps, dtype=np.int64) >= start_ns
        if duration_s is not None:
            run &= np.array(stamps, dtype=np.int64) <= start_ns + round(duration_s * 1e9)
        lanes, line = route_along_path(index, points[run], headings[run])
        source = (
            "the logged ego path mapped onto the lane graph (redrive.maps.route.route_along_path)"
            if lanes
            else "the logged ego path is on no lane of the map: no route"
        )
    return Mission(
        route_lane_ids=lanes,
        route_xy=line,
        logged_stamps_ns=np.array(stamps, dtype=np.int64),
        logged_xy=points,
        logged_yaw_rad=headings,
        logged_speed_mps=np.array(speed, dtype=np.float64),
        frame_id=frame_id,
        source=source,
    )
