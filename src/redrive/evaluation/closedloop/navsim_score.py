"""NAVSIM's ``PDMScorer.score_proposals`` for a batch of simulated proposals, v1.1 and v2.

Follows ``navsim/planning/simulation/planner/pdm_planner/scoring/pdm_scorer.py`` of tag v1.1
(PDMS) and of v2.2 (EPDMS) and ``pdm_scorer_utils.get_collision_type``; each sub-score is
computed as that code computes it (see ``docs/metrics.md``, section NAVSIM).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely

from redrive.evaluation._kinematics import rectangles_overlap
from redrive.evaluation.closedloop.navsim_comfort import comfortable
from redrive.evaluation.closedloop.navsim_scene import MapContext, Occupancy, TrackInfo
from redrive.evaluation.closedloop.navsim_sim import (
    HEADING,
    VELOCITY_X,
    VELOCITY_Y,
    X,
    Y,
)

F64 = npt.NDArray[np.float64]

__all__ = ["SCORER_DEFAULTS", "aggregate", "ego_coords", "score_proposals"]

#: ``PDMScorerConfig`` of v1.1 and v2 (``pdm_scorer.yaml``), shared keys.
SCORER_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {
        "driving_direction_horizon_s": 1.0,
        "driving_direction_compliance_threshold_m": 2.0,
        "driving_direction_violation_threshold_m": 6.0,
        "ttc_stopped_speed_mps": 5e-3,
        "future_collision_horizon_s": 1.0,
        "progress_distance_threshold_m": 5.0,
        "lane_keeping_deviation_limit_m": 0.5,
        "lane_keeping_horizon_s": 2.0,
        "collision_stopped_speed_mps": 5e-2,  # get_collision_type / nuPlan is_track_stopped
        "comfort_rear_axle_to_center_m": 1.461,  # get_pacifica_parameters().rear_axle_to_center
    }
)

_AHEAD_RAD = math.radians(30.0)  # nuPlan is_agent_ahead
_BEHIND_RAD = math.radians(150.0)  # nuPlan is_agent_behind
FL, RL, RR, FR, CENTER = range(5)  # NAVSIM BBCoordsIndex


def ego_coords(
    states: F64, *, half_length_m: float, half_width_m: float, rear_axle_to_center_m: float
) -> F64:
    """``state_array_to_coords_array``: (B, T, 5, 2) front-left, rear-left, rear-right,
    front-right corners and the centre of the ego box."""
    h = states[..., HEADING]
    c, s = np.cos(h), np.sin(h)
    centre = states[..., X : Y + 1] + rear_axle_to_center_m * np.stack([c, s], axis=-1)
    fwd = np.stack([c, s], axis=-1)
    left = np.stack([-s, c], axis=-1)
    out = np.empty((*states.shape[:2], 5, 2), dtype=np.float64)
    out[..., FL, :] = centre + half_length_m * fwd + half_width_m * left
    out[..., RL, :] = centre - half_length_m * fwd + half_width_m * left
    out[..., RR, :] = centre - half_length_m * fwd - half_width_m * left
    out[..., FR, :] = centre + half_length_m * fwd - half_width_m * left
    out[..., CENTER, :] = centre
    return out


def _bearing(ego: F64, point: F64) -> float:
    ang = math.atan2(point[1] - ego[Y], point[0] - ego[X])
    return abs(math.remainder(float(ego[HEADING]) - ang, math.tau))


def _ego_areas(coords: F64, ctx: MapContext) -> tuple[npt.NDArray[np.bool_], ...]:
    """``_calculate_ego_area``: (B, T) multiple lanes, non-drivable area, oncoming traffic."""
    b, t = coords.shape[:2]
    pts = coords.reshape(-1, 2)
    n_lanes = len(ctx.lane_polygons)
    inside = np.zeros((n_lanes, pts.shape[0]), dtype=bool)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    bounds = ctx.lane_bounds
    near = (
        (bounds[:, 0] <= hi[0])
        & (bounds[:, 2] >= lo[0])
        & (bounds[:, 1] <= hi[1])
        & (bounds[:, 3] >= lo[1])
    )
    for i in np.flatnonzero(near).tolist():  # a lane off the points' box holds none of them
        inside[i] = shapely.contains_xy(ctx.lane_polygons[i], pts[:, 0], pts[:, 1])
    per_lane = inside.reshape(n_lanes, b, t, 5).transpose(1, 2, 0, 3)  # B, T, L, 5
    corners_in = per_lane[..., :4]
    count = corners_in.sum(axis=-1)  # B, T, L
    multiple = ((count > 0).sum(axis=-1) > 1) & np.all(count != 4, axis=-1)
    corner_pts = coords[..., :4, :].reshape(-1, 2)
    on_road = shapely.contains_xy(ctx.drivable, corner_pts[:, 0], corner_pts[:, 1])
    nondrivable = on_road.reshape(b, t, 4).sum(axis=-1) < 4
    route = np.array([lid in ctx.route_lane_ids for lid in ctx.lane_ids], dtype=bool)
    oncoming = per_lane[..., CENTER][..., route].sum(axis=-1) == 0
    return multiple, nondrivable, oncoming


def _collision_kind(
    state: F64, ego_corners: F64, obj_corners: F64, info: TrackInfo, stopped_mps: float
) -> str:
    """``get_collision_type`` (the track's speed and heading of its first instance)."""
    if float(np.hypot(state[VELOCITY_X], state[VELOCITY_Y])) <= stopped_mps:
        return "stopped_ego"
    if not info.is_agent or float(np.hypot(*info.velocity_xy)) <= stopped_mps:
        return "stopped_track"
    if _bearing(state, obj_corners.mean(axis=0)) > _BEHIND_RAD:
        return "active_rear"
    front = shapely.LineString([ego_corners[FL], ego_corners[FR]])
    if front.intersects(shapely.Polygon(obj_corners)):
        return "active_front"
    return "active_lateral"


def _pack(obs: Sequence[Occupancy]) -> tuple[F64, npt.NDArray[np.bool_], F64, F64]:
    """The observation as padded arrays: corners (T, M, 4, 2), valid (T, M), centres (T, M, 2)
    and bounding radii (T, M)."""
    t = len(obs)
    m = max((len(o.tokens) for o in obs), default=0)
    corners = np.zeros((t, m, 4, 2), dtype=np.float64)
    valid = np.zeros((t, m), dtype=bool)
    for i, o in enumerate(obs):
        k = len(o.tokens)
        corners[i, :k] = o.corners
        valid[i, :k] = True
    centres = corners.mean(axis=2)
    radii = np.linalg.norm(corners[:, :, 0] - centres, axis=-1)
    return corners, valid, centres, radii


def _contacts(
    boxes: F64, times: npt.NDArray[np.int64], packed: tuple[F64, npt.NDArray[np.bool_], F64, F64]
) -> list[tuple[int, ...]]:
    """Index tuples ``(*box index, m)`` where box ``boxes[...]`` (…, 4, 2) overlaps box ``m``
    of observation step ``times[...]`` (an array shaped like ``boxes.shape[:-2]``), in
    lexicographic order: a bounding-circle test first, the exact test (separating axes,
    touching counts as shapely's ``intersects``) on what passes."""
    corners, valid, centres, radii = packed
    if corners.shape[1] == 0:
        return []
    inside = times < corners.shape[0]
    tt = np.where(inside, times, 0)
    c = boxes.mean(axis=-2)
    r = np.linalg.norm(boxes[..., 0, :] - c, axis=-1)
    d = np.linalg.norm(c[..., None, :] - centres[tt], axis=-1)
    cand = (d <= r[..., None] + radii[tt] + 1e-9) & valid[tt] & inside[..., None]
    idx = np.argwhere(cand)
    if idx.size == 0:
        return []
    lead = tuple(idx[:, :-1].T)
    hit = rectangles_overlap(boxes[lead], corners[tt[lead], idx[:, -1]])
    return [tuple(int(v) for v in row) for row in idx[hit]]


def _no_at_fault_collision(
    states: F64,
    coords: F64,
    *,
    obs: Sequence[Occupancy],
    packed: tuple[F64, npt.NDArray[np.bool_], F64, F64],
    unique: Mapping[str, TrackInfo],
    straddling: npt.NDArray[np.bool_],
    p: Mapping[str, Any],
    ignore: frozenset[str],
) -> F64:
    """``_calculate_no_at_fault_collision``: 0 for an at-fault collision with an agent, 0.5
    with an object (any number of them: the minimum is kept), 1 otherwise."""
    b, t = states.shape[:2]
    scores = np.ones(b, dtype=np.float64)
    collided: list[set[str]] = [set(ignore) for _ in range(b)]
    stopped = float(p["collision_stopped_speed_mps"])
    boxes = coords[:, :, :4].transpose(1, 0, 2, 3)  # T, B, 4, 2: NAVSIM loops time first
    times = np.broadcast_to(np.arange(t)[:, None], (t, b))
    for ti, bi, m in _contacts(boxes, times, packed):
        occ = obs[ti]
        token = occ.tokens[m]
        if token in collided[bi]:
            continue
        info = unique[token]
        kind = _collision_kind(states[bi, ti], coords[bi, ti], occ.corners[m], info, stopped)
        if kind in ("active_front", "stopped_track") or (
            bool(straddling[bi, ti]) and kind == "active_lateral"
        ):
            scores[bi] = min(scores[bi], 0.0 if info.is_agent else 0.5)
        else:
            collided[bi].add(token)
    return scores


def _ttc(
    states: F64,
    coords: F64,
    *,
    obs: Sequence[Occupancy],
    packed: tuple[F64, npt.NDArray[np.bool_], F64, F64],
    straddling: npt.NDArray[np.bool_],
    ctx: MapContext,
    version: str,
    interval_s: float,
    p: Mapping[str, Any],
    ignore: frozenset[str],
) -> F64:
    """``_calculate_ttc``: the ego box projected 0, 0.3, 0.6, 0.9 s ahead at constant speed
    meets a box ahead (or, straddling lanes / off-road / in an intersection, not behind)."""
    b, t = states.shape[:2]
    scores = np.ones(b, dtype=np.float64)
    collided: list[set[str]] = [set(ignore) for _ in range(b)]
    future = np.arange(0, int(float(p["future_collision_horizon_s"]) * 10), 3)
    speeds = np.hypot(states[..., VELOCITY_X], states[..., VELOCITY_Y])
    h = states[..., HEADING]
    dxy = np.stack([np.cos(h) * speeds, np.sin(h) * speeds], axis=-1)
    last = t - 1 if version == "v1" else t - 1 - int(future.max())
    rear_in_inter = ctx.in_intersection(states[..., X : Y + 1].reshape(-1, 2)).reshape(b, t)
    min_speed = float(p["ttc_stopped_speed_mps"])
    steps = np.arange(last + 1)
    # (T', F, B, 4, 2): NAVSIM loops over time, then the projection, then the hits
    base = coords[:, steps, :4].transpose(1, 0, 2, 3)
    shift = dxy[:, steps].transpose(1, 0, 2)  # T', B, 2
    offs = future.astype(np.float64) * interval_s
    boxes = base[:, None] + shift[:, None, :, None, :] * offs[None, :, None, None, None]
    times = np.broadcast_to((steps[:, None] + future[None, :])[..., None], boxes.shape[:3])
    for ti, ki, bi, m in _contacts(boxes, times, packed):
        occ = obs[ti + int(future[ki])]
        token = occ.tokens[m]
        if token in collided[bi] or speeds[bi, ti] < min_speed:
            continue
        bearing = _bearing(states[bi, ti], occ.centroid(m))
        wide = bool(straddling[bi, ti]) or bool(rear_in_inter[bi, ti])
        if bearing < _AHEAD_RAD or (wide and not bearing > _BEHIND_RAD):
            scores[bi] = 0.0
        else:
            collided[bi].add(token)
    return scores


def _driving_direction(
    coords: F64,
    oncoming: npt.NDArray[np.bool_],
    ctx: MapContext,
    *,
    version: str,
    interval_s: float,
    p: Mapping[str, Any],
) -> F64:
    """``_calculate_driving_direction_compliance``: the most distance driven against traffic
    within any 1-s window (v2: not counting steps in an intersection)."""
    centre = coords[:, :, CENTER]
    b, t = centre.shape[:2]
    prog = np.zeros((b, t), dtype=np.float64)
    prog[:, 1:] = np.linalg.norm(centre[:, 1:] - centre[:, :-1], axis=-1)
    mask = oncoming.copy()
    if version == "v2":
        mask &= ~ctx.in_intersection(centre.reshape(-1, 2)).reshape(b, t)
    prog[~mask] = 0.0
    horizon = int(float(p["driving_direction_horizon_s"]) / interval_s)
    csum = np.concatenate([np.zeros((b, 1)), np.cumsum(prog, axis=1)], axis=1)
    lo = np.maximum(0, np.arange(t) - horizon)
    window = csum[:, np.arange(t) + 1] - csum[:, lo]
    worst = window.max(axis=1)
    ok = float(p["driving_direction_compliance_threshold_m"])
    bad = float(p["driving_direction_violation_threshold_m"])
    return np.where(worst < ok, 1.0, np.where(worst < bad, 0.5, 0.0))


def _lane_keeping(coords: F64, ctx: MapContext, *, interval_s: float, p: Mapping[str, Any]) -> F64:
    """v2 ``_calculate_lane_keeping``: 0 once the centre stays more than 0.5 m off the route's
    centreline for 2 s in a row (steps in an intersection neither count nor reset)."""
    assert ctx.centerline is not None
    centre = coords[:, :, CENTER]
    b, t = centre.shape[:2]
    flat = centre.reshape(-1, 2)
    # the centreline near the points only (distances beyond the margin exceed the limit either
    # way: the verdict is the same, the long line is not walked for every point)
    margin = 10.0 + float(p["lane_keeping_deviation_limit_m"])
    lo, hi = flat.min(axis=0) - margin, flat.max(axis=0) + margin
    near = shapely.clip_by_rect(ctx.centerline, lo[0], lo[1], hi[0], hi[1])
    if near.is_empty:
        dev = np.full((b, t), np.inf)
    else:
        dev = shapely.distance(near, shapely.points(flat)).reshape(b, t)
    inter = ctx.in_intersection(flat).reshape(b, t)
    need = int(np.ceil(float(p["lane_keeping_horizon_s"]) / interval_s))
    limit = float(p["lane_keeping_deviation_limit_m"])
    out = np.ones(b, dtype=np.float64)
    for bi in range(b):
        run = 0
        for ti in range(t):
            if inter[bi, ti]:
                continue
            run = run + 1 if dev[bi, ti] > limit else 0
            if run >= need:
                out[bi] = 0.0
                break
    return out


def _traffic_lights(coords: F64, red: Sequence[Sequence[shapely.Polygon]] | None) -> F64:
    """v2 ``_calculate_traffic_light_compliance``: 0 once the ego box touches the polygon of an
    on-route lane under a red light."""
    b, t = coords.shape[:2]
    out = np.ones(b, dtype=np.float64)
    if red is None:
        return out
    for ti in range(min(t, len(red))):
        if not red[ti]:
            continue
        boxes = shapely.polygons(coords[:, ti, :4])
        for poly in red[ti]:
            out[shapely.intersects(boxes, poly)] = 0.0
    return out


def score_proposals(
    states: F64,
    *,
    obs: Sequence[Occupancy],
    unique: Mapping[str, TrackInfo],
    ctx: MapContext,
    version: str,
    vehicle: Mapping[str, float],
    interval_s: float,
    params: Mapping[str, Any] = SCORER_DEFAULTS,
    red_lights: Sequence[Sequence[shapely.Polygon]] | None = None,
    history: F64 | None = None,
    ignore_tokens: frozenset[str] = frozenset(),
) -> dict[str, F64]:
    """Every sub-score (B,) of the simulated proposals ``states`` (B, T, 11) and the aggregate.

    ``vehicle``: ``half_length_m``, ``half_width_m``, ``rear_axle_to_center_m``.  ``history``
    (H, 11): the logged ego's past states that v2's history comfort prepends (None: 1).
    ``ignore_tokens``: boxes the ego touched before (``PDMObservation.collided_track_ids``).

    Keys: ``nc``, ``dac``, ``ddc``, ``ttc``, ``progress_m`` (raw), ``ep``, ``multi`` and
    ``score``; v1 adds ``c``; v2 adds ``tlc``, ``lk``, ``hc``."""
    coords = ego_coords(states, **vehicle)
    multiple, nondrivable, oncoming = _ego_areas(coords, ctx)
    straddling = multiple | nondrivable
    packed = _pack(obs)
    out: dict[str, F64] = {
        "nc": _no_at_fault_collision(
            states,
            coords,
            obs=obs,
            packed=packed,
            unique=unique,
            straddling=straddling,
            p=params,
            ignore=ignore_tokens,
        ),
        "dac": np.where(nondrivable.any(axis=1), 0.0, 1.0),
        "ddc": _driving_direction(
            coords, oncoming, ctx, version=version, interval_s=interval_s, p=params
        ),
        "ttc": _ttc(
            states,
            coords,
            obs=obs,
            packed=packed,
            straddling=straddling,
            ctx=ctx,
            version=version,
            interval_s=interval_s,
            p=params,
            ignore=ignore_tokens,
        ),
    }
    if ctx.centerline is None:
        msg = "NAVSIM scoring needs the route's centreline (no route lane near the ego)"
        raise ValueError(msg)
    start = shapely.line_locate_point(ctx.centerline, shapely.points(coords[:, 0, CENTER]))
    end = shapely.line_locate_point(ctx.centerline, shapely.points(coords[:, -1, CENTER]))
    out["progress_m"] = np.clip(np.asarray(end - start, dtype=np.float64), 0.0, None)
    t = np.arange(states.shape[1], dtype=np.float64) * interval_s
    # v2's ego_is_comfortable shifts to the centre of its default vehicle, the Pacifica, whatever
    # the scorer's vehicle (v1.1 does not shift)
    r2c = float(params["comfort_rear_axle_to_center_m"])
    if version == "v1":
        out["c"] = comfortable(states, t, version="v1", rear_axle_to_center_m=r2c).astype(
            np.float64
        )
    else:
        out["tlc"] = _traffic_lights(coords, red_lights)
        out["lk"] = _lane_keeping(coords, ctx, interval_s=interval_s, p=params)
        if history is None or len(history) == 0:
            out["hc"] = np.ones(states.shape[0], dtype=np.float64)
        else:
            padded = np.concatenate(
                [np.broadcast_to(history, (states.shape[0], *history.shape)), states], axis=1
            )
            tp = np.arange(padded.shape[1], dtype=np.float64) * interval_s
            out["hc"] = comfortable(padded, tp, version="v2", rear_axle_to_center_m=r2c).astype(
                np.float64
            )
    return aggregate(out, version=version, params=params)


def aggregate(
    parts: dict[str, F64], *, version: str, params: Mapping[str, Any] = SCORER_DEFAULTS
) -> dict[str, F64]:
    """``_aggregate_scores`` (v1.1) / ``_aggregate_pdm_scores`` (v2, without the two-frame
    extended comfort): the multiplicative metrics times the weighted mean, the progress
    normalised by the best progress of a proposal that passes every multiplicative metric."""
    out = dict(parts)
    threshold = float(params["progress_distance_threshold_m"])
    raw = out["progress_m"]
    if version == "v1":
        multi = out["nc"] * out["dac"]
        masked = raw * multi
        best = float(masked.max())
        if best > threshold:
            ep = masked / best
        else:
            ep = np.ones_like(raw)
            ep[multi == 0.0] = 0.0
        weighted = (5.0 * ep + 5.0 * out["ttc"] + 2.0 * out["c"] + 0.0 * out["ddc"]) / 12.0
    else:
        multi = out["nc"] * out["dac"] * out["ddc"] * out["tlc"]
        masked = raw * multi
        best = float(masked.max())
        ep = np.clip(raw / best, 0.0, 1.0) if best > threshold else np.ones_like(raw)
        weighted = (5.0 * ep + 5.0 * out["ttc"] + 2.0 * out["lk"] + 2.0 * out["hc"]) / 14.0
    out["ep"] = np.asarray(ep, dtype=np.float64)
    out["multi"] = multi
    out["score"] = multi * weighted
    return out
