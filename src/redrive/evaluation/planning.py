"""Open-loop planning metrics: each frame's plan against the logged ego and ground truth.

A plan (``PlannedPath``) holds waypoints x, y, z, t_s in base_link of the frame where it was
made (rear axle, x forward, y left), t_s seconds after ``stamp_ns``. Per frame with a plan:

* **ADE/FDE over horizons** (the forecasting displacement errors, as nuPlan's
  ``planner_expert_average_l2_error`` / ``planner_expert_final_l2_error``): the logged ego poses of
  the ``ego`` table (map frame, later frames) are put into the plan's base_link with the ego pose
  of the plan's frame and interpolated linearly in time at the waypoint times. ``ADE/Hs`` = mean
  planar (x, y) distance over waypoints with ``0 < t_s <= H``; ``FDE/Hs`` = the distance at
  ``t_s = H`` (plan interpolated at H). A frame counts for horizon H only when the plan reaches
  H and the log covers ``stamp + H``.
* **Collision along the plan** (nuPlan ``no_ego_at_fault_collisions``, simplified): the ego
  footprint (rear-axle reference: ``ego_length_m`` × ``ego_width_m``, ``rear_overhang_m`` behind
  the axle) at each waypoint with ``t_s <= collision_horizon_s``, heading along the plan's motion,
  against every ground-truth object of the frame predicted at constant velocity (centre +
  velocity · t_s; velocity over ground in base_link axes; yaw kept). Oriented-rectangle overlap by
  separating axes (touching counts). The first contact with each object is classified as in
  ``_get_collision_type`` of ``no_ego_at_fault_collisions.py`` (nuPlan also classifies each
  collided track once): plan speed ≤ 0.05 m/s → stopped
  ego (not at fault); object speed ≤ 0.05 m/s → stopped track (at fault); object centre more
  than 150° from the ego heading seen from the rear axle (``is_agent_behind``) → rear (not at
  fault); the ego's front edge touches the object → front (at fault); else lateral. nuPlan counts
  a lateral collision at fault only while the ego straddles lanes or leaves the drivable area;
  without a map we never do (**simplification**).
* **Minimum time-to-collision** (nuPlan ``time_to_collision_within_bound.py``
  ``_compute_time_to_collision_at_timestamp``): the ego keeps its logged speed (``ego`` table;
  the plan's initial speed when the frame has no ego state) but follows the plan's *geometry*
  (not its timing), objects keep their velocity; boxes are checked every ``ttc_step_s`` up to
  ``ttc_horizon_s`` (nuPlan: 0.1 s, 3.0 s), and the first contact is refined by bisection to
  1e-4 s (nuPlan reports the grid time). Objects behind the ego (``is_agent_behind``) are left
  out (nuPlan keeps only objects ahead, or also lateral ones in intersections, from its map).
  TTC = 0 when the ego already touches an object, ``inf`` when nothing is hit or the ego is
  stopped (≤ 5e-3 m/s, nuPlan's ``stopped_speed_threshold``). ``low_ttc_fraction`` = frames
  with TTC < ``ttc_threshold_s`` (nuPlan's ``least_min_ttc`` = 0.95 s).
* **Progress** (nuPlan ``ego_progress_along_expert_route.py``, on the logged path instead of
  map roadblocks): the logged ego path from the plan's stamp to ``stamp + T`` (T = the plan's
  last time, at most ``progress_horizon_s`` = 3 s; frames whose log ends before ``stamp + T`` are
  not scored) is the route; the plan's position at T is projected onto it: ``progress_m``; ``progress_ratio = clip(progress_m / logged_m, 0, 1)`` (nuPlan's
  ``ego_expert_progress_along_route_ratio``). nuPlan divides by ``max(logged_m, 2 m)``
  (``score_progress_threshold`` of its config) over a whole scenario; per frame, that would
  score every plan 0 while the logged ego waits at a light, so frames where the logged ego moved
  less than ``progress_threshold_m`` (2 m) get no ratio instead (``progress_m`` still counts).
* **Comfort** of the plan's own kinematics (finite differences, see
  :func:`redrive.evaluation._kinematics.path_kinematics`) against nuPlan's
  ``ego_is_comfortable`` bounds (``nuplan/planning/script/config/common/simulation_metric/
  low_level/ego_*_statistics.yaml``): lon accel in [−4.05, 2.40] m/s², |lat accel| ≤ 4.89 m/s²,
  |yaw rate| ≤ 0.95 rad/s, |yaw accel| ≤ 1.93 rad/s², |lon jerk| ≤ 4.13 m/s³, |jerk| ≤ 8.37 m/s³.
  nuPlan smooths the simulated states with a Savitzky-Golay filter (window 15, order 2) first;
  a plan is already a designed trajectory, so we do not.

Bookmarks: ``collision`` (severity = the largest relative speed at contact, m/s, of the at-fault
contacts, or of all when none is at fault: nuPlan's collision-energy ``ego_delta_v`` idea) and ``low_ttc`` (TTC < ``ttc_bookmark_s``; severity = 1/TTC, 1/s).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
import shapely

from redrive.errors import ConfigError
from redrive.evaluation._kinematics import (
    EgoTrack,
    base_from_map_xy,
    ego_footprint_corners,
    path_kinematics,
    polyline_pose_at,
    project_on_polyline,
    rectangle_corners,
    rectangles_overlap,
)
from redrive.evaluation.base import (
    Bookmark,
    EvalData,
    Metric,
    MetricResult,
    MetricSkipped,
    Series,
)
from redrive.types import DetectedObject, ObjectColumns, PlannedPath, Role, VehicleState

__all__ = ["COMFORT_BOUNDS", "PlanningMetrics", "time_to_collision_s"]

logger = logging.getLogger(__name__)

F64 = npt.NDArray[np.float64]

#: nuPlan's thresholds (stopped ego / stopped track) in ``_get_collision_type``, m/s.
COLLISION_STOPPED_SPEED_MPS = 5e-2
#: nuPlan's ``stopped_speed_threshold`` of ``compute_time_to_collision``, m/s.
TTC_STOPPED_SPEED_MPS = 5e-3
#: nuPlan's ``is_agent_behind`` angle tolerance, rad (150°).
BEHIND_ANGLE_RAD = math.radians(150.0)

#: nuPlan ``ego_is_comfortable`` bounds (config ``simulation_metric/low_level/ego_*.yaml``).
COMFORT_BOUNDS: Mapping[str, float] = MappingProxyType(
    {
        "min_lon_accel_mps2": -4.05,
        "max_lon_accel_mps2": 2.40,
        "max_abs_lat_accel_mps2": 4.89,
        "max_abs_yaw_rate_rad_s": 0.95,
        "max_abs_yaw_accel_rad_s2": 1.93,
        "max_abs_lon_jerk_mps3": 4.13,
        "max_abs_jerk_mps3": 8.37,
    }
)


def _corners_at(objs: ObjectColumns, t_s: F64) -> F64:
    """Corners (T, M, 4, 2) of the objects' footprints at times ``t_s`` (T,), constant velocity."""
    size = objs.size_m
    base = rectangle_corners(objs.center_m[:, :2], objs.yaw_rad, size[:, 0], size[:, 1])
    shift = t_s[:, None, None] * objs.velocity_mps[None, :, :2]
    return base[None] + shift[:, :, None, :]


