"""A road map: lanes with a direction of travel and a speed limit, plus extra drivable areas.

Coordinates are metres in the ``map`` frame (float64: map coordinates are large).  A lane's
direction of travel is the order of its centreline points.  Geometric queries (is a footprint
on the road, which lane is at a point) live with their users (the closed-loop metrics); this is
only the data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.types._arrays import frozen_array

__all__ = ["DrivableArea", "MapLane", "RoadMap"]


@dataclass(frozen=True, slots=True, kw_only=True)
class MapLane:
    """One lane.

    Attributes:
        lane_id: unique in its map.
        centerline: (N, 2) float64, metres, map frame, N ≥ 2, in the direction of travel.
        width_m: lane width (the lane covers ``width_m / 2`` either side of the centreline), > 0.
        speed_limit_mps: the legal speed limit, m/s; None when unknown.
    """

    lane_id: str
    centerline: npt.NDArray[np.float64]
    width_m: float
    speed_limit_mps: float | None = None

    def __post_init__(self) -> None:
        line = frozen_array(
            self.centerline,
            name=f"MapLane {self.lane_id!r}.centerline",
            dtype=np.float64,
            shape=(None, 2),
        )
        if line.shape[0] < 2 or not np.all(np.isfinite(line)):
            msg = f"MapLane {self.lane_id!r}: centerline needs >= 2 finite points, got {line.shape[0]}"
            raise ValueError(msg)
        object.__setattr__(self, "centerline", line)
        width = float(self.width_m)
        if not (width > 0 and math.isfinite(width)):
            msg = f"MapLane {self.lane_id!r}: width_m must be > 0, got {self.width_m!r}"
            raise ValueError(msg)
        object.__setattr__(self, "width_m", width)
        limit = self.speed_limit_mps
        if limit is not None:
            limit = float(limit)
            if not (limit > 0 and math.isfinite(limit)):
                msg = f"MapLane {self.lane_id!r}: speed_limit_mps must be > 0 or None, got {limit}"
                raise ValueError(msg)
            object.__setattr__(self, "speed_limit_mps", limit)

    @property
    def length_m(self) -> float:
        """Length of the centreline, metres."""
        return float(np.hypot(*np.diff(self.centerline, axis=0).T).sum())


@dataclass(frozen=True, slots=True, kw_only=True)
class DrivableArea:
    """A drivable polygon that is not a lane (an intersection square, a car park …).

    Attributes:
        area_id: unique in its map.
        polygon: (N, 2) float64 vertices, metres, map frame, N ≥ 3, not closed (the last
            vertex joins the first).
        kind: what it is: ``intersection`` (lateral tracks count for time-to-collision there, as in
            nuPlan), ``shoulder``, ``carpark`` or another word.
    """

    area_id: str
    polygon: npt.NDArray[np.float64]
    kind: str = "intersection"

    def __post_init__(self) -> None:
        poly = frozen_array(
            self.polygon,
            name=f"DrivableArea {self.area_id!r}.polygon",
            dtype=np.float64,
            shape=(None, 2),
        )
        if poly.shape[0] < 3 or not np.all(np.isfinite(poly)):
            msg = f"DrivableArea {self.area_id!r}: polygon needs >= 3 finite vertices"
            raise ValueError(msg)
        object.__setattr__(self, "polygon", poly)


@dataclass(frozen=True, slots=True, kw_only=True)
class RoadMap:
    """The drivable road of a run: its lanes and extra drivable areas (map frame).

    The drivable area is the union of the lanes (each centreline widened by half its width
    either side) and the areas.

    Attributes:
        lanes: the lanes; ids unique.
        areas: extra drivable polygons; ids unique.
        frame_id: the frame of the coordinates (``map``).
    """

    lanes: tuple[MapLane, ...]
    areas: tuple[DrivableArea, ...] = ()
    frame_id: str = "map"

    def __post_init__(self) -> None:
        lanes = tuple(self.lanes)
        areas = tuple(self.areas)
        for what, ids in (
            ("lane", [lane.lane_id for lane in lanes]),
            ("area", [a.area_id for a in areas]),
        ):
            seen: set[str] = set()
            for i in ids:
                if i in seen:
                    msg = f"RoadMap: {what} id {i!r} appears twice"
                    raise ValueError(msg)
                seen.add(i)
        object.__setattr__(self, "lanes", lanes)
        object.__setattr__(self, "areas", areas)

    def lane(self, lane_id: str) -> MapLane:
        """The lane ``lane_id`` (KeyError when there is none)."""
        for lane in self.lanes:
            if lane.lane_id == lane_id:
                return lane
        raise KeyError(lane_id)
