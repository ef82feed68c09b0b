"""Ego progress along the logged route and comfort of the driven ego (nuPlan's definitions;
see ``docs/metrics.md``)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from scipy.signal import savgol_filter

from redrive.evaluation._kinematics import project_on_polyline
from redrive.evaluation.base import Bookmark, EvalData, Metric, MetricResult, MetricSkipped
from redrive.evaluation.closedloop._common import (
    EGO_DEFAULTS,
    EgoRun,
    ego_run,
    road_index,
    series,
)
from redrive.evaluation.closedloop.deviation import with_deviation
from redrive.evaluation.closedloop.lanes import progress_along_route
from redrive.evaluation.planning import COMFORT_BOUNDS
from redrive.types import Role

__all__ = [
    "COMFORT_DEFAULTS",
    "Comfort",
    "EgoProgress",
    "approximate_derivative",
    "body_accelerations",
    "comfort_kinematics",
    "comfort_verdicts",
    "phase_unwrap",
    "progress_ratio",
]

F64 = npt.NDArray[np.float64]

PROGRESS_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {**EGO_DEFAULTS, "score_progress_threshold_m": 2.0}
)


def progress_ratio(
    data: EvalData, params: Mapping[str, Any]
) -> tuple[float, float, float, F64, F64]:
    """(ratio, ego progress m, expert progress m, frames, ego progress so far per frame m):
    nuPlan ``EgoProgressAlongExpertRouteStatistics.compute``.

    The expert is the logged ego (``logged_ego``; in open loop the ego itself). With a road
    map, both footprint centres' progress is measured along the baselines of the expert
    route's roadblocks (:func:`~redrive.evaluation.closedloop.lanes.progress_along_route`); an
    expert in no lane scores the ratio 1 (ego progress NaN, expert 0), as nuPlan does. Without a
    map the route is the expert's own path and progress the arc length of the last centre minus
    the first's, projected on it. nuPlan's ratio: 0 when the ego went back more than
    ``score_progress_threshold_m`` (2 m), else min(1, max(ego, thr) / max(expert, thr)).
    """
    ego = ego_run(data)
    logged = data.logged_ego()
    expert = EgoRun.of(logged) if logged else ego
    thr = float(params["score_progress_threshold_m"])
    frames = ego.frames.astype(np.float64)
    road = road_index(data)
    if road is not None:
        along = progress_along_route(
            road, expert_points=expert.centres(params), ego_points=ego.centres(params)
        )
        if along is None:
            return 1.0, math.nan, 0.0, frames, np.full(len(ego), math.nan)
        ego_steps, expert_steps = along
        ego_m, expert_m = float(ego_steps.sum()), float(expert_steps.sum())
        arc = np.cumsum(ego_steps)
    else:
        route = expert.centres(params)
        keep = np.concatenate([[True], np.hypot(*np.diff(route, axis=0).T) > 1e-6])
        route = route[keep]
        expert_m = float(np.hypot(*np.diff(route, axis=0).T).sum())
        arc, _, _ = project_on_polyline(ego.centres(params), route)
        ego_m = float(arc[-1] - arc[0])
        arc = arc - arc[0]
    ratio = 0.0 if ego_m < -thr else min(1.0, max(ego_m, thr) / max(expert_m, thr))
    return ratio, ego_m, expert_m, frames, np.asarray(arc, dtype=np.float64)


class EgoProgress(Metric):
    """nuPlan ``ego_progress_along_expert_route``: how far the ego got along the expert's route
    (its roadblocks on the road map; without a map, its path) compared with the logged ego (the
    expert), :func:`progress_ratio`.

    Values: ``ego_progress_ratio`` (headline, [0, 1]), ``ego_progress_m``,
    ``expert_progress_m``, ``making_progress`` (nuPlan ``ego_is_making_progress``: ratio at least
    ``min_progress_ratio`` 0.2), ``along_map_route`` (1: along the map's roadblocks, 0: along
    the expert's path), in a closed loop with a logged ego ``deviated_frames``. Per frame
    ``progress_m`` (the progress so far).
    """

    name: ClassVar[str] = "ego_progress"
    version: ClassVar[str] = "2"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego"})
    unit: ClassVar[str] = "ratio"
    higher_is_better: ClassVar[bool] = True  # the headline; per value in the result
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {**PROGRESS_DEFAULTS, "min_progress_ratio": 0.2}
    )

    def evaluate(self, data: EvalData) -> MetricResult:
        ratio, ego_m, expert_m, frames, arc = progress_ratio(data, self.params)
        along_map = float(road_index(data) is not None)
        result = MetricResult(
            values={
                "ego_progress_ratio": ratio,
                "ego_progress_m": ego_m,
                "expert_progress_m": expert_m,
                "making_progress": float(ratio >= float(self.params["min_progress_ratio"])),
                "along_map_route": along_map,
            },
            units={
                "ego_progress_m": "m",
                "expert_progress_m": "m",
                "making_progress": "score",
                "along_map_route": "flag",
            },
            # the logged ego's: the reference; the flag says how progress was measured
            higher_is_better={"expert_progress_m": None, "along_map_route": None},
            per_frame={"progress_m": series(frames.astype(np.int64), arc)},
        )
        return with_deviation(result, data, frames.astype(np.int64))


#: the comfort quantities: name → (bound key(s)); nuPlan's six ``ego_is_comfortable`` parts.
_QUANTITIES = (
    ("lon_accel_mps2", ("min_lon_accel_mps2", "max_lon_accel_mps2")),  # ego_lon_acceleration
    ("lat_accel_mps2", ("max_abs_lat_accel_mps2",)),  # ego_lat_acceleration
    ("yaw_rate_rad_s", ("max_abs_yaw_rate_rad_s",)),  # ego_yaw_rate
    ("yaw_accel_rad_s2", ("max_abs_yaw_accel_rad_s2",)),  # ego_yaw_acceleration
    ("lon_jerk_mps3", ("max_abs_lon_jerk_mps3",)),  # ego_lon_jerk
    ("jerk_mps3", ("max_abs_jerk_mps3",)),  # ego_jerk (of the acceleration magnitude)
)

#: nuPlan ``state_extractors``: ``extract_ego_acceleration`` (Savitzky–Golay smoothing, window 8,
#: order 2), ``extract_ego_jerk`` (derivative, window 15, order 2), ``extract_ego_yaw_rate``
#: (its ``window_length`` is never passed on: ``approximate_derivatives``' default 5; order 2 for
#: the rate, ``ego_yaw_acceleration``'s order 3 for the second derivative), 8 decimals.
COMFORT_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {
        **EGO_DEFAULTS,
        **COMFORT_BOUNDS,
        "accel_window": 8,
        "accel_order": 2,
        "jerk_window": 15,
        "jerk_order": 2,
        "yaw_rate_window": 5,
        "yaw_rate_order": 2,
        "yaw_accel_window": 5,
        "yaw_accel_order": 3,
        "decimals": 8,
    }
)

#: fewest ego states comfort can be computed on (the yaw acceleration's order-3 polynomial
#: needs a window of 4; nuPlan raises below that).
COMFORT_MIN_STATES = 4


def phase_unwrap(heading_rad: F64) -> F64:
    """nuPlan ``phase_unwrap``: headings shifted by whole turns so that successive ones differ by
    at most π (``round`` of the step over 2π, as the devkit does it)."""
    two_pi = 2.0 * np.pi
    adjust = np.zeros_like(heading_rad)
    adjust[1:] = np.cumsum(np.round(np.diff(heading_rad) / two_pi))
    return np.asarray(heading_rad - two_pi * adjust, dtype=np.float64)


def approximate_derivative(y: F64, t_s: F64, *, window: int, order: int, deriv: int) -> F64:
    """nuPlan ``approximate_derivatives``: a Savitzky–Golay derivative with the window shrunk to
    the series, the sample spacing the *mean* time step."""
    window = min(window, len(t_s))
    if not order < window:
        msg = f"Savitzky-Golay order {order} needs a window above it, got {window} samples"
        raise MetricSkipped(msg)
    dt = np.diff(t_s)
    if not (dt > 0).all():
        raise MetricSkipped("comfort needs ego states with strictly increasing stamps")
    out = savgol_filter(y, window_length=window, polyorder=order, deriv=deriv, delta=dt.mean())
    return np.asarray(out, dtype=np.float64)


def body_accelerations(ego: EgoRun, params: Mapping[str, Any]) -> tuple[F64, F64, F64, bool]:
    """nuPlan's raw acceleration signals of each ego state, before smoothing:
    (``center_acceleration_2d.x``, ``center_acceleration_2d.y``, ``acceleration``, from_states).

    ``DynamicCarState.center_acceleration_2d`` shifts the rear-axle acceleration (in the ego
    frame) to the box centre with ``get_acceleration_shifted``, which adds ``d·ω² + d·α`` to x
    (d = rear axle → centre, ω the yaw rate, α the yaw acceleration — as the devkit writes it)
    and leaves y; ``acceleration`` is the magnitude of the rear-axle acceleration.  ω is the
    state's yaw rate, α its change since the previous state (nuPlan's kinematic bicycle model:
    ``(ω_next − ω) / dt``; 0 at the first state).

    States that carry no acceleration at all (every component 0 while the speed changes: a log
    without it) get one from their speeds and headings (longitudinal ``dv/dt``, lateral
    ``v·dψ/dt``); ``from_states`` is then False.
    """
    t = ego.t_s
    h = ego.heading_rad
    c, s = np.cos(h), np.sin(h)
    ax, ay = ego.accel_xy[:, 0], ego.accel_xy[:, 1]
    yaw_rate = ego.yaw_rate_rad_s
    from_states = bool(np.any(ego.accel_xy != 0.0)) or float(np.ptp(ego.speed_mps)) == 0.0
    if from_states:
        lon = ax * c + ay * s
        lat = -ax * s + ay * c
    else:
        lon = np.gradient(ego.speed_mps, t)
        yaw_rate = np.gradient(phase_unwrap(h), t)
        lat = ego.speed_mps * yaw_rate
    yaw_accel = np.zeros_like(yaw_rate)
    yaw_accel[1:] = np.diff(yaw_rate) / np.diff(t)
    d = float(params["ego_length_m"]) / 2.0 - float(params["rear_overhang_m"])
    center_x = lon + d * yaw_rate**2 + d * yaw_accel
    return center_x, lat, np.hypot(lon, lat), from_states


def comfort_kinematics(ego: EgoRun, params: Mapping[str, Any]) -> dict[str, F64] | None:
    """The six comfort signals of nuPlan's state extractors, per ego state; None with fewer than
    :data:`COMFORT_MIN_STATES` states.

    Accelerations: the states' own (:func:`body_accelerations`) smoothed by a Savitzky–Golay
    filter (``accel_window``, ``accel_order``; the window shrunk to the run), rounded to
    ``decimals``. Jerks: the derivative of the smoothed acceleration (``jerk_window``,
    ``jerk_order``). Yaw rate and acceleration: first and second derivative of the unwrapped
    heading (``yaw_rate_window``/``yaw_rate_order``, ``yaw_accel_window``/``yaw_accel_order``).
    The key ``acceleration_from_states`` is 1.0 when the states carried the acceleration.
    """
    n = len(ego)
    if n < COMFORT_MIN_STATES:
        return None
    t = ego.t_s
    if not (np.diff(t) > 0).all():
        raise MetricSkipped("comfort needs ego states with strictly increasing stamps")
    decimals = int(params["decimals"])
    raw_x, raw_y, raw_mag, from_states = body_accelerations(ego, params)
    window = min(int(params["accel_window"]), n)
    order = int(params["accel_order"])
    if not order < window:
        return None

    def smooth(a: F64) -> F64:
        out = savgol_filter(a, window_length=window, polyorder=order)
        return np.asarray(np.round(out, decimals=decimals), dtype=np.float64)

    def deriv(y: F64, prefix: str, k: int) -> F64:
        d = approximate_derivative(
            y, t, window=int(params[f"{prefix}_window"]), order=int(params[f"{prefix}_order"]),
            deriv=k,
        )  # fmt: skip
        return np.asarray(np.round(d, decimals=decimals), dtype=np.float64)

    lon, lat, mag = smooth(raw_x), smooth(raw_y), smooth(raw_mag)
    heading = phase_unwrap(ego.heading_rad)
    return {
        "lon_accel_mps2": lon,
        "lat_accel_mps2": lat,
        "yaw_rate_rad_s": deriv(heading, "yaw_rate", 1),
        "yaw_accel_rad_s2": deriv(heading, "yaw_accel", 2),
        "lon_jerk_mps3": deriv(lon, "jerk", 1),
        "jerk_mps3": deriv(mag, "jerk", 1),
        "acceleration_from_states": np.full(n, float(from_states)),
    }


def comfort_verdicts(
    kin: Mapping[str, F64], params: Mapping[str, Any]
) -> dict[str, npt.NDArray[np.bool_]]:
    """Per quantity, per frame: within nuPlan's bound — strictly (``WithinBoundMetricBase.
    _compute_within_bound``: ``min < value < max``; a bound on |x| is ``-b < x < b``)."""
    out = {}
    for key, bounds in _QUANTITIES:
        v = kin[key]
        if len(bounds) == 2:
            lo, hi = float(params[bounds[0]]), float(params[bounds[1]])
        else:
            hi = float(params[bounds[0]])
            lo = -hi
        out[key] = (v > lo) & (v < hi)
    return out


class Comfort(Metric):
    """nuPlan ``ego_is_comfortable``: every one of its six within-bound parts holds at every
    ego state — longitudinal acceleration in (−4.05, 2.40) m/s², |lateral acceleration| < 4.89
    m/s², |yaw rate| < 0.95 rad/s, |yaw acceleration| < 1.93 rad/s², |longitudinal jerk| < 4.13
    m/s³, |jerk| < 8.37 m/s³ (strict bounds), each signal smoothed as nuPlan's state extractors
    smooth it (:func:`comfort_kinematics`).

    Values: ``comfortable`` (headline, 1 or 0), ``uncomfortable_frames``, the extreme value of
    each quantity, ``<quantity>_within_bound`` (1 or 0: nuPlan's ``abs_<metric>_within_bounds``
    of each part), ``acceleration_from_states`` (1: the states' own acceleration; 0: the states
    carry none, it was taken from their speeds and headings), and in a log-backed closed loop
    ``deviated_frames``. Per frame each quantity. Bookmarks ``discomfort`` where a bound is
    first crossed (severity: the largest |value| past it).
    """

    name: ClassVar[str] = "comfort"
    version: ClassVar[str] = "2"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True  # the headline; per value in the result
    defaults: ClassVar[Mapping[str, Any]] = COMFORT_DEFAULTS

    def evaluate(self, data: EvalData) -> MetricResult:
        ego = ego_run(data, minimum=COMFORT_MIN_STATES)
        kin = comfort_kinematics(ego, self.params)
        if kin is None:
            msg = f"comfort needs at least {COMFORT_MIN_STATES} ego states"
            raise MetricSkipped(msg)
        ok = comfort_verdicts(kin, self.params)
        all_ok = np.logical_and.reduce(list(ok.values()))
        values: dict[str, float] = {
            "comfortable": float(all_ok.all()),
            "uncomfortable_frames": float((~all_ok).sum()),
        }
        units: dict[str, str] = {"uncomfortable_frames": "frames"}
        for key, _ in _QUANTITIES:
            v = kin[key]
            name = f"max_abs_{key}" if key != "lon_accel_mps2" else "min_lon_accel_mps2"
            values[name] = float(np.abs(v).max()) if name.startswith("max_abs") else float(v.min())
            units[name] = _unit(key)
        values["max_lon_accel_mps2"] = float(kin["lon_accel_mps2"].max())
        units["max_lon_accel_mps2"] = "m/s²"
        for key, good in ok.items():
            values[f"{key}_within_bound"] = float(good.all())
            units[f"{key}_within_bound"] = "score"
        values["acceleration_from_states"] = float(kin["acceleration_from_states"][0])
        units["acceleration_from_states"] = "flag"
        bookmarks = []
        for key, good in ok.items():
            bad = np.flatnonzero(~good)
            if bad.size:
                k = int(bad[0])
                bookmarks.append(
                    Bookmark(
                        frame_index=int(ego.frames[k]),
                        kind="discomfort",
                        detail=f"{key} {kin[key][k]:.2f} {_unit(key)} out of nuPlan's comfort bound",
                        severity=float(np.abs(kin[key][bad]).max()),
                    )
                )
        hib: dict[str, bool | None] = {
            k: False
            for k in values
            if k not in ("comfortable", "min_lon_accel_mps2") and not k.endswith("_within_bound")
        }
        hib["acceleration_from_states"] = None
        return with_deviation(
            MetricResult(
                values=values,
                units=units,
                higher_is_better=hib,
                per_frame={key: series(ego.frames, kin[key]) for key, _ in _QUANTITIES},
                bookmarks=bookmarks,
            ),
            data,
            ego.frames,
        )


def _unit(key: str) -> str:
    for suffix, unit in (
        ("_mps2", "m/s²"),
        ("_mps3", "m/s³"),
        ("_rad_s2", "rad/s²"),
        ("_rad_s", "rad/s"),
    ):
        if key.endswith(suffix):
            return unit
    return ""
