"""PDM-Closed, the reference planner NAVSIM measures ego progress against.

Follows NAVSIM's ``pdm_planner`` (``abstract_pdm_closed_planner.py``
``AbstractPDMClosedPlanner._get_closed_loop_trajectory``, ``proposal/pdm_generator.py``
``PDMGenerator``, ``proposal/batch_idm_policy.py`` ``BatchIDMPolicy``,
``observation/pdm_observation.py`` ``PDMObservation.update``) with the metric cache's
configuration (``metric_cache_processor.py``: speed-limit fractions 0.2 … 1.0, fallback target
15 m/s, minimum gap 1 m, headway 1.5 s, acceleration 1.5 m/s², deceleration 3 m/s², lateral
offsets ±1 m, map radius 100 m): 15 IDM proposals along the route's centreline and its two
offsets, each forecast against the current boxes at constant velocity, simulated and scored
like the planner's trajectory, and the best one kept.  Its quirks are kept: the leading agent
is refreshed every second step, so at the first step it is the zero-initialised row (progress
0: the IDM brakes there), and one leading-agent row is shared by the proposals of a step.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely
from shapely.ops import substring

from redrive.evaluation._kinematics import rectangle_corners
from redrive.evaluation.closedloop.navsim_scene import MapContext, Occupancy, TrackInfo
from redrive.evaluation.closedloop.navsim_score import ego_coords, score_proposals
from redrive.evaluation.closedloop.navsim_sim import (
    STATE_SIZE,
    VELOCITY_X,
    X,
    Y,
    normalize_angle,
)
from redrive.types import ObjectColumns

F64 = npt.NDArray[np.float64]

__all__ = [
    "PDM_CLOSED_DEFAULTS",
    "forecast_observation",
    "pdm_closed_candidates",
    "pdm_closed_choice",
]

PDM_CLOSED_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {
        "speed_limit_fractions": (0.2, 0.4, 0.6, 0.8, 1.0),
        "fallback_target_velocity_mps": 15.0,
        "min_gap_to_lead_agent_m": 1.0,
        "headway_time_s": 1.5,
        "idm_accel_max_mps2": 1.5,
        "idm_decel_max_mps2": 3.0,
        "lateral_offsets_m": (-1.0, 1.0),
        "map_radius_m": 100.0,
        "leading_agent_update_rate": 2,
        "observation_sample_res": 2,
    }
)
_IDM_EXPONENT = 10  # BatchIDMPolicy.propagate's acceleration_exponent


def forecast_observation(
    objs: ObjectColumns,
    *,
    ego_center_xy: F64,
    ego_box: F64,
    n_steps: int,
    interval_s: float,
    p: Mapping[str, Any],
) -> tuple[list[Occupancy], dict[str, TrackInfo], frozenset[str]]:
    """``PDMObservation.update``: the boxes within the map radius, agents moved at their
    velocity, others fixed, sampled every ``observation_sample_res`` steps; and the tokens
    the ego box ``ego_box`` (4, 2) touches now (ignored by the scorer)."""
    from redrive.evaluation._kinematics import rectangles_overlap
    from redrive.evaluation.closedloop._common import AGENT_CLASSES

    keep = np.hypot(*(objs.center_m[:, :2] - ego_center_xy).T) <= float(p["map_radius_m"])
    idx = np.flatnonzero(keep)
    tokens = tuple(
        str(int(objs.object_id[m])) if int(objs.object_id[m]) >= 0 else f"now:{m}" for m in idx
    )
    agent = np.array([objs.object_class[m] in AGENT_CLASSES for m in idx], dtype=bool)
    vel = objs.velocity_mps[idx, :2] * agent[:, None]
    unique = {
        tok: TrackInfo(
            object_class=objs.object_class[m],
            velocity_xy=np.asarray(objs.velocity_mps[m, :2], dtype=np.float64).copy(),
            heading_rad=float(objs.yaw_rad[m]),
        )
        for tok, m in zip(tokens, idx.tolist(), strict=True)
    }
    res = int(p["observation_sample_res"])
    n_samples = (n_steps - 1) // res + 1
    dts = np.arange(n_samples, dtype=np.float64) * res * interval_s
    centres = objs.center_m[idx, :2][None] + dts[:, None, None] * vel[None]  # S, M, 2
    corners = rectangle_corners(
        centres.reshape(-1, 2),
        np.tile(objs.yaw_rad[idx], n_samples),
        np.tile(objs.size_m[idx, 0], n_samples),
        np.tile(objs.size_m[idx, 1], n_samples),
    ).reshape(n_samples, idx.size, 4, 2)
    samples = [Occupancy(tokens=tokens, corners=corners[k]) for k in range(n_samples)]
    out = [samples[i // res] for i in range(n_steps)]
    touching = rectangles_overlap(ego_box[None], out[0].corners) if idx.size else np.zeros(0, bool)
    collided = frozenset(tok for tok, t in zip(tokens, touching.tolist(), strict=True) if t)
    return out, unique, collided


class _Path:
    """``PDMPath``: (x, y, heading) interpolated linearly along the arc length."""

    def __init__(self, xyh: F64) -> None:
        self.xyh = xyh
        seg = np.hypot(*np.diff(xyh[:, :2], axis=0).T)
        self.progress = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(self.progress[-1])
        self.line = shapely.LineString(xyh[:, :2])

    def interpolate(self, s: F64) -> F64:
        d = np.clip(s, 1e-5, self.length)
        out = np.empty((np.size(d), 3), dtype=np.float64)
        for k in range(3):
            out[:, k] = np.interp(d, self.progress, self.xyh[:, k])
        out[:, 2] = normalize_angle(out[:, 2])
        return out

    def project(self, xy: F64) -> F64:
        pts = shapely.points(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        return np.asarray(shapely.line_locate_point(self.line, pts), dtype=np.float64)

    def corridor(self, start: float, end: float, half_width_m: float) -> shapely.Geometry:
        a, b = np.clip([start, end], 0.0, self.length)
        inside = (a <= self.progress) & (self.progress <= b)
        if inside.sum() > 1:
            line = shapely.LineString(self.xyh[inside, :2])
        else:
            line = substring(self.line, a, b)
        return shapely.buffer(line, half_width_m, cap_style="square")


def _offset(xyh: F64, lateral_m: float) -> F64:
    """``parallel_discrete_path``: each pose moved ``lateral_m`` to its left."""
    out = xyh.copy()
    out[:, 0] += lateral_m * np.cos(xyh[:, 2] + np.pi / 2)
    out[:, 1] += lateral_m * np.sin(xyh[:, 2] + np.pi / 2)
    return out


def _idm_step(
    x: F64, v: F64, *, lead: F64, target: F64, p: Mapping[str, Any], dt: float
) -> tuple[F64, F64]:
    """``BatchIDMPolicy.propagate``."""
    gap0 = float(p["min_gap_to_lead_agent_m"])
    headway = float(p["headway_time_s"])
    a_max, d_max = float(p["idm_accel_max_mps2"]), float(p["idm_decel_max_mps2"])
    s_star = gap0 + v * headway + v * (v - lead[:, 1]) / (2 * np.sqrt(a_max * d_max))
    s_alpha = np.maximum(lead[:, 0] - x - lead[:, 2], gap0)
    v_dot = a_max * (1 - (v / target) ** _IDM_EXPONENT - (s_star / s_alpha) ** 2)
    v_dot = np.clip(v_dot, -d_max, a_max)
    return x + dt * v, v + dt * v_dot


def pdm_closed_candidates(
    initial_state: F64,
    *,
    ctx: MapContext,
    obs: list[Occupancy],
    unique: Mapping[str, TrackInfo],
    collided: frozenset[str],
    red_lights: list[list[shapely.Polygon]] | None,
    vehicle: Mapping[str, float],
    sim: Mapping[str, Any],
    p: Mapping[str, Any] = PDM_CLOSED_DEFAULTS,
) -> F64:
    """PDM-Closed's proposals (P, N+1, 3) from the ego state ``initial_state`` (11,)
    (``PDMGenerator.generate_proposals``: path-major, the IDM policies within a path)."""
    if ctx.centerline_xyh is None:
        msg = "PDM-Closed needs the route's centreline"
        raise ValueError(msg)
    dt = float(sim["interval_s"])
    n = int(sim["num_poses"]) + 1
    limit = ctx.centerline_speed_limit_mps
    fractions = np.asarray(p["speed_limit_fractions"], dtype=np.float64)
    targets = fractions * (float(p["fallback_target_velocity_mps"]) if limit is None else limit)
    paths = [_Path(ctx.centerline_xyh)] + [
        _Path(_offset(ctx.centerline_xyh, float(o))) for o in p["lateral_offsets_m"]
    ]
    n_lon = targets.size
    half_l, half_w = vehicle["half_length_m"], vehicle["half_width_m"]
    r2c = vehicle["rear_axle_to_center_m"]
    poses = np.zeros((len(paths) * n_lon, n, 3), dtype=np.float64)
    update = int(p["leading_agent_update_rate"])
    red_polys = list(red_lights[0]) if red_lights else []
    steps = [ti for ti in range(1, n) if ti % update == 0]
    tokens = obs[0].tokens if obs else ()
    keep = np.array([tok not in collided for tok in tokens], dtype=bool)
    info: list[tuple[float | None, float]] = []
    for tok in tokens:
        track = unique[tok]
        info.append(
            (float(np.hypot(*track.velocity_xy)) if track.is_agent else 0.0, track.heading_rad)
        )
    info += [(None, 0.0)] * len(red_polys)
    n_box = len(tokens)
    corners = np.stack([obs[ti].corners for ti in steps]) if steps else np.zeros((0, n_box, 4, 2))
    boxes = shapely.polygons(corners) if n_box else np.zeros((len(steps), 0), dtype=object)
    reds = np.array(red_polys, dtype=object).reshape(1, -1).repeat(len(steps), axis=0)
    polys = np.concatenate([boxes, reds], axis=1)
    centres = np.concatenate(
        [
            corners.mean(axis=2),
            shapely.get_coordinates(shapely.centroid(reds.reshape(-1))).reshape(len(steps), -1, 2),
        ],
        axis=1,
    )
    valid = np.concatenate(
        [np.broadcast_to(keep, (len(steps), n_box)), np.ones(reds.shape, bool)], axis=1
    )
    for li, path in enumerate(paths):
        rows = slice(li * n_lon, (li + 1) * n_lon)
        x = np.full(n_lon, float(path.project(initial_state[X : Y + 1])[0]))
        v = np.full(n_lon, float(initial_state[VELOCITY_X]))
        poses[rows, 0] = path.interpolate(x[:1])[0]
        corridor = path.corridor(
            float(x[0]), float(x[0]) + float(targets.max()) * (n - 1) * dt, half_w
        )
        shapely.prepare(corridor)
        hits = shapely.intersects(corridor, polys) & valid if polys.size else valid
        prog = np.full(valid.shape, -np.inf)
        if hits.any():  # only boxes in the corridor can lead
            prog[hits] = path.project(centres[hits])
        lead = np.zeros((n_lon, 3), dtype=np.float64)
        for ti in range(1, n):
            if ti % update == 0:
                si = steps.index(ti)
                lead = _leading_agents(
                    path,
                    polys=polys[si],
                    hit=hits[si],
                    progress=prog[si],
                    info=info,
                    current=poses[rows, ti - 1],
                    x=x,
                    half_l=half_l,
                    half_w=half_w,
                    r2c=r2c,
                )
            x, v = _idm_step(x, v, lead=lead, target=targets, p=p, dt=dt)
            poses[rows, ti] = path.interpolate(x)
    return poses


def pdm_closed_choice(
    simulated: F64,
    *,
    ctx: MapContext,
    obs: list[Occupancy],
    unique: Mapping[str, TrackInfo],
    collided: frozenset[str],
    red_lights: list[list[shapely.Polygon]] | None,
    version: str,
    vehicle: Mapping[str, float],
    interval_s: float,
) -> int:
    """The proposal PDM-Closed keeps: the first best score of its simulated proposals
    (``AbstractPDMClosedPlanner._get_closed_loop_trajectory``: ``np.argmax``)."""
    scores = score_proposals(
        simulated,
        obs=obs,
        unique=unique,
        ctx=ctx,
        version=version,
        vehicle=vehicle,
        interval_s=interval_s,
        red_lights=red_lights,
        ignore_tokens=collided,
    )["score"]
    return int(np.argmax(scores))


def _leading_agents(
    path: _Path,
    *,
    polys: npt.NDArray[np.object_],
    hit: npt.NDArray[np.bool_],
    progress: F64,
    info: list[tuple[float | None, float]],
    current: F64,
    x: F64,
    half_l: float,
    half_w: float,
    r2c: float,
) -> F64:
    """``PDMGenerator._update_leading_agents`` at an update step: per proposal (progress,
    velocity, rear length) of the nearest box or red light ahead in the corridor (``hit``:
    the step's boxes and red lights in the corridor, ``progress``: their centroids' progress
    along the path, ``info``: their (speed or None for a red light, heading))."""
    out = np.zeros((x.size, 3), dtype=np.float64)
    row = np.zeros(3, dtype=np.float64)  # NAVSIM reuses one row for the proposals of a step
    cand = np.flatnonzero(hit)
    dist_all = None
    for k in range(x.size):
        ahead = cand[progress[cand] > x[k]]
        if ahead.size:
            if dist_all is None:  # every proposal's box against every candidate, one call
                states = np.zeros((x.size, 1, STATE_SIZE))
                states[:, 0, :3] = current
                box = ego_coords(
                    states, half_length_m=half_l, half_width_m=half_w, rear_axle_to_center_m=r2c
                )
                ego = shapely.polygons(box[:, 0, :4])
                dist_all = np.full((x.size, polys.size), np.inf)
                dist_all[:, cand] = shapely.distance(ego[:, None], polys[None, cand])
            dist = dist_all[k, ahead]
            j = int(ahead[int(np.argmin(dist))])
            row[0] = x[k] + float(dist.min())
            speed, heading = info[j]
            if speed is not None:
                rel = normalize_angle(np.asarray(heading - current[k, 2]))
                row[1] = speed * float(np.cos(rel))
        else:
            row[0] = path.length
            row[2] = half_l
        out[k] = row
    return out
