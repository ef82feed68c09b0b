"""Metrics against the road map: drivable-area and driving-direction compliance, speed limits
(nuPlan's definitions; see ``docs/metrics.md``).  A run without a map skips them."""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from redrive.evaluation.base import Bookmark, EvalData, Metric, MetricResult
from redrive.evaluation.closedloop._common import EGO_DEFAULTS, ego_run, require_road, series
from redrive.types import Role

__all__ = [
    "DrivableAreaCompliance",
    "DrivingDirectionCompliance",
    "SpeedLimitCompliance",
    "drivable_area_score",
    "driving_direction_score",
]

F64 = npt.NDArray[np.float64]

DAC_DEFAULTS: Mapping[str, Any] = MappingProxyType({**EGO_DEFAULTS, "max_violation_m": 0.3})


def drivable_area_score(data: EvalData, params: Mapping[str, Any]) -> tuple[float, F64, F64]:
    """(score, per-frame largest corner distance outside the drivable area m, frames)."""
    road = require_road(data)
    ego = ego_run(data)
    corners = ego.corners(params)
    outside = road.distance_outside(corners.reshape(-1, 2)).reshape(-1, 4).max(axis=1)
    score = float(not np.any(outside >= float(params["max_violation_m"])))
    return score, outside, ego.frames.astype(np.float64)


class DrivableAreaCompliance(Metric):
    """nuPlan ``drivable_area_compliance``: every footprint corner in the drivable area (the
    union of lanes and drivable areas of the map); a corner more than ``max_violation_m``
    (0.3 m) outside at any frame fails the run.

    Values: ``drivable_area_compliance`` (headline, 1 or 0), ``off_road_frames`` (a corner
    outside at all), ``max_outside_m``. Per frame ``outside_m``, ``corners_in_drivable_area``.
    Bookmarks ``off_road`` (frames where the ego leaves it).
    """

    name: ClassVar[str] = "drivable_area"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego", "road_map"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True  # the headline; per value in the result
    defaults: ClassVar[Mapping[str, Any]] = DAC_DEFAULTS

    def evaluate(self, data: EvalData) -> MetricResult:
        score, outside, frames_f = drivable_area_score(data, self.params)
        frames = frames_f.astype(np.int64)
        off = outside > 0.0
        starts = off & ~np.concatenate([[False], off[:-1]])
        return MetricResult(
            values={
                "drivable_area_compliance": score,
                "off_road_frames": float(off.sum()),
                "max_outside_m": float(outside.max()) if outside.size else 0.0,
            },
            units={"off_road_frames": "frames", "max_outside_m": "m"},
            higher_is_better={"off_road_frames": False, "max_outside_m": False},
            per_frame={
                "outside_m": series(frames, outside),
                "corners_in_drivable_area": series(frames, (~off).astype(np.float64)),
            },
            bookmarks=[
                Bookmark(
                    frame_index=int(f),
                    kind="off_road",
                    detail=f"ego footprint leaves the drivable area by {d:.2f} m",
                    severity=float(d),
                )
                for f, d in zip(frames[starts], outside[starts], strict=True)
            ],
        )


DDC_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {
        **EGO_DEFAULTS,
        "compliance_threshold_m": 2.0,
        "violation_threshold_m": 6.0,
        "time_horizon_s": 1.0,
    }
)


def driving_direction_score(data: EvalData, params: Mapping[str, Any]) -> tuple[float, F64, F64]:
    """(score, per-frame wrong-way distance over the last ``time_horizon_s`` m, frames)."""
    road = require_road(data)
    ego = ego_run(data)
    centres = ego.centres(params)
    against = np.zeros(len(ego))
    if len(ego) > 1:
        # every (frame, lane holding the centre) pair at once; off every lane: no pair (the
        # drivable-area metric's business)
        which, lanes = road.lane_hits(centres[1:])
        ids = [road.lanes[k].lane_id for k in lanes.tolist()]
        _, _, heading = road.station(centres[1:][which], ids)
        steps = np.diff(centres, axis=0)[which]
        along = steps[:, 0] * np.cos(heading) + steps[:, 1] * np.sin(heading)
        best = np.full(len(ego) - 1, -np.inf)
        np.maximum.at(best, which, along)
        # some lane it is in runs its way: no violation
        against[1:] = np.where(np.isfinite(best), np.maximum(0.0, -best), 0.0)
    t = ego.t_s
    window = float(params["time_horizon_s"])
    over = np.array(
        [against[(t > t[i] - window + 1e-9) & (t <= t[i])].sum() for i in range(len(ego))]
    )
    worst = float(over.max()) if over.size else 0.0
    if worst < float(params["compliance_threshold_m"]):
        score = 1.0
    elif worst < float(params["violation_threshold_m"]):
        score = 0.5
    else:
        score = 0.0
    return score, over, ego.frames.astype(np.float64)


