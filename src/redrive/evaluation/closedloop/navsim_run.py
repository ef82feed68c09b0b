"""NAVSIM's pseudo-simulation on a run: every 0.5 s the planner's trajectory is simulated from
the ego's state there and scored against what the log's agents did next.

One NAVSIM scene per proposal (``navsim/evaluate/pdm_score.py`` ``pdm_score`` /
``pdm_score_from_interpolated_trajectory``; v2's ``run_pdm_score_one_stage.py``
``compute_final_scores`` and ``scoring/scene_aggregator.py`` for the two-frame extended comfort).
The planner's path (positions in the base_link of its frame) gets NAVSIM's inputs: headings
from the direction of travel between waypoints, the ego's state as the first pose, sampled
at 10 Hz over 4 s (held at its last pose if shorter).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.evaluation.base import EvalData, MetricSkipped
from redrive.evaluation.closedloop._common import EGO_DEFAULTS, require_road, scene
from redrive.evaluation.closedloop.navsim_closed import (
    PDM_CLOSED_DEFAULTS,
    forecast_observation,
    pdm_closed_candidates,
    pdm_closed_choice,
)
from redrive.evaluation.closedloop.navsim_comfort import two_frame_extended_comfort
from redrive.evaluation.closedloop.navsim_scene import (
    MapContext,
    Occupancy,
    TrackInfo,
    interpolate_observation,
    lane_polygons,
    map_context,
    red_light_polygons,
)
from redrive.evaluation.closedloop.navsim_score import ego_coords, score_proposals
from redrive.evaluation.closedloop.navsim_sim import (
    STATE_SIZE,
    interpolate_poses,
    simulate_proposals,
)
from redrive.types import LightState, ObjectColumns, PlannedPath, RoadMap, VehicleState

F64 = npt.NDArray[np.float64]

__all__ = ["SceneScore", "navsim_scenes", "planner_poses", "state_array"]

V1_KEYS = ("nc", "dac", "ep", "ttc", "c", "ddc")
V2_KEYS = ("nc", "dac", "ddc", "tlc", "ep", "ttc", "lk", "hc")


@dataclass(frozen=True, slots=True, kw_only=True)
class SceneScore:
    """One scored proposal: its frame, the sub-scores (``V1_KEYS`` / ``V2_KEYS``, v2 with
    ``ec``, NaN for the first of a sequence), the PDM-Closed reference's raw progress and the
    score."""

    frame: int
    stamp_ns: int
    parts: Mapping[str, float]
    score: float
    simulated: F64


def state_array(state: VehicleState) -> F64:
    """NAVSIM's initial ego state (``ego_status_to_ego_state``): rear-axle pose, body-frame
    velocity and acceleration; steering angle, its rate, angular velocity and acceleration 0."""
    h = float(state.heading_rad)
    c, s = math.cos(h), math.sin(h)
    out = np.zeros(STATE_SIZE, dtype=np.float64)
    out[0:2] = state.position[:2]
    out[2] = h
    vx, vy = float(state.velocity[0]), float(state.velocity[1])
    ax, ay = float(state.acceleration[0]), float(state.acceleration[1])
    out[3:5] = (c * vx + s * vy, -s * vx + c * vy)
    out[5:7] = (c * ax + s * ay, -s * ax + c * ay)
    return out


def _headings(xy: F64, first_rad: float) -> F64:
    """Direction of travel into each point (the previous heading where it does not move)."""
    out = np.empty(xy.shape[0], dtype=np.float64)
    prev_xy = np.zeros(2)
    prev_h = first_rad
    for i, p in enumerate(xy):
        d = p - prev_xy
        if float(np.hypot(*d)) > 1e-3:
            prev_h = math.atan2(float(d[1]), float(d[0]))
        out[i] = prev_h
        prev_xy = p
    return out


def planner_poses(path: PlannedPath, ego: VehicleState, sim: Mapping[str, Any]) -> F64 | None:
    """The path as NAVSIM's ``transform_trajectory`` + ``get_trajectory_as_array`` see a
    planner's output: (N+1, 3) map-frame poses every ``interval_s``; None without a waypoint
    after its start or in a frame other than ``base_link`` (of the plan's frame) or ``map``."""
    wp = path.waypoints
    sel = wp[:, 3] > 1e-9
    if not sel.any() or path.frame_id not in ("base_link", "map"):
        return None
    h0 = float(ego.heading_rad)
    c, s = math.cos(h0), math.sin(h0)
    if path.frame_id == "map":  # into base_link of the plan's frame first
        d = wp[sel, :2] - ego.position[:2]
        local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
    else:
        local = wp[sel, :2]
    rel_t = wp[sel, 3]
    h_local = _headings(local, 0.0)
    world = np.column_stack([c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]])
    world += ego.position[:2]
    poses = np.vstack(
        [[ego.position[0], ego.position[1], h0], np.column_stack([world, h_local + h0])]
    )
    times = np.concatenate([[0.0], rel_t])
    n = int(sim["num_poses"])
    return interpolate_poses(
        times, poses, query_s=np.arange(n + 1, dtype=np.float64) * float(sim["interval_s"])
    )


