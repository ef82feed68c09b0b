"""Metrics against the road map: drivable-area and driving-direction compliance, speed limits
(nuPlan's definitions; see ``docs/metrics.md``).  A run without a map skips them."""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
import shapely

from redrive.evaluation.base import Bookmark, EvalData, Metric, MetricResult
from redrive.evaluation.closedloop._common import (
    EGO_DEFAULTS,
    EgoRun,
    ego_run,
    require_road,
    series,
)
from redrive.evaluation.closedloop.deviation import with_deviation
from redrive.evaluation.closedloop.lanes import driven_route, is_connector, lane_edges
from redrive.types import Role

__all__ = [
    "SL_DEFAULTS",
    "DrivableAreaCompliance",
    "DrivingDirectionCompliance",
    "SpeedLimitCompliance",
    "drivable_area_score",
    "driving_direction_score",
    "speed_limit_score",
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
        result = MetricResult(
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
        return with_deviation(result, data, frames)


DDC_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {
        **EGO_DEFAULTS,
        "compliance_threshold_m": 2.0,
        "violation_threshold_m": 6.0,
        "time_horizon_s": 1.0,
    }
)


def driving_direction_score(data: EvalData, params: Mapping[str, Any]) -> tuple[float, F64, F64]:
    """(score, per-frame progress along the driving direction over the last ``time_horizon_s``
    m — negative: against it —, frames): nuPlan ``DrivingDirectionComplianceStatistics``.

    Per state, the ego centre's progress along the centreline of the first lane of its
    :func:`driven_route` entry: the change of its projection (shapely ``project``, as
    ``get_distance_of_closest_baseline_point_to_its_start``) since the previous state in the
    same lane; 0 in no lane, on entering a lane, and — the devkit's truthiness test — when the
    projection is exactly 0. Summed over the last ``n + 1`` states, ``n = int(time_horizon /
    mean step)`` (10 at 10 Hz: 11 states). Score from the most negative sum ``m``: 1 when
    ``|m|`` < ``compliance_threshold_m``, 0.5 when < ``violation_threshold_m``, else 0.
    """
    road = require_road(data)
    ego = ego_run(data)
    centres = ego.centres(params)
    route = driven_route(road, centres)
    progress = np.zeros(len(ego))
    prev_lane: int | None = route[0][0] if route and route[0] else None
    prev_dist: float | None = None
    for i, lanes in enumerate(route):
        if not lanes:
            continue
        if prev_lane is not None and lanes[0] == prev_lane:
            line = shapely.LineString(road.lanes[lanes[0]].centerline)
            dist = float(shapely.line_locate_point(line, shapely.Point(*centres[i])))
            progress[i] = dist - prev_dist if prev_dist is not None and dist else 0.0
            prev_dist = dist
        else:
            prev_dist = None
            prev_lane = lanes[0]
    stamps_us = ego.stamps_ns // 1000
    mean_step_us = float(np.mean(np.diff(stamps_us))) if len(ego) > 1 else math.inf
    n = int(float(params["time_horizon_s"]) * 1e6 / mean_step_us) if mean_step_us > 0 else 0
    over = np.array([progress[max(0, i - n) : i + 1].sum() for i in range(len(ego))])
    worst = abs(float(over.min())) if over.size else 0.0
    if worst < float(params["compliance_threshold_m"]):
        score = 1.0
    elif worst < float(params["violation_threshold_m"]):
        score = 0.5
    else:
        score = 0.0
    return score, over, ego.frames.astype(np.float64)


class DrivingDirectionCompliance(Metric):
    """nuPlan ``driving_direction_compliance``: the ego centre's progress along the direction of
    travel of the lane it is assigned to, summed over the last ``time_horizon_s`` (1 s: 11
    states at 10 Hz, as the devkit's window sums ``n + 1`` samples); from the most negative sum,
    score 1 below ``compliance_threshold_m`` (2 m) against the lane, 0.5 below
    ``violation_threshold_m`` (6 m), else 0 (:func:`driving_direction_score`).

    Values: ``driving_direction_compliance`` (headline), ``max_wrong_way_m`` (the most negative
    sum, as a distance against the lane; 0 if none), ``min_progress_in_horizon_m`` (nuPlan's
    ``min_progress_along_driving_direction_in_1_second_interval``), in a log-backed closed
    loop ``deviated_frames``. Per frame ``progress_in_horizon_m`` (signed) and ``wrong_way_m``.
    Bookmarks ``wrong_way`` where the windowed distance first reaches the compliance threshold.
    """

    name: ClassVar[str] = "driving_direction"
    version: ClassVar[str] = "2"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego", "road_map"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True  # the headline; per value in the result
    defaults: ClassVar[Mapping[str, Any]] = DDC_DEFAULTS

    def evaluate(self, data: EvalData) -> MetricResult:
        score, progress, frames_f = driving_direction_score(data, self.params)
        frames = frames_f.astype(np.int64)
        wrong = np.maximum(0.0, -progress)
        horizon = float(self.params["time_horizon_s"])
        bad = wrong >= float(self.params["compliance_threshold_m"])
        starts = bad & ~np.concatenate([[False], bad[:-1]])
        result = MetricResult(
            values={
                "driving_direction_compliance": score,
                "max_wrong_way_m": float(wrong.max()) if wrong.size else 0.0,
                "min_progress_in_horizon_m": float(progress.min()) if progress.size else 0.0,
            },
            units={"max_wrong_way_m": "m", "min_progress_in_horizon_m": "m"},
            higher_is_better={"max_wrong_way_m": False, "min_progress_in_horizon_m": True},
            per_frame={
                "progress_in_horizon_m": series(frames, progress),
                "wrong_way_m": series(frames, wrong),
            },
            bookmarks=[
                Bookmark(
                    frame_index=int(f),
                    kind="wrong_way",
                    detail=f"ego drives {d:.1f} m against its lane within {horizon:g} s",
                    severity=float(d),
                )
                for f, d in zip(frames[starts], wrong[starts], strict=True)
            ],
        )
        return with_deviation(result, data, frames)


SL_DEFAULTS: Mapping[str, Any] = MappingProxyType({**EGO_DEFAULTS, "max_overspeed_mps": 2.23})


def speed_limit_score(data: EvalData, params: Mapping[str, Any]) -> tuple[float, F64, F64, EgoRun]:
    """(score, per-frame overspeed m/s, per-frame limit m/s — NaN where none —, the ego) of
    :class:`SpeedLimitCompliance`."""
    road = require_road(data)
    ego = ego_run(data)
    route = driven_route(road, ego.centres(params))
    limits = [lane.speed_limit_mps for lane in road.lanes]
    limit = np.full(len(ego), math.nan)
    for i, lanes in enumerate(route):
        if not lanes:
            continue
        if is_connector(road, lanes[0]):  # a connector: its outgoing and incoming lanes' limits
            edges = [
                e for k in lanes for out in (True, False) for e in lane_edges(road, k, outgoing=out)
            ]
            here = [limits[e] for e in edges]
        else:
            here = [limits[k] for k in lanes]
        if here and all(here):  # the devkit's ``all(speed_limits)``: None or 0 is no limit
            limit[i] = float(max(v for v in here if v is not None))
    over = np.where(np.isnan(limit), 0.0, np.maximum(0.0, ego.speed_mps - np.nan_to_num(limit)))
    t = ego.t_s
    duration = float(t[-1]) if t.size else 0.0
    if duration <= 0.0 or not np.any(over > 0):
        score = 1.0
    else:
        dt = float(np.mean(np.diff(t)))
        loss = over.sum() * dt / (max(float(params["max_overspeed_mps"]), 1e-3) * duration)
        score = max(0.0, 1.0 - float(loss))
    return score, over, limit, ego


class SpeedLimitCompliance(Metric):
    """nuPlan ``speed_limit_compliance``: the ego's speed above the limit of the lane its centre
    is assigned to (:func:`~redrive.evaluation.closedloop.lanes.driven_route`; on lane
    connectors the highest limit of their outgoing and incoming lanes; no lane, or a lane
    without a limit: no violation); score = max(0, 1 −
    Σ overspeed·dt / (``max_overspeed_mps`` · duration)) with dt the mean step and duration
    last − first stamp, ``max_overspeed_mps`` 2.23 m/s; 1 without any violation.

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
    defaults: ClassVar[Mapping[str, Any]] = SL_DEFAULTS

    def evaluate(self, data: EvalData) -> MetricResult:
        score, over, limit, ego = speed_limit_score(data, self.params)
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
        result = MetricResult(
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
        return with_deviation(result, data, ego.frames)