@dataclass(frozen=True, slots=True)
class _Contact:
    """The first contact of a plan with one object."""

    t_s: float
    object_id: int
    object_class: str
    kind: str  # nuPlan CollisionType, lower case: stopped_ego, stopped_track, active_rear …
    at_fault: bool
    relative_speed_mps: float


@dataclass(slots=True)
class _Series:
    frames: list[int] = field(default_factory=list)
    values: list[float] = field(default_factory=list)

    def add(self, frame: int, value: float) -> None:
        self.frames.append(frame)
        self.values.append(value)

    def series(self) -> Series:
        return np.array(self.frames, dtype=np.int64), np.array(self.values, dtype=np.float64)


def _ego_corners(xy: F64, heading: F64, p: Mapping[str, Any]) -> F64:
    return ego_footprint_corners(
        xy,
        heading,
        length_m=float(p["ego_length_m"]),
        width_m=float(p["ego_width_m"]),
        rear_overhang_m=float(p["rear_overhang_m"]),
    )


def time_to_collision_s(
    path_xy: npt.ArrayLike,
    objects: Sequence[DetectedObject],
    *,
    speed_mps: float,
    step_s: float = 0.1,
    horizon_s: float = 3.0,
    ego_length_m: float = 4.7,
    ego_width_m: float = 1.9,
    rear_overhang_m: float = 0.95,
) -> tuple[float, int]:
    """Time until the ego footprint, moving at ``speed_mps`` along the polyline ``path_xy``
    (rear-axle positions in base_link, starting at the ego), first touches one of ``objects``
    moving at constant velocity; see the module docstring for the definition.

    Returns:
        (TTC in s — 0.0 when already touching, ``inf`` when nothing is hit within
        ``horizon_s`` or the ego is stopped; the object id hit, −1 when none).
    """
    objs = ObjectColumns.from_objects(objects)
    if len(objs) == 0:
        return math.inf, -1
    angle = np.abs(np.arctan2(objs.center_m[:, 1], objs.center_m[:, 0]))
    objs = objs.take(angle <= BEHIND_ANGLE_RAD)
    if len(objs) == 0:
        return math.inf, -1
    params = {
        "ego_length_m": ego_length_m,
        "ego_width_m": ego_width_m,
        "rear_overhang_m": rear_overhang_m,
    }
    poly = np.asarray(path_xy, dtype=np.float64).reshape(-1, 2)

    def hits(t: F64) -> npt.NDArray[np.bool_]:
        xy, heading = polyline_pose_at(poly, speed_mps * t)
        # the ego's start pose is the plan's first point, heading of the first segment
        ego = _ego_corners(xy, heading, params)  # (T, 4, 2)
        return rectangles_overlap(ego[:, None], _corners_at(objs, t))  # (T, M)

    now = hits(np.zeros(1))[0]
    if now.any():
        return 0.0, int(objs.object_id[int(np.argmax(now))])
    if speed_mps <= TTC_STOPPED_SPEED_MPS:
        return math.inf, -1
    n = math.floor(horizon_s / step_s + 1e-9)
    grid = step_s * np.arange(1, n + 1, dtype=np.float64)
    contact = hits(grid)
    first = np.flatnonzero(contact.any(axis=1))
    if first.size == 0:
        return math.inf, -1
    i = int(first[0])
    lo, hi = (0.0 if i == 0 else float(grid[i - 1])), float(grid[i])
    while hi - lo > 1e-4:
        mid = 0.5 * (lo + hi)
        if hits(np.array([mid]))[0].any():
            hi = mid
        else:
            lo = mid
    who = hits(np.array([hi]))[0]
    return hi, int(objs.object_id[int(np.argmax(who))]) if who.any() else -1