class _Track:
    """A logged ego track interpolated in time (map frame)."""

    def __init__(self, states: Mapping[int, VehicleState]) -> None:
        items = sorted(states.values(), key=lambda s: s.stamp_ns)
        self.t_ns = np.array([s.stamp_ns for s in items], dtype=np.int64)
        self.arr = np.stack([state_array(s) for s in items]) if items else np.zeros((0, STATE_SIZE))

    def covers(self, t0_ns: int, t1_ns: int) -> bool:
        return bool(self.t_ns.size) and self.t_ns[0] <= t0_ns and self.t_ns[-1] >= t1_ns

    def at(self, stamps_ns: F64) -> F64:
        t = (self.t_ns - self.t_ns[0]) / 1e9
        q = (np.asarray(stamps_ns, dtype=np.float64) - self.t_ns[0]) / 1e9
        out = np.zeros((q.size, STATE_SIZE), dtype=np.float64)
        for k in range(7):
            col = np.unwrap(self.arr[:, k]) if k == 2 else self.arr[:, k]
            out[:, k] = np.interp(q, t, col)
        out[:, 2] = np.arctan2(np.sin(out[:, 2]), np.cos(out[:, 2]))
        return out


def _visited_lanes(data: EvalData, logged: _Track) -> list[str]:
    """The lanes the logged ego drives, in order (the route: NAVSIM's route roadblocks)."""
    road = require_road(data)
    if not logged.t_ns.size:
        return []
    inside = road.lanes_containing(logged.arr[:, :2])  # L, K
    out: list[str] = []
    for k in range(inside.shape[1]):
        for i in np.flatnonzero(inside[:, k]).tolist():
            lane = road.lanes[i]
            tangent = road.lane_tangent(i, logged.arr[k, :2])
            h = logged.arr[k, 2]
            if tangent[0] * math.cos(h) + tangent[1] * math.sin(h) > 0 and lane.lane_id not in out:
                out.append(lane.lane_id)
    return out


def _extend_route(road_map: RoadMap, visited: list[str], *, length_m: float) -> list[str]:
    """The route on past the last lane the logged ego drove, along the map's successors (the
    one that turns least), for ``length_m``: NAVSIM's route comes from the scenario's mission
    and goes on past the log; a log alone does not say where the drive was going."""
    if not visited:
        return visited
    lanes = {lane.lane_id: lane for lane in road_map.lanes}
    out = list(visited)
    cur = lanes.get(visited[-1])
    ahead = 0.0
    while cur is not None and ahead < length_m and len(out) < len(visited) + 32:
        d_end = cur.centerline[-1] - cur.centerline[-2]
        h_end = math.atan2(float(d_end[1]), float(d_end[0]))
        best: tuple[float, str] | None = None
        for sid in cur.successors:
            nxt = lanes.get(sid)
            if nxt is None or sid in out:
                continue
            d0 = nxt.centerline[-1] - nxt.centerline[0]
            turn = abs(math.remainder(math.atan2(float(d0[1]), float(d0[0])) - h_end, math.tau))
            if best is None or turn < best[0]:
                best = (turn, sid)
        if best is None:
            break
        out.append(best[1])
        cur = lanes[best[1]]
        ahead += cur.length_m
    return out


