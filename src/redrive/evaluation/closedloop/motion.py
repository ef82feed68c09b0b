"""Ego progress along the logged route and comfort of the driven ego (nuPlan's definitions;
see ``docs/metrics.md``)."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from scipy.signal import savgol_filter

from redrive.evaluation._kinematics import project_on_polyline
from redrive.evaluation.base import Bookmark, EvalData, Metric, MetricResult, MetricSkipped
from redrive.evaluation.closedloop._common import EGO_DEFAULTS, EgoRun, ego_run, series
from redrive.evaluation.planning import COMFORT_BOUNDS
from redrive.types import Role

__all__ = ["Comfort", "EgoProgress", "comfort_kinematics", "comfort_verdicts", "progress_ratio"]

F64 = npt.NDArray[np.float64]

PROGRESS_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {**EGO_DEFAULTS, "score_progress_threshold_m": 2.0}
)


def progress_ratio(
    data: EvalData, params: Mapping[str, Any]
) -> tuple[float, float, float, F64, F64]:
    """(ratio, ego progress m, expert progress m, frames, ego arc length along the route m).

    The route is the logged ego's path (``logged_ego``; in open loop the ego itself); progress
    is the arc length of the last footprint centre minus that of the first, projected on it.
    nuPlan's ratio: 0 when the ego went back more than the threshold, else
    min(1, max(ego, thr) / max(expert, thr)), ``score_progress_threshold_m`` = 2 m.
    """
    ego = ego_run(data)
    logged = data.logged_ego()
    expert = EgoRun.of(logged) if logged else ego
    route = expert.centres(params)
    keep = np.concatenate([[True], np.hypot(*np.diff(route, axis=0).T) > 1e-6])
    route = route[keep]
    expert_m = float(np.hypot(*np.diff(route, axis=0).T).sum())
    arc, _, _ = project_on_polyline(ego.centres(params), route)
    ego_m = float(arc[-1] - arc[0])
    thr = float(params["score_progress_threshold_m"])
    ratio = 0.0 if ego_m < -thr else min(1.0, max(ego_m, thr) / max(expert_m, thr))
    return ratio, ego_m, expert_m, ego.frames.astype(np.float64), arc - arc[0]


class EgoProgress(Metric):
    """nuPlan ``ego_progress_along_expert_route``: how far the ego got along the logged route
    compared with the logged ego (the expert).

    Values: ``ego_progress_ratio`` (headline, [0, 1]), ``ego_progress_m``,
    ``expert_progress_m``, ``making_progress`` (nuPlan ``ego_is_making_progress``: ratio above
    ``min_progress_ratio`` 0.2). Per frame ``progress_m`` (arc length along the route).
    """

    name: ClassVar[str] = "ego_progress"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego"})
    unit: ClassVar[str] = "ratio"
    higher_is_better: ClassVar[bool] = True  # the headline; per value in the result
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {**PROGRESS_DEFAULTS, "min_progress_ratio": 0.2}
    )

    def evaluate(self, data: EvalData) -> MetricResult:
        ratio, ego_m, expert_m, frames, arc = progress_ratio(data, self.params)
        return MetricResult(
            values={
                "ego_progress_ratio": ratio,
                "ego_progress_m": ego_m,
                "expert_progress_m": expert_m,
                "making_progress": float(ratio > float(self.params["min_progress_ratio"])),
            },
            units={"ego_progress_m": "m", "expert_progress_m": "m", "making_progress": "score"},
            higher_is_better={"expert_progress_m": None},  # the logged ego's: the reference
            per_frame={"progress_m": series(frames.astype(np.int64), arc)},
        )


#: the comfort quantities: name → (kinematics key, bound key(s)).
_QUANTITIES = (
    ("lon_accel_mps2", ("min_lon_accel_mps2", "max_lon_accel_mps2")),
    ("lat_accel_mps2", ("max_abs_lat_accel_mps2",)),
    ("yaw_rate_rad_s", ("max_abs_yaw_rate_rad_s",)),
    ("yaw_accel_rad_s2", ("max_abs_yaw_accel_rad_s2",)),
    ("lon_jerk_mps3", ("max_abs_lon_jerk_mps3",)),
    ("jerk_mps3", ("max_abs_jerk_mps3",)),
)

COMFORT_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {**COMFORT_BOUNDS, "savgol_window": 15, "savgol_order": 2}
)


def comfort_kinematics(ego: EgoRun, params: Mapping[str, Any]) -> dict[str, F64] | None:
    """Accelerations, yaw rate/acceleration and jerks of the ego track by Savitzky-Golay
    derivatives (``savgol_window`` samples, shrunk to the track, order ``savgol_order``; as
    nuPlan's state extractors); None with fewer than 3 states."""
    n = len(ego)
    order = int(params["savgol_order"])
    window = min(int(params["savgol_window"]), n if n % 2 else n - 1)
    if n < 3 or window <= order:
        return None
    t = ego.t_s
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        return None

    def d(x: F64, k: int) -> F64:
        return np.asarray(savgol_filter(x, window, order, deriv=k, delta=dt), dtype=np.float64)

    ax, ay = d(ego.xy[:, 0], 2), d(ego.xy[:, 1], 2)
    h = np.unwrap(ego.heading_rad)
    c, s = np.cos(h), np.sin(h)
    lon = ax * c + ay * s
    return {
        "lon_accel_mps2": lon,
        "lat_accel_mps2": -ax * s + ay * c,
        "yaw_rate_rad_s": d(h, 1),
        "yaw_accel_rad_s2": d(h, 2),
        "lon_jerk_mps3": d(lon, 1),
        "jerk_mps3": d(np.hypot(ax, ay), 1),
    }


def comfort_verdicts(
    kin: Mapping[str, F64], params: Mapping[str, Any]
) -> dict[str, npt.NDArray[np.bool_]]:
    """Per quantity, per frame: within nuPlan's bound."""
    out = {}
    for key, bounds in _QUANTITIES:
        v = kin[key]
        if len(bounds) == 2:
            out[key] = (v >= float(params[bounds[0]])) & (v <= float(params[bounds[1]]))
        else:
            out[key] = np.abs(v) <= float(params[bounds[0]])
    return out


class Comfort(Metric):
    """nuPlan ``ego_is_comfortable``: longitudinal acceleration in [−4.05, 2.40] m/s²,
    |lateral acceleration| ≤ 4.89 m/s², |yaw rate| ≤ 0.95 rad/s, |yaw acceleration| ≤
    1.93 rad/s², |longitudinal jerk| ≤ 4.13 m/s³, |jerk| ≤ 8.37 m/s³ at every frame.

    Values: ``comfortable`` (headline, 1 or 0), ``uncomfortable_frames`` and the extreme value of
    each quantity. Per frame each quantity. Bookmarks ``discomfort`` where a bound is first
    crossed (severity: how far past the bound, relative).
    """

    name: ClassVar[str] = "comfort"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True  # the headline; per value in the result
    defaults: ClassVar[Mapping[str, Any]] = COMFORT_DEFAULTS

    def evaluate(self, data: EvalData) -> MetricResult:
        ego = ego_run(data, minimum=3)
        kin = comfort_kinematics(ego, self.params)
        if kin is None:
            raise MetricSkipped("comfort needs at least 3 ego states with increasing stamps")
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
        return MetricResult(
            values=values,
            units=units,
            higher_is_better={
                k: False for k in values if k not in ("comfortable", "min_lon_accel_mps2")
            },
            per_frame={key: series(ego.frames, kin[key]) for key, _ in _QUANTITIES},
            bookmarks=bookmarks,
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