class PlanningMetrics(Metric):
    """ADE/FDE over horizons, collision and at-fault collision along the plan, minimum TTC,
    progress along the logged route and comfort, for a planning algorithm (open loop).

    Parameters (defaults): ``horizons_s`` (1, 2, 3); ``ego_length_m`` 4.7, ``ego_width_m`` 1.9,
    ``rear_overhang_m`` 0.95; ``collision_horizon_s`` 3.0; ``ttc_step_s`` 0.1,
    ``ttc_horizon_s`` 3.0, ``ttc_threshold_s`` 0.95, ``ttc_bookmark_s`` 1.5;
    ``progress_horizon_s`` 3.0, ``progress_threshold_m`` 2.0; the comfort bounds of :data:`COMFORT_BOUNDS`.

    Values: ``ADE/3s`` (headline: the longest horizon), ``FDE/3s``, ``ADE/1s``, ``FDE/1s`` …,
    ``collision_rate``, ``at_fault_collision_rate``, ``collisions``, ``at_fault_collisions``,
    ``min_ttc_s``, ``low_ttc_fraction``, ``progress_ratio``, ``progress_m``,
    ``comfortable_fraction`` and the worst value of each comfort quantity over all plans
    (``max_lon_accel_mps2``, ``min_lon_accel_mps2``, ``max_abs_lat_accel_mps2``,
    ``max_abs_yaw_rate_rad_s``, ``max_abs_yaw_accel_rad_s2``, ``max_abs_lon_jerk_mps3``,
    ``max_abs_jerk_mps3``), ``frames`` (plans scored). Rates and fractions are over the frames
    where they are defined (collision/TTC: frames with ground truth; comfort: plans with ≥ 3
    distinct times). Per-frame series of each.
    """

    name: ClassVar[str] = "planning"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = Role.PLANNING
    # ground truth only for the collision and TTC values: ADE/FDE, progress and comfort need
    # the ego track alone (real logs without object labels)
    needs: ClassVar[frozenset[str]] = frozenset({"paths", "ego"})
    unit: ClassVar[str] = "m"
    higher_is_better: ClassVar[bool] = False
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {
            "horizons_s": (1.0, 2.0, 3.0),
            "ego_length_m": 4.7,
            "ego_width_m": 1.9,
            "rear_overhang_m": 0.95,
            "collision_horizon_s": 3.0,
            "ttc_step_s": 0.1,
            "ttc_horizon_s": 3.0,
            "ttc_threshold_s": 0.95,
            "ttc_bookmark_s": 1.5,
            "progress_horizon_s": 3.0,
            "progress_threshold_m": 2.0,
            **COMFORT_BOUNDS,
        }
    )

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        horizons = tuple(float(h) for h in self.params["horizons_s"])
        if not horizons or any(not (h > 0 and math.isfinite(h)) for h in horizons):
            msg = f"metric 'planning': horizons_s must be positive seconds, got {horizons}"
            raise ConfigError(msg)
        self.horizons_s = tuple(sorted(set(horizons)))
        for key in ("ego_length_m", "ego_width_m", "ttc_step_s", "ttc_horizon_s"):
            if not float(self.params[key]) > 0:
                msg = f"metric 'planning': {key} must be > 0, got {self.params[key]!r}"
                raise ConfigError(msg)

    # -- per-frame pieces -------------------------------------------------------------------

    def _displacement(
        self, path: PlannedPath, ego_now: VehicleState, track: EgoTrack, horizon_s: float
    ) -> tuple[float, float]:
        wp = path.waypoints
        t = wp[:, 3]
        h_ns = round(horizon_s * 1e9)
        if t.size == 0 or t[-1] < horizon_s - 1e-9 or not track.covers(path.stamp_ns + h_ns):
            return math.nan, math.nan
        origin, heading = ego_now.position[:2], float(ego_now.heading_rad)
        sel = (t > 0) & (t <= horizon_s + 1e-9)
        stamps = path.stamp_ns + np.round(t[sel] * 1e9).astype(np.int64)
        logged, _ = track.interpolate(stamps)
        err = np.hypot(*(wp[sel, :2] - base_from_map_xy(logged, origin, heading)).T)
        ade = float(err.mean()) if err.size else math.nan
        plan_end = np.array([np.interp(horizon_s, t, wp[:, 0]), np.interp(horizon_s, t, wp[:, 1])])
        log_end, _ = track.interpolate([path.stamp_ns + h_ns])
        fde = float(np.hypot(*(plan_end - base_from_map_xy(log_end, origin, heading)[0])))
        return ade, fde

    def _collisions(self, path: PlannedPath, objs: ObjectColumns) -> list[_Contact]:
        """The first contact of the plan with each object it touches, in time order."""
        kin = path_kinematics(path.waypoints)
        if kin is None or len(objs) == 0:
            return []
        sel = kin.t_s <= float(self.params["collision_horizon_s"]) + 1e-9
        t = kin.t_s[sel]
        xy, heading_rad = kin.xy[sel], kin.heading_rad[sel]
        speed, velocity = kin.speed_mps[sel], kin.velocity_xy[sel]
        ego = _ego_corners(xy, heading_rad, self.params)
        obj_corners = _corners_at(objs, t)  # (K, M, 4, 2)
        contact = rectangles_overlap(ego[:, None], obj_corners)  # (K, M)
        found: list[_Contact] = []
        for m in np.flatnonzero(contact.any(axis=0)):
            k = int(np.argmax(contact[:, m]))
            corners = obj_corners[k, m]
            to_obj = corners.mean(axis=0) - xy[k]
            rel_angle = abs(
                math.remainder(math.atan2(to_obj[1], to_obj[0]) - float(heading_rad[k]), math.tau)
            )
            obj_speed = float(np.hypot(*objs.velocity_mps[m, :2]))
            front = shapely.LineString([ego[k, 0], ego[k, 3]])
            if speed[k] <= COLLISION_STOPPED_SPEED_MPS:
                kind, at_fault = "stopped_ego", False
            elif obj_speed <= COLLISION_STOPPED_SPEED_MPS:
                kind, at_fault = "stopped_track", True
            elif rel_angle > BEHIND_ANGLE_RAD:
                kind, at_fault = "active_rear", False
            elif front.intersects(shapely.Polygon(corners)):
                kind, at_fault = "active_front", True
            else:
                kind, at_fault = "active_lateral", False
            found.append(
                _Contact(
                    t_s=float(t[k]),
                    object_id=int(objs.object_id[m]),
                    object_class=objs.object_class[m].value,
                    kind=kind,
                    at_fault=at_fault,
                    relative_speed_mps=float(np.hypot(*(velocity[k] - objs.velocity_mps[m, :2]))),
                )
            )
        return sorted(found, key=lambda c: (c.t_s, c.object_id))

    def _progress(
        self, path: PlannedPath, ego_now: VehicleState, track: EgoTrack
    ) -> tuple[float, float]:
        wp = path.waypoints
        if wp.shape[0] == 0 or len(track) == 0:
            return math.nan, math.nan
        t_end = min(float(wp[-1, 3]), float(self.params["progress_horizon_s"]))
        end_ns = path.stamp_ns + round(t_end * 1e9)
        if end_ns <= path.stamp_ns or not (track.covers(path.stamp_ns) and track.covers(end_ns)):
            return math.nan, math.nan
        route = base_from_map_xy(
            track.samples_between(path.stamp_ns, end_ns),
            ego_now.position[:2],
            float(ego_now.heading_rad),
        )
        logged_m = float(np.hypot(*np.diff(route, axis=0).T).sum())
        plan_end = np.array(
            [[np.interp(t_end, wp[:, 3], wp[:, 0]), np.interp(t_end, wp[:, 3], wp[:, 1])]]
        )
        arc, _, _ = project_on_polyline(plan_end, route)
        progress = float(arc[0])
        if logged_m < float(self.params["progress_threshold_m"]):
            return progress, math.nan  # the logged ego (nearly) stood still: no ratio
        return progress, min(1.0, max(0.0, progress / logged_m))

    # -- evaluate ----------------------------------------------------------------------------

    def evaluate(self, data: EvalData) -> MetricResult:
        p = self.params
        paths = data.paths()
        ego = data.ego()
        truth = data.ground_truth()
        track = EgoTrack.from_states(ego)
        series: dict[str, _Series] = {}

        def add(key: str, frame: int, value: float) -> None:
            series.setdefault(key, _Series()).add(frame, value)

        bookmarks: list[Bookmark] = []
        comfort_keys = (
            ("max_lon_accel_mps2", "lon_accel_mps2", np.max),
            ("min_lon_accel_mps2", "lon_accel_mps2", np.min),
            ("max_abs_lat_accel_mps2", "lat_accel_mps2", None),
            ("max_abs_yaw_rate_rad_s", "yaw_rate_rad_s", None),
            ("max_abs_yaw_accel_rad_s2", "yaw_accel_rad_s2", None),
            ("max_abs_lon_jerk_mps3", "lon_jerk_mps3", None),
            ("max_abs_jerk_mps3", "jerk_mag_mps3", None),
        )
        scored = 0
        for frame in sorted(paths):
            path = paths[frame]
            if path.waypoints.shape[0] == 0:
                continue
            if path.frame_id not in ("base_link", ""):
                msg = (
                    f"planning metric: the plan of frame {frame} is in {path.frame_id!r}; only "
                    "base_link plans can be scored"
                )
                raise MetricSkipped(msg)
            scored += 1
            now = ego.get(frame)
            if now is not None:
                for h in self.horizons_s:
                    ade, fde = self._displacement(path, now, track, h)
                    if not math.isnan(ade):
                        add(f"ADE/{h:g}s", frame, ade)
                    if not math.isnan(fde):
                        add(f"FDE/{h:g}s", frame, fde)
                progress, ratio = self._progress(path, now, track)
                if not math.isnan(progress):
                    add("progress_m", frame, progress)
                if not math.isnan(ratio):
                    add("progress_ratio", frame, ratio)
            kin = path_kinematics(path.waypoints)
            if kin is not None:
                ok = True
                for key, attr, fn in comfort_keys:
                    arr = getattr(kin, attr)
                    val = float(fn(arr)) if fn is not None else float(np.max(np.abs(arr)))
                    add(key, frame, val)
                    bound = float(p[key])
                    ok &= val >= bound if key.startswith("min_") else val <= bound
                add("comfortable", frame, float(ok))
            if frame in truth:
                objs = ObjectColumns.from_objects(truth[frame])
                contacts = self._collisions(path, objs)
                add("collision", frame, float(bool(contacts)))
                add("at_fault_collision", frame, float(any(c.at_fault for c in contacts)))
                if contacts:
                    first = contacts[0]
                    fault = [c for c in contacts if c.at_fault]
                    bookmarks.append(
                        Bookmark(
                            frame_index=frame,
                            kind="collision",
                            detail=(
                                f"plan hits {first.object_class} {first.object_id} at "
                                f"t={first.t_s:.2f} s ({first.kind}, "
                                f"{'at fault' if first.at_fault else 'not at fault'}, "
                                f"{first.relative_speed_mps:.1f} m/s relative)"
                                + (f"; {len(contacts)} objects hit" if len(contacts) > 1 else "")
                                + (
                                    f"; at fault with {fault[0].object_class} {fault[0].object_id}"
                                    if fault and not first.at_fault
                                    else ""
                                )
                            ),
                            severity=max(c.relative_speed_mps for c in (fault or contacts)),
                        )
                    )
                speed = (
                    now.speed_mps
                    if now is not None
                    else (float(kin.speed_mps[0]) if kin is not None else 0.0)
                )
                ttc, oid = time_to_collision_s(
                    path.waypoints[:, :2],
                    truth[frame],
                    speed_mps=speed,
                    step_s=float(p["ttc_step_s"]),
                    horizon_s=float(p["ttc_horizon_s"]),
                    ego_length_m=float(p["ego_length_m"]),
                    ego_width_m=float(p["ego_width_m"]),
                    rear_overhang_m=float(p["rear_overhang_m"]),
                )
                add("min_ttc_s", frame, ttc)
                if ttc < float(p["ttc_bookmark_s"]):
                    bookmarks.append(
                        Bookmark(
                            frame_index=frame,
                            kind="low_ttc",
                            detail=f"TTC {ttc:.2f} s to object {oid} at {speed:.1f} m/s",
                            severity=1.0 / max(ttc, 1e-3),
                        )
                    )
        return self._result(series, bookmarks, scored)

    def _result(
        self, series: Mapping[str, _Series], bookmarks: list[Bookmark], scored: int
    ) -> MetricResult:
        def mean(key: str) -> float:
            s = series.get(key)
            return float(np.mean(s.values)) if s and s.values else math.nan

        def total(key: str) -> float:
            s = series.get(key)
            return float(np.sum(s.values)) if s and s.values else 0.0

        values: dict[str, float] = {}
        units: dict[str, str] = {}
        for h in sorted(self.horizons_s, reverse=True):
            for kind in ("ADE", "FDE"):
                values[f"{kind}/{h:g}s"] = mean(f"{kind}/{h:g}s")
        values["collision_rate"] = mean("collision")
        values["at_fault_collision_rate"] = mean("at_fault_collision")
        values["collisions"] = total("collision")
        values["at_fault_collisions"] = total("at_fault_collision")
        ttc = series.get("min_ttc_s")
        ttc_vals = np.array(ttc.values if ttc else [], dtype=np.float64)
        values["min_ttc_s"] = float(ttc_vals.min()) if ttc_vals.size else math.nan
        values["low_ttc_fraction"] = (
            float(np.mean(ttc_vals < float(self.params["ttc_threshold_s"])))
            if ttc_vals.size
            else math.nan
        )
        values["progress_ratio"] = mean("progress_ratio")
        values["progress_m"] = mean("progress_m")
        values["comfortable_fraction"] = mean("comfortable")
        for key in COMFORT_BOUNDS:
            s = series.get(key)
            if not s or not s.values:
                values[key] = math.nan
            elif key.startswith("min_"):
                values[key] = float(np.min(s.values))
            else:
                values[key] = float(np.max(s.values))
            units[key] = _unit_of(key)
        values["frames"] = float(scored)
        for key in (
            "collision_rate",
            "at_fault_collision_rate",
            "low_ttc_fraction",
            "progress_ratio",
            "comfortable_fraction",
        ):
            units[key] = "ratio"
        units.update(collisions="frames", at_fault_collisions="frames", frames="frames")
        units.update(min_ttc_s="s", progress_m="m")
        # errors, collisions and comfort maxima are lower-is-better (the metric's direction);
        # these are not
        better = {"min_ttc_s", "progress_ratio", "progress_m", "comfortable_fraction"}
        better.add("min_lon_accel_mps2")  # the hardest braking: closer to 0 is gentler
        directions: dict[str, bool | None] = {k: True for k in values if k in better}
        directions["frames"] = None
        # how each aggregate is made from its per-frame series (compare bootstraps that)
        statistics: dict[str, tuple[str, str]] = {
            "collision_rate": ("collision", "mean"),
            "at_fault_collision_rate": ("at_fault_collision", "mean"),
            "collisions": ("collision", "sum"),
            "at_fault_collisions": ("at_fault_collision", "sum"),
            "min_ttc_s": ("min_ttc_s", "min"),
            "comfortable_fraction": ("comfortable", "mean"),
        }
        for key in COMFORT_BOUNDS:
            statistics[key] = (key, "min" if key.startswith("min_") else "max")
        return MetricResult(
            values=values,
            units=units,
            higher_is_better=directions,
            per_frame={k: s.series() for k, s in series.items()},
            bookmarks=bookmarks,
            statistics={k: v for k, v in statistics.items() if v[0] in series},
        )


def _unit_of(key: str) -> str:
    for suffix, unit in (
        ("_mps2", "m/s²"),
        ("_mps3", "m/s³"),
        ("_rad_s2", "rad/s²"),
        ("_rad_s", "rad/s"),
        ("_mps", "m/s"),
        ("_m", "m"),
        ("_s", "s"),
    ):
        if key.endswith(suffix):
            return unit
    return ""
