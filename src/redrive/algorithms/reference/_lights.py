"""The stop lines the reference planner obeys: a red light is a stopped obstacle at its line.

From the road map (:attr:`Algorithm.road_map <redrive.algorithms.Algorithm.road_map>`) each
:class:`~redrive.types.MapTrafficLight` gives a *gate*: its stop line (the map's
:class:`~redrive.types.StopLine`, or, without one, the cross-section of each controlled lane
where it meets the junction: the end of an approach lane, the start of a lane connector) and the
direction of travel through it (its lanes').  Every frame, the gates whose light the frame's
``traffic`` shows RED — or YELLOW while the ego can still stop before the line at the
comfortable deceleration ``b`` (``v² / (2 b) ≤`` the gap), as the synthetic world's drivers
decide — and that the planned path crosses in their direction of travel, ahead of a front bumper
not already more than 0.5 m past them, become stopped leaders at the crossing.  A yellow light
the ego could not stop for is *committed*: it drives on through it (and through its red) until
the light shows green again.

A line is tested (moved into base_link by numpy and crossed with the path, in one compiled
call) only when a cheap pre-filter in plain floats cannot tell it apart: a line lying wholly
beyond one side of the path's bounding box, by more than :data:`_CLEAR_M`, is not crossed —
what the exact test says of it too (its own bounding-box test rejects it).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from redrive.algorithms.reference._plan_kernels import gate_crossing, path_bounds
from redrive.types import LightState, MapLane, RoadMap, TrafficLight, VehicleState

__all__ = ["Gate", "gates_of", "stop_arcs"]

F64 = npt.NDArray[np.float64]

#: a bumper this far past a line (metres) has crossed it: the line no longer holds it back
_PASSED_M = 0.5
#: the pre-filter's margin (metres): a line farther than this beyond a side of the path's
#: bounding box (in plain floats, not numpy's products: they differ by rounding, ≪ this) is
#: clear of the path; nearer, the exact test decides
_CLEAR_M = 1e-3


@dataclass(frozen=True, slots=True)
class Gate:
    """One light's stop line: ``line`` (K, 2) map metres, ``direction`` (2,) unit vector;
    ``points`` the line's vertices as Python floats (the pre-filter's)."""

    light_id: str
    line: F64
    direction: F64
    points: tuple[tuple[float, float], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        pts = [(float(x), float(y)) for x, y in np.asarray(self.line).reshape(-1, 2).tolist()]
        object.__setattr__(self, "points", tuple(pts))


def _tangent(lane: MapLane, point: F64) -> F64:
    """The unit direction of travel of ``lane`` at its centreline vertex nearest ``point``."""
    c = lane.centerline
    k = int(np.argmin(np.hypot(c[:, 0] - point[0], c[:, 1] - point[1])))
    k = min(k, len(c) - 2)
    d = c[k + 1] - c[k]
    return np.asarray(d / max(float(np.hypot(d[0], d[1])), 1e-12), dtype=np.float64)


def _cross_section(lane: MapLane, *, at_end: bool) -> tuple[F64, F64]:
    """The segment across ``lane`` at its end (or start), and the direction of travel there."""
    c = lane.centerline
    p, q = (c[-1], c[-2]) if at_end else (c[0], c[1])
    d = (p - q) if at_end else (q - p)
    d = d / max(float(np.hypot(d[0], d[1])), 1e-12)
    normal = np.array([-d[1], d[0]])
    half = lane.width_m / 2.0
    return np.array([p + half * normal, p - half * normal]), np.asarray(d, dtype=np.float64)


def gates_of(road_map: RoadMap | None) -> tuple[Gate, ...]:
    """The gates of every traffic light of ``road_map`` (none without a map or lights)."""
    if road_map is None:
        return ()
    stop_lines = {s.stop_line_id: s for s in road_map.stop_lines}
    gates: list[Gate] = []
    for light in road_map.traffic_lights:
        lanes = [road_map.lane(i) for i in light.lane_ids]
        stop = stop_lines.get(light.stop_line_id) if light.stop_line_id is not None else None
        if stop is not None and lanes:
            mid = stop.line.mean(axis=0)
            gates.append(Gate(light.light_id, stop.line, _tangent(lanes[0], mid)))
            continue
        for lane in lanes:  # no stop line: where each controlled lane meets the junction
            line, direction = _cross_section(lane, at_end=lane.intersection_id is None)
            gates.append(Gate(light.light_id, line, direction))
    return tuple(gates)


def stop_arcs(
    gates: Iterable[Gate],
    lights: Iterable[TrafficLight],
    *,
    state: VehicleState,
    path_xy: F64,
    path_s: F64,
    front_offset_m: float,
    comfort_decel_mps2: float,
    committed: set[str],
) -> F64:
    """Arc lengths (along the base_link path ``path_xy`` / ``path_s``) of the stop lines the ego
    must stop at now (see the module text); updates ``committed`` (yellow lights driven through).
    """
    shown: Mapping[str, LightState] = {light.id: light.state for light in lights}
    for light_id in [i for i in committed if shown.get(i) is LightState.GREEN]:
        committed.discard(light_id)
    out: list[float] = []
    if len(path_xy) < 2:
        return np.array(out, dtype=np.float64)
    # the ego pose and the path's bounding box (x min, y min, x max, y max), once a light
    # asks for them
    ego: tuple[F64, F64, tuple[float, float, float, float]] | None = None
    box = (0.0,) * 8  # the pre-filter's pose and bounding box, in floats
    for gate in gates:
        light = shown.get(gate.light_id)
        if light not in (LightState.RED, LightState.YELLOW) or gate.light_id in committed:
            continue
        if ego is None:  # the ego pose and the path's bounding box
            c, sn = math.cos(state.heading_rad), math.sin(state.heading_rad)
            bounds = path_bounds(path_xy)
            ego = (state.position[:2], np.array([[c, sn], [-sn, c]]), bounds)
            x_lo, y_lo, x_hi, y_hi = bounds
            ox, oy = state.position[:2].tolist()
            box = (
                c,
                sn,
                ox,
                oy,
                x_lo - _CLEAR_M,
                y_lo - _CLEAR_M,
                x_hi + _CLEAR_M,
                y_hi + _CLEAR_M,
            )
        if _clear_of(gate.points, box):
            continue  # beyond the path's bounding box: gate_crossing would not find it
        origin, base_from_map, bounds = ego
        line = (gate.line - origin) @ base_from_map.T
        # the bounding boxes' test and the first crossing in one compiled call
        found, s, tx, ty = gate_crossing(path_xy, path_s, line, *bounds)
        if not found:
            continue
        tangent = np.array([tx, ty])
        if float(tangent @ (base_from_map @ gate.direction)) <= 0.0:
            continue  # crossed against its direction of travel: not this light's lane
        gap = s - front_offset_m
        if gap < -_PASSED_M:
            continue  # already through it
        if light is LightState.YELLOW and state.speed_mps**2 / (2.0 * comfort_decel_mps2) > gap:
            committed.add(gate.light_id)  # too close to stop comfortably: drive through
            continue
        out.append(s)
    return np.array(out, dtype=np.float64)


def _clear_of(points: tuple[tuple[float, float], ...], box: tuple[float, ...]) -> bool:
    """Whether the line of ``points`` (map metres) lies, in base_link of the pose ``box[:4]``
    (cos, sin of the heading, origin x, y), wholly below ``box[4:6]`` or above ``box[6:8]``
    (the path's bounding box widened by :data:`_CLEAR_M`) in x or in y.  A NaN anywhere is
    never clear (its comparisons are false)."""
    c, sn, ox, oy, x_lo, y_lo, x_hi, y_hi = box
    below_x = above_x = below_y = above_y = True
    for x, y in points:
        dx, dy = x - ox, y - oy
        bx, by = c * dx + sn * dy, c * dy - sn * dx
        below_x = below_x and bx < x_lo
        above_x = above_x and bx > x_hi
        below_y = below_y and by < y_lo
        above_y = above_y and by > y_hi
    return below_x or above_x or below_y or above_y
