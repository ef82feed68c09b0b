"""Control metrics: how far the logged ego was from the plan the controller was given, and how
smooth the commands were.

**Open-loop replay.** In a replayed log the ego is *not* driven by these commands: the log's
ego moved as it was recorded. The tracking errors below therefore measure how far the logged
ego was from the plan; they are the controller's tracking error only in closed loop
(``CLOSED_LOOP`` mode, or a log recorded with this controller driving), and an open-loop run
stores them with subject ``log`` (``MetricResult.scores``: the ego's motion), so ``evaluate``,
``report`` and ``compare`` show them as the log's, not the controller's. The command
smoothness figures are the controller's own in either case.

Definitions, for each frame f where the control algorithm produced commands and the planner
(``planner`` parameter; by default the run's only planning algorithm) produced a plan P_f in
base_link of frame f: take the next logged ego state g after f (within ``max_gap_s``, and
within the plan's time span), at ``t = stamp_g − stamp_f``, put it into P_f's base_link with the
ego pose of frame f, and compare (the same cross-track/heading/speed errors as the
path-tracking literature, e.g. Snider, "Automatic Steering Methods for Autonomous Automobile
Path Tracking", CMU-RI-TR-09-08, 2009, §2):

* lateral error (m): signed distance from the plan's polyline (nearest point; positive = the ego
  is left of the plan);
* heading error (rad): ego heading − tangent heading of the plan at that nearest point, wrapped
  to [−π, π);
* speed error (m/s): ego speed over ground − the plan's speed at t (finite differences of the
  waypoints, :func:`redrive.evaluation._kinematics.path_kinematics`);
* longitudinal error (m): the ego's arc length along the plan − the plan's arc length at t
  (positive = ahead of the plan).

Each as RMSE and max |·| over the frames. Command smoothness: between consecutive commands
(consecutive frames with commands) the rates ``Δsteering_angle_rad / Δt`` (rad/s),
``Δthrottle / Δt`` and ``Δbrake / Δt`` (1/s), Δt from the frames' stamps; RMSE and max |·|.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from redrive.errors import ConfigError
from redrive.evaluation._kinematics import (
    EgoTrack,
    base_from_map_xy,
    path_kinematics,
    project_on_polyline,
    wrap_angle,
)
from redrive.evaluation.base import (
    SCORES_EGO,
    EvalData,
    Metric,
    MetricResult,
    MetricSkipped,
    Series,
)
from redrive.types import Role

__all__ = ["ControlMetrics", "planner_of"]

F64 = npt.NDArray[np.float64]


def planner_of(data: EvalData, requested: str = "") -> str:
    """The planning algorithm whose plans a controller followed: ``requested`` if given, else
    the run's only planning algorithm.

    Raises:
        ConfigError: none or several planning algorithms and none requested, or an unknown one.
    """
    planners = data.run.manifest.names(Role.PLANNING)
    if requested:
        if requested not in planners:
            msg = (
                f"{data.run.path}: no planning algorithm {requested!r} "
                f"(planning algorithms: {', '.join(planners) or 'none'})"
            )
            raise ConfigError(msg)
        return requested
    if len(planners) != 1:
        msg = (
            f"{data.run.path}: control metrics need the plan the controller followed, but the run "
            f"has {len(planners)} planning algorithms ({', '.join(planners) or 'none'}); "
            "pass planner=NAME"
        )
        raise MetricSkipped(msg)
    return planners[0]


def _rms(x: F64) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else math.nan


def _max_abs(x: F64) -> float:
    return float(np.max(np.abs(x))) if x.size else math.nan


class ControlMetrics(Metric):
    """Tracking error of the logged ego against the plan, and command smoothness (see the module
    docstring for the definitions and the open-loop caveat).

    Parameters (defaults): ``planner`` "" (the run's only planning algorithm), ``max_gap_s``
    0.5 (the next ego state must come within this time of the plan).

    Values: ``lateral_rmse_m`` (headline), ``lateral_max_m``, ``heading_rmse_rad``,
    ``heading_max_rad``, ``speed_rmse_mps``, ``speed_max_mps``, ``longitudinal_rmse_m``,
    ``longitudinal_max_m``, ``steering_rate_rmse_rad_s``, ``steering_rate_max_rad_s``,
    ``throttle_rate_rmse_1_s``, ``throttle_rate_max_1_s``, ``brake_rate_rmse_1_s``,
    ``brake_rate_max_1_s``, ``frames`` (frames with a tracking error). Per-frame series:
    ``lateral_error_m``, ``heading_error_rad``, ``speed_error_mps``, ``longitudinal_error_m``
    (at the plan's frame), ``steering_rate_rad_s``, ``throttle_rate_1_s``, ``brake_rate_1_s``
    (at the later frame of each pair).
    """

    name: ClassVar[str] = "control"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = Role.CONTROL
    # the plans it reads are the planner's, not the scored controller's: checked in evaluate
    needs: ClassVar[frozenset[str]] = frozenset({"commands", "ego"})
    unit: ClassVar[str] = "m"
    higher_is_better: ClassVar[bool] = False
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType({"planner": "", "max_gap_s": 0.5})

    def evaluate(self, data: EvalData) -> MetricResult:
        planner = planner_of(data, str(self.params["planner"]))
        paths = data.run.paths(planner)
        if not paths:
            msg = f"the planner {planner!r} produced no paths for the controller to follow"
            raise MetricSkipped(msg)
        commands = data.commands()
        ego = data.ego()
        track = EgoTrack.from_states(ego)
        stamps = _frame_stamps(data)
        max_gap_ns = round(float(self.params["max_gap_s"]) * 1e9)

        frames: list[int] = []
        errors: list[tuple[float, float, float, float]] = []
        for f in sorted(commands):
            path, now = paths.get(f), ego.get(f)
            if path is None or now is None:
                continue
            kin = path_kinematics(path.waypoints)
            if kin is None:
                continue
            later = np.flatnonzero(track.stamps_ns > now.stamp_ns)
            if later.size == 0:
                continue
            g = int(later[0])
            dt_ns = int(track.stamps_ns[g]) - path.stamp_ns
            t = dt_ns / 1e9
            if dt_ns <= 0 or dt_ns > max_gap_ns or t > kin.t_s[-1] + 1e-9:
                continue
            origin, heading = now.position[:2], float(now.heading_rad)
            pos = base_from_map_xy(track.xy[g], origin, heading)
            arc, lateral, tangent = project_on_polyline(pos, kin.xy)
            plan_at_t = np.array(
                [[np.interp(t, kin.t_s, kin.xy[:, 0]), np.interp(t, kin.t_s, kin.xy[:, 1])]]
            )
            plan_arc, _, _ = project_on_polyline(plan_at_t, kin.xy)
            heading_err = float(wrap_angle(track.heading_rad[g] - heading - tangent[0]))
            speed_err = float(track.speed_mps[g] - np.interp(t, kin.t_s, kin.speed_mps))
            frames.append(f)
            errors.append((float(lateral[0]), heading_err, speed_err, float(arc[0] - plan_arc[0])))
        err = np.array(errors, dtype=np.float64).reshape(-1, 4)
        idx = np.array(frames, dtype=np.int64)

        cmd_frames = np.array(sorted(commands), dtype=np.int64)
        cmd = np.array(
            [
                (
                    commands[int(f)].steering_angle_rad,
                    commands[int(f)].throttle,
                    commands[int(f)].brake,
                )
                for f in cmd_frames
            ],
            dtype=np.float64,
        ).reshape(-1, 3)
        cmd_t = np.array([stamps.get(int(f), -1) for f in cmd_frames], dtype=np.int64)
        if cmd_frames.size > 1:
            dt = np.diff(cmd_t).astype(np.float64) / 1e9
            ok = dt > 0
            rates = (np.diff(cmd, axis=0)[ok]) / dt[ok, None]
            rate_frames = cmd_frames[1:][ok]
        else:
            rates = np.zeros((0, 3))
            rate_frames = np.zeros(0, dtype=np.int64)

        values = {
            "lateral_rmse_m": _rms(err[:, 0]),
            "lateral_max_m": _max_abs(err[:, 0]),
            "heading_rmse_rad": _rms(err[:, 1]),
            "heading_max_rad": _max_abs(err[:, 1]),
            "speed_rmse_mps": _rms(err[:, 2]),
            "speed_max_mps": _max_abs(err[:, 2]),
            "longitudinal_rmse_m": _rms(err[:, 3]),
            "longitudinal_max_m": _max_abs(err[:, 3]),
            "steering_rate_rmse_rad_s": _rms(rates[:, 0]),
            "steering_rate_max_rad_s": _max_abs(rates[:, 0]),
            "throttle_rate_rmse_1_s": _rms(rates[:, 1]),
            "throttle_rate_max_1_s": _max_abs(rates[:, 1]),
            "brake_rate_rmse_1_s": _rms(rates[:, 2]),
            "brake_rate_max_1_s": _max_abs(rates[:, 2]),
            "frames": float(idx.size),
        }
        units = {k: _unit(k) for k in values}
        per_frame: dict[str, Series] = {
            "lateral_error_m": (idx, err[:, 0]),
            "heading_error_rad": (idx, err[:, 1]),
            "speed_error_mps": (idx, err[:, 2]),
            "longitudinal_error_m": (idx, err[:, 3]),
            "steering_rate_rad_s": (rate_frames, rates[:, 0]),
            "throttle_rate_1_s": (rate_frames, rates[:, 1]),
            "brake_rate_1_s": (rate_frames, rates[:, 2]),
        }
        # the errors and rates are lower-is-better (the metric's direction); the frame count is
        # neither.  The tracking errors are of the ego's motion: in open loop the logged ego's
        # (the log's, whatever the controller commanded); the rates are the controller's own.
        tracking = {
            "lateral": "lateral_error_m",
            "heading": "heading_error_rad",
            "speed": "speed_error_mps",
            "longitudinal": "longitudinal_error_m",
        }
        scores = dict.fromkeys(tracking.values(), SCORES_EGO)
        statistics: dict[str, tuple[str, str]] = {}
        for prefix, series_name in (
            *tracking.items(),
            ("steering_rate", "steering_rate_rad_s"),
            ("throttle_rate", "throttle_rate_1_s"),
            ("brake_rate", "brake_rate_1_s"),
        ):
            for key in values:
                if key.startswith(prefix + "_rmse"):
                    statistics[key] = (series_name, "rms")
                elif key.startswith(prefix + "_max"):
                    statistics[key] = (series_name, "max_abs")
                else:
                    continue
                if series_name in tracking.values():
                    scores[key] = SCORES_EGO
        scores["frames"] = SCORES_EGO
        return MetricResult(
            values=values,
            units=units,
            higher_is_better={"frames": None},
            per_frame=per_frame,
            scores=scores,
            statistics=statistics,
        )


def _frame_stamps(data: EvalData) -> dict[int, int]:
    table = data.frames()
    return dict(
        zip(
            (int(v) for v in table.column("frame_index").to_pylist()),
            (int(v) for v in table.column("stamp_ns").to_pylist()),
            strict=True,
        )
    )


def _unit(key: str) -> str:
    if key == "frames":
        return "frames"
    for suffix, unit in (("_rad_s", "rad/s"), ("_1_s", "1/s"), ("_mps", "m/s"), ("_rad", "rad")):
        if key.endswith(suffix):
            return unit
    return "m"