@dataclass(frozen=True, slots=True, kw_only=True)
class _Frame:
    """What both versions share at one scene: the map around the ego, its initial state, the
    simulated planner / human trajectories and PDM-Closed's simulated proposals."""

    frame: int
    stamp_ns: int
    ctx: MapContext
    init: F64
    pred: F64
    human: F64 | None
    candidates: F64
    forecast: tuple[list[Occupancy], dict[str, TrackInfo], frozenset[str]]
    history: F64 | None


@dataclass(frozen=True, slots=True, kw_only=True)
class _Run:
    frames: tuple[_Frame, ...]
    samples_at: Callable[[int, int], list[ObjectColumns | None]]  # the 2-Hz samples after a stamp
    vehicle: Mapping[str, float]


def _shared(data: EvalData, p: Mapping[str, Any]) -> _Run:
    """The run's scenes simulated once (cached on ``data`` per parameters)."""
    key = "navsim:" + ",".join(f"{k}={p[k]!r}" for k in sorted(_SHARED_KEYS))
    cached = data._cache.get(key)
    if isinstance(cached, _Run):
        return cached
    require_road(data)  # MetricSkipped without a map
    road_map = data.road_map()
    assert road_map is not None
    paths = data.paths()
    if not paths:
        raise MetricSkipped("the planner made no trajectory in this run")
    ego_states = data.ego()
    logged = _Track(data.logged_ego() or ego_states)
    sc = scene(data, {k: p[k] for k in EGO_DEFAULTS})
    frames = sorted(ego_states, key=lambda f: ego_states[f].stamp_ns)
    stamps = np.array([ego_states[f].stamp_ns for f in frames], dtype=np.int64)
    period_ns = float(np.median(np.diff(stamps))) if stamps.size > 1 else 1e8
    tol_ns = max(period_ns / 2.0, 1e6)
    sim = {k: p[k] for k in _SIM_KEYS}
    dt = float(p["interval_s"])
    n = int(p["num_poses"]) + 1
    horizon_ns = round((n - 1) * dt * 1e9)
    length = float(p["ego_length_m"])
    vehicle = {
        "half_length_m": length / 2.0,
        "half_width_m": float(p["ego_width_m"]) / 2.0,
        "rear_axle_to_center_m": length / 2.0 - float(p["rear_overhang_m"]),
    }
    visited = _extend_route(
        road_map, _visited_lanes(data, logged), length_m=float(p["route_extension_m"])
    )
    lanes = lane_polygons(road_map)

    def frame_at(t_ns: float) -> int | None:
        i = int(np.searchsorted(stamps, t_ns))
        near = [j for j in (i - 1, i) if 0 <= j < stamps.size and abs(stamps[j] - t_ns) <= tol_ns]
        return frames[min(near, key=lambda j: abs(stamps[j] - t_ns))] if near else None

    def samples_at(stamp_ns: int, count: int) -> list[ObjectColumns | None]:
        out = []
        for k in range(count):
            fk = frame_at(stamp_ns + k * 0.5e9)
            out.append(None if fk is None else sc.objects.get(fk))
        return out

    scenes: list[_Frame] = []
    next_ns = -math.inf
    interval_ns = float(p["scene_interval_s"]) * 1e9
    for f in frames:
        s0 = ego_states[f].stamp_ns
        if f not in paths or s0 < next_ns - tol_ns or stamps[-1] < s0 + horizon_ns - tol_ns:
            continue
        ego = ego_states[f]
        pred = planner_poses(paths[f], ego, sim)
        objs_now = sc.objects.get(f)
        if pred is None or objs_now is None:
            continue
        ctx = map_context(
            road_map,
            ego_xy=np.asarray(ego.position[:2], dtype=np.float64),
            ego_heading_rad=float(ego.heading_rad),
            visited_lane_ids=visited,
            radius_m=float(p["map_radius_m"]),
            lanes=lanes,
        )
        if ctx.centerline is None:
            continue
        next_ns = s0 + interval_ns
        init = state_array(ego)
        box = ego_coords(init[None, None], **vehicle)[0, 0]
        forecast = forecast_observation(
            objs_now, ego_center_xy=box[4], ego_box=box[:4], n_steps=n + 11, interval_s=dt, p=p
        )
        candidates = pdm_closed_candidates(
            init,
            ctx=ctx,
            obs=forecast[0],
            unique=forecast[1],
            collided=forecast[2],
            red_lights=None,
            vehicle=vehicle,
            sim=sim,
            p=p,
        )
        human_poses = None
        if logged.covers(s0, s0 + horizon_ns):
            fut = logged.at(s0 + np.arange(1, 9, dtype=np.float64) * 0.5e9)
            human = PlannedPath(stamp_ns=s0, waypoints=_local_waypoints(fut, ego))
            human_poses = planner_poses(human, ego, sim)
        batch = [candidates, pred[None]] + ([human_poses[None]] if human_poses is not None else [])
        simulated = simulate_proposals(np.concatenate(batch), init, p=sim)
        m = candidates.shape[0]
        history = None
        if logged.covers(s0 - round(1.5e9), s0):
            knots = logged.at(np.array([s0 - 1.5e9, s0 - 1.0e9, s0 - 0.5e9]))
            history = np.zeros((9, STATE_SIZE), dtype=np.float64)
            for k in range(7):
                col = np.unwrap(knots[:, k]) if k == 2 else knots[:, k]
                history[:, k] = np.interp(np.arange(9) * 0.1, [0.0, 0.5, 1.0], col)
        scenes.append(
            _Frame(
                frame=f,
                stamp_ns=s0,
                ctx=ctx,
                init=init,
                pred=simulated[m],
                human=simulated[m + 1] if human_poses is not None else None,
                candidates=simulated[:m],
                forecast=forecast,
                history=history,
            )
        )
    run = _Run(frames=tuple(scenes), samples_at=samples_at, vehicle=vehicle)
    data._cache[key] = run
    return run


