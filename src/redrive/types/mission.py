"""What a closed-loop ego is asked to do on a recorded log: its route along the lane graph and
the logged (expert) ego trajectory.

nuPlan hands a planner its mission before the first step (``PlannerInitialization``: the
route's roadblock ids, the mission goal and the map); its ``LogFuturePlanner`` drives the
scenario's logged ego future.  A :class:`Mission` is both, handed to every algorithm once before
the first frame (``Algorithm.use_mission``) when the run has one: a closed loop on a recorded log
with a road map maps the log's own ego path onto the lane graph
(:func:`redrive.maps.route.route_along_path`).  Coordinates are metres in the frame of the ego
state (``Frame.vehicle_state.frame_id``, the map frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.types._arrays import frozen_array

__all__ = ["Mission"]

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True, kw_only=True)
class Mission:
    """A route along the lanes and the logged ego trajectory (see the module docstring).

    Attributes:
        route_lane_ids: the lanes of the route, in driving order (ids of the run's road map);
            () when the log's path is on no lane.
        route_xy: (N, 2) the route's reference line (its lanes' centrelines joined, a lane change
            as a straight blend between the two), metres; (0, 2) without a route.
        logged_stamps_ns: (M,) the logged ego's stamps (int64 ns, log time, increasing).
        logged_xy: (M, 2) its rear-axle positions, metres.
        logged_yaw_rad: (M,) its headings.
        logged_speed_mps: (M,) its speeds.
        source: how the route was made (for the manifest).
    """

    route_lane_ids: tuple[str, ...]
    route_xy: F64
    logged_stamps_ns: npt.NDArray[np.int64]
    logged_xy: F64
    logged_yaw_rad: F64
    logged_speed_mps: F64
    frame_id: str = "map"
    source: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "route_lane_ids", tuple(self.route_lane_ids))
        route = frozen_array(self.route_xy, name="route_xy", dtype=np.float64, shape=(None, 2))
        object.__setattr__(self, "route_xy", route)
        stamps = frozen_array(
            self.logged_stamps_ns, name="logged_stamps_ns", dtype=np.int64, shape=(None,)
        )
        m = stamps.shape[0]
        xy = frozen_array(self.logged_xy, name="logged_xy", dtype=np.float64, shape=(m, 2))
        yaw = frozen_array(self.logged_yaw_rad, name="logged_yaw_rad", dtype=np.float64, shape=(m,))
        speed = frozen_array(
            self.logged_speed_mps, name="logged_speed_mps", dtype=np.float64, shape=(m,)
        )
        if m > 1 and not bool(np.all(np.diff(stamps) > 0)):
            msg = "Mission: logged_stamps_ns must increase"
            raise ValueError(msg)
        for key, value in (
            ("logged_stamps_ns", stamps),
            ("logged_xy", xy),
            ("logged_yaw_rad", yaw),
            ("logged_speed_mps", speed),
        ):
            object.__setattr__(self, key, value)

    @property
    def has_route(self) -> bool:
        return bool(self.route_xy.shape[0] >= 2)