class DrivingDirectionCompliance(Metric):
    """nuPlan ``driving_direction_compliance``: the distance the ego's centre moves against the
    direction of travel of the lane it is in, summed over ``time_horizon_s`` (1 s); score 1
    below ``compliance_threshold_m`` (2 m), 0.5 below ``violation_threshold_m`` (6 m), else 0.

    Values: ``driving_direction_compliance`` (headline), ``max_wrong_way_m``. Per frame
    ``wrong_way_m``. Bookmarks ``wrong_way`` where the windowed distance first passes 2 m.
    """

    name: ClassVar[str] = "driving_direction"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego", "road_map"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True  # the headline; per value in the result
    defaults: ClassVar[Mapping[str, Any]] = DDC_DEFAULTS

    def evaluate(self, data: EvalData) -> MetricResult:
        score, over, frames_f = driving_direction_score(data, self.params)
        frames = frames_f.astype(np.int64)
        bad = over >= float(self.params["compliance_threshold_m"])
        starts = bad & ~np.concatenate([[False], bad[:-1]])
        return MetricResult(
            values={
                "driving_direction_compliance": score,
                "max_wrong_way_m": float(over.max()) if over.size else 0.0,
            },
            units={"max_wrong_way_m": "m"},
            higher_is_better={"max_wrong_way_m": False},
            per_frame={"wrong_way_m": series(frames, over)},
            bookmarks=[
                Bookmark(
                    frame_index=int(f),
                    kind="wrong_way",
                    detail=f"ego drives {d:.1f} m against its lane within 1 s",
                    severity=float(d),
                )
                for f, d in zip(frames[starts], over[starts], strict=True)
            ],
        )


class SpeedLimitCompliance(Metric):
    """nuPlan ``speed_limit_compliance``: the ego's speed above the limit of the lane its centre
    is in (the highest limit where lanes overlap; no lane or no limit: no violation);
    score = max(0, 1 − Σ overspeed·dt / (``max_overspeed_mps`` · duration)), 2.23 m/s.

    Values: ``speed_limit_compliance`` (headline), ``max_overspeed_mps``, ``speeding_frames``.
    Per frame ``overspeed_mps``, ``speed_limit_mps`` (NaN off the lanes). Bookmarks
    ``speeding`` where a violation starts (severity: its largest overspeed).
    """

    name: ClassVar[str] = "speed_limit"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego", "road_map"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True  # the headline; per value in the result
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {**EGO_DEFAULTS, "max_overspeed_mps": 2.23}
    )

    def evaluate(self, data: EvalData) -> MetricResult:
        road = require_road(data)
        ego = ego_run(data)
        which, lanes = road.lane_hits(ego.centres(self.params))
        limits = np.array(
            [
                math.nan if lane.speed_limit_mps is None else lane.speed_limit_mps
                for lane in road.lanes
            ]
        )[lanes]
        # the highest limit of the lanes holding the centre; NaN when none does or one of them
        # has no limit
        limit = np.full(len(ego), -np.inf)
        np.maximum.at(limit, which, np.nan_to_num(limits, nan=-np.inf))
        unknown = np.zeros(len(ego), dtype=bool)
        unknown[which[np.isnan(limits)]] = True
        limit[unknown | ~np.isfinite(limit)] = math.nan
        over = np.where(np.isnan(limit), 0.0, np.maximum(0.0, ego.speed_mps - np.nan_to_num(limit)))
        t = ego.t_s
        duration = float(t[-1]) if t.size else 0.0
        if duration <= 0.0 or not np.any(over > 0):
            score = 1.0
        else:
            dt = float(np.mean(np.diff(t)))
            loss = over.sum() * dt / (max(float(self.params["max_overspeed_mps"]), 1e-3) * duration)
            score = max(0.0, 1.0 - float(loss))
        speeding = over > 0
        starts = np.flatnonzero(speeding & ~np.concatenate([[False], speeding[:-1]]))
        bookmarks = []
        for s in starts:
            e = s
            while e + 1 < len(ego) and speeding[e + 1]:
                e += 1
            worst = float(over[s : e + 1].max())
            bookmarks.append(
                Bookmark(
                    frame_index=int(ego.frames[s]),
                    kind="speeding",
                    detail=f"{worst:.1f} m/s over the {limit[s] * 3.6:.0f} km/h limit "
                    f"for {e - s + 1} frames",
                    severity=worst,
                )
            )
        return MetricResult(
            values={
                "speed_limit_compliance": score,
                "max_overspeed_mps": float(over.max()) if over.size else 0.0,
                "speeding_frames": float(speeding.sum()),
            },
            units={"max_overspeed_mps": "m/s", "speeding_frames": "frames"},
            higher_is_better={"max_overspeed_mps": False, "speeding_frames": False},
            per_frame={
                "overspeed_mps": series(ego.frames, over),
                "speed_limit_mps": series(ego.frames, limit),
            },
            bookmarks=bookmarks,
        )