def navsim_scenes(
    data: EvalData,
    *,
    version: str,
    params: Mapping[str, Any],
    light_states: Mapping[int, Mapping[str, LightState]] | None = None,
) -> list[SceneScore]:
    """Score the run's planner every ``scene_interval_s`` with NAVSIM ``version`` ("v1" PDMS,
    "v2" EPDMS).  ``light_states``: frame → light id → state (v2's traffic-light compliance;
    None: no light is known to be red)."""
    p = params
    shared = _shared(data, p)
    road_map = data.road_map()
    assert road_map is not None
    ego_states = data.ego()
    dt = float(p["interval_s"])
    n = int(p["num_poses"]) + 1
    obs_steps = n + (10 if version == "v1" else 0)  # v1.1 observes 5 s for its TTC
    n_samples = round((obs_steps - 1) * dt / 0.5) + 1
    known = sorted((ego_states[f].stamp_ns, f) for f in (light_states or {}) if f in ego_states)

    def lights_at(t_ns: float) -> Mapping[str, LightState] | None:
        if not light_states:
            return None
        i = bisect.bisect_right(known, (t_ns + 1e6, math.inf))
        return light_states[known[i - 1][1]] if i else None

    out: list[SceneScore] = []
    vehicle = shared.vehicle
    for fr in shared.frames:
        obs, unique = interpolate_observation(
            shared.samples_at(fr.stamp_ns, n_samples), n_steps=obs_steps, interval_s=dt
        )
        red = None
        if version == "v2":
            red = red_light_polygons(
                road_map, fr.ctx, [lights_at(fr.stamp_ns + i * dt * 1e9) for i in range(n)]
            )
        fobs, funique, collided = fr.forecast
        best = pdm_closed_choice(
            fr.candidates,
            ctx=fr.ctx,
            obs=fobs,
            unique=funique,
            collided=collided,
            red_lights=None if red is None else [red[0]] * len(fobs),
            version=version,
            vehicle=vehicle,
            interval_s=dt,
        )
        kw: dict[str, Any] = {
            "obs": obs,
            "unique": unique,
            "ctx": fr.ctx,
            "version": version,
            "vehicle": vehicle,
            "interval_s": dt,
            "red_lights": red,
            "params": p,
        }
        both = np.stack([fr.candidates[best], fr.pred])
        scores = score_proposals(both, history=fr.history if version == "v2" else None, **kw)
        keys = V1_KEYS if version == "v1" else V2_KEYS
        parts = {k: float(scores[k][1]) for k in keys}
        if version == "v2" and bool(p["human_penalty_filter"]) and fr.human is not None:
            hs = score_proposals(fr.human[None], **kw)
            for k in keys:
                if float(hs[k][0]) == 0.0:
                    parts[k] = 1.0
        out.append(
            SceneScore(
                frame=fr.frame, stamp_ns=fr.stamp_ns, parts=parts, score=math.nan, simulated=fr.pred
            )
        )
    return _finalise(out, version=version, dt=dt)


def _local_waypoints(states: F64, ego: VehicleState) -> F64:
    h = float(ego.heading_rad)
    c, s = math.cos(h), math.sin(h)
    d = states[:, :2] - ego.position[:2]
    t = np.arange(1, states.shape[0] + 1) * 0.5
    return np.column_stack(
        [c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], np.zeros(len(t)), t]
    )


def _finalise(scenes: Sequence[SceneScore], *, version: str, dt: float) -> list[SceneScore]:
    """The score of each scene: v1.1's from its parts; v2's with the two-frame extended comfort
    against the previous scene within 0.55 s (``infer_start_adjacent_mapping``), weight 2 of 16,
    left out (weights 14) for the first of a sequence (``compute_final_scores``)."""
    out: list[SceneScore] = []
    for i, sc in enumerate(scenes):
        parts = dict(sc.parts)
        if version == "v1":
            weighted = (5 * parts["ep"] + 5 * parts["ttc"] + 2 * parts["c"] + 0 * parts["ddc"]) / 12
            score = parts["nc"] * parts["dac"] * weighted
        else:
            ec = math.nan
            if i > 0:
                gap = (sc.stamp_ns - scenes[i - 1].stamp_ns) / 1e9
                if 0 < gap <= 0.55:
                    ec = two_frame_extended_comfort(
                        sc.simulated, scenes[i - 1].simulated, interval_s=dt, gap_s=gap
                    )
            parts["ec"] = ec
            total = 5 * parts["ep"] + 5 * parts["ttc"] + 2 * parts["lk"] + 2 * parts["hc"]
            weight = 14.0
            if not math.isnan(ec):
                total += 2 * ec
                weight = 16.0
            multi = parts["nc"] * parts["dac"] * parts["ddc"] * parts["tlc"]
            score = multi * total / weight
        out.append(
            SceneScore(
                frame=sc.frame,
                stamp_ns=sc.stamp_ns,
                parts=parts,
                score=score,
                simulated=sc.simulated,
            )
        )
    return out


_SIM_KEYS = frozenset(
    {
        "interval_s",
        "num_poses",
        "wheel_base_m",
        "q_longitudinal",
        "r_longitudinal",
        "q_lateral",
        "r_lateral",
        "tracking_horizon",
        "jerk_penalty",
        "curvature_rate_penalty",
        "stopping_proportional_gain",
        "stopping_velocity_mps",
        "max_steering_angle_rad",
        "accel_time_constant_s",
        "steering_angle_time_constant_s",
    }
)
_SHARED_KEYS = (
    _SIM_KEYS | frozenset(EGO_DEFAULTS) | frozenset(PDM_CLOSED_DEFAULTS) | {"scene_interval_s"}
)
