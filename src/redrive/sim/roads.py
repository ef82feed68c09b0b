"""Road network: straight and circular-arc multi-lane segments, lanes, routes, one intersection.

Every segment has a *reference line* (a straight line or a circular arc) parametrised by arclength
``s`` (metres) with a signed lateral offset ``d`` (metres, positive to the left, REP-103).  Forward
lanes lie right of the reference line (``d < 0``, driving on the right), backward lanes left of it
and run the other way.  A lane is a polyline sampled every ~0.5 m with analytic arclength, heading
and curvature; a :class:`Route` is a chain of lanes with one arclength parametrisation.

Layouts are built by :func:`urban_network` (a 4-way signalised intersection) and
:func:`highway_network` (straight – gentle curve – straight); :func:`rasterize` paints the
network into the :class:`~redrive.sim.scene.GroundMap` of the scene.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

__all__ = [
    "HighwayLayout",
    "Lane",
    "RoadNetwork",
    "RoadSegment",
    "Route",
    "Signal",
    "StopLine",
    "UrbanLayout",
    "build_network",
    "highway_network",
    "urban_network",
]

F64 = npt.NDArray[np.float64]
_SAMPLE_M = 0.5
#: width of a painted stop line (metres); lanes end this far before it plus their margin
STOP_LINE_WIDTH_M = 0.5


@dataclass(frozen=True, slots=True, kw_only=True)
class RoadSegment:
    """A straight (``curvature_1pm == 0``) or circular-arc piece of road.

    Attributes:
        name: unique name; lanes are named ``{name}:f{i}`` / ``{name}:b{i}`` (0 = next to centre).
        start_xy: (x, y) metres of the reference line at s = 0; ``start_heading_rad`` its heading.
        length_m: arclength of the reference line; ``curvature_1pm`` signed (left turn > 0).
        lanes_forward, lanes_backward: lane counts right / left of the reference line.
        lane_width_m, shoulder_m, sidewalk_width_m: widths across the road, metres.
    """

    name: str
    start_xy: tuple[float, float]
    start_heading_rad: float
    length_m: float
    curvature_1pm: float = 0.0
    lanes_forward: int = 1
    lanes_backward: int = 1
    lane_width_m: float = 3.5
    shoulder_m: float = 0.0
    sidewalk_width_m: float = 0.0

    @property
    def right_edge_m(self) -> float:
        """Lateral offset of the right road edge (negative), metres."""
        return -(self.lanes_forward * self.lane_width_m + self.shoulder_m)

    @property
    def left_edge_m(self) -> float:
        """Lateral offset of the left road edge, metres."""
        return self.lanes_backward * self.lane_width_m + self.shoulder_m

    def pose_at(self, s_m: npt.ArrayLike, d_m: npt.ArrayLike = 0.0) -> tuple[F64, F64, F64]:
        """Map x, y (metres) and heading (rad) of reference point ``s_m`` offset by ``d_m``."""
        s = np.asarray(s_m, dtype=np.float64)
        d = np.asarray(d_m, dtype=np.float64)
        x0, y0 = self.start_xy
        th0, k = self.start_heading_rad, self.curvature_1pm
        heading = th0 + k * s
        if k == 0.0:
            x = x0 + s * math.cos(th0) - d * math.sin(th0)
            y = y0 + s * math.sin(th0) + d * math.cos(th0)
        else:
            # centre c = p0 + n(θ0)/k; p(s) + d n(θ) = c - (1/k - d) n(θ), n(θ) = (-sin θ, cos θ).
            cx, cy = x0 - math.sin(th0) / k, y0 + math.cos(th0) / k
            r = 1.0 / k - d
            x = cx + r * np.sin(heading)
            y = cy - r * np.cos(heading)
        return np.asarray(x, np.float64), np.asarray(y, np.float64), heading

    def local_coords(self, x: F64, y: F64) -> tuple[F64, F64]:
        """Arclength s and lateral offset d (metres) of map points (vectorised inverse of pose_at).

        On an arc, ``s`` is measured around the arc midpoint so points of the arc are never wrapped.
        """
        x0, y0 = self.start_xy
        th0, k = self.start_heading_rad, self.curvature_1pm
        if k == 0.0:
            c, s_ = math.cos(th0), math.sin(th0)
            dx, dy = x - x0, y - y0
            return dx * c + dy * s_, -dx * s_ + dy * c
        cx, cy = x0 - math.sin(th0) / k, y0 + math.cos(th0) / k
        vx, vy = x - cx, y - cy
        rad = np.hypot(vx, vy)
        if k > 0:
            theta, d = np.arctan2(vx, -vy), 1.0 / k - rad
        else:
            theta, d = np.arctan2(-vx, vy), 1.0 / k + rad
        mid = th0 + k * self.length_m / 2.0
        delta = np.mod(theta - mid + np.pi, 2.0 * np.pi) - np.pi
        return (delta + (mid - th0)) / k, d

    def lane_offset_m(self, index: int, *, forward: bool) -> float:
        """Lateral offset (metres) of the centre line of lane ``index``."""
        return -(index + 0.5) * self.lane_width_m if forward else (index + 0.5) * self.lane_width_m


@dataclass(frozen=True, slots=True, kw_only=True)
class Lane:
    """One lane centre line, sampled every ~0.5 m (arrays share the first axis, float64).

    Attributes:
        lane_id: ``{segment}:f{i}``, ``{segment}:b{i}`` or a connector name.
        points: (N, 2) metres; s_m: (N,) arclength from the lane start, metres.
        heading_rad: (N,) direction of travel; curvature_1pm: (N,) signed, 1/m.
        width_m: lane width.
        stop_line_s_m: arclength of the stop line on this lane (None: none).
        light_id: the signal governing the stop line.
    """

    lane_id: str
    points: F64
    s_m: F64
    heading_rad: F64
    curvature_1pm: F64
    width_m: float
    stop_line_s_m: float | None = None
    light_id: int | None = None

    @property
    def length_m(self) -> float:
        return float(self.s_m[-1])


def segment_lane(
    seg: RoadSegment, index: int, *, forward: bool, stop_back_m: float | None = None
) -> Lane:
    """The lane ``index`` of ``seg`` (backward lanes run from s = L to s = 0)."""
    d = seg.lane_offset_m(index, forward=forward)
    n = max(2, math.ceil(seg.length_m / _SAMPLE_M) + 1)
    ref_s = np.linspace(0.0, seg.length_m, n)
    if not forward:
        ref_s = ref_s[::-1].copy()
    x, y, heading = seg.pose_at(ref_s, d)
    scale = 1.0 - seg.curvature_1pm * d  # arclength stretch of an offset curve
    lane_s = np.abs(ref_s - ref_s[0]) * scale
    curvature = seg.curvature_1pm / scale
    if not forward:
        heading = heading + math.pi
        curvature = -curvature
    stop = None if stop_back_m is None else float(lane_s[-1] - stop_back_m)
    return Lane(
        lane_id=f"{seg.name}:{'f' if forward else 'b'}{index}",
        points=np.stack([x, y], axis=1),
        s_m=lane_s,
        heading_rad=heading,
        curvature_1pm=np.full(n, curvature),
        width_m=seg.lane_width_m,
        stop_line_s_m=stop,
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class StopLine:
    """A stop line on a route: route arclength of its near edge (metres) and its signal."""

    s_m: float
    light_id: int


class Route:
    """A chain of lanes with one arclength ``s`` (metres) from the start of the first lane."""

    def __init__(self, name: str, lanes: Sequence[Lane]) -> None:
        self.name = name
        self.lane_ids = tuple(lane.lane_id for lane in lanes)
        pts, ss, hs, ks, stops = [], [], [], [], []
        offset = 0.0
        for i, lane in enumerate(lanes):
            cut = 0 if i == 0 else 1
            pts.append(lane.points[cut:])
            ss.append(lane.s_m[cut:] + offset)
            hs.append(lane.heading_rad[cut:])
            ks.append(lane.curvature_1pm[cut:])
            if lane.stop_line_s_m is not None and lane.light_id is not None:
                stops.append(StopLine(s_m=offset + lane.stop_line_s_m, light_id=lane.light_id))
            offset += lane.length_m
        self.points: F64 = np.concatenate(pts)
        self.s_m: F64 = np.concatenate(ss)
        self.heading_rad: F64 = np.unwrap(np.concatenate(hs))
        self.curvature_1pm: F64 = np.concatenate(ks)
        self.width_m = float(lanes[0].width_m)
        self.stop_lines = tuple(stops)
        for arr in (self.points, self.s_m, self.heading_rad, self.curvature_1pm):
            arr.flags.writeable = False
        # the same samples as Python floats: pose_at runs for every agent every physics step,
        # where bisect and float arithmetic cost a fraction of numpy's per-call overhead
        self._s_list: list[float] = self.s_m.tolist()
        self._x_list: list[float] = self.points[:, 0].tolist()
        self._y_list: list[float] = self.points[:, 1].tolist()
        self._heading_list: list[float] = self.heading_rad.tolist()
        self._x: F64 = np.ascontiguousarray(self.points[:, 0])
        self._y: F64 = np.ascontiguousarray(self.points[:, 1])

    @property
    def length_m(self) -> float:
        return float(self.s_m[-1])

    def pose_at(self, s_m: float, d_m: float = 0.0) -> tuple[float, float, float]:
        """x, y (metres) and heading (rad) at arclength ``s_m``, offset ``d_m`` to the left.

        Positions are interpolated linearly between samples of the polyline (exact on straight
        lanes); beyond the ends the route is extended straight.
        """
        s_arr, xs, ys, hs = self._s_list, self._x_list, self._y_list, self._heading_list
        i = min(max(bisect.bisect_right(s_arr, s_m) - 1, 0), len(s_arr) - 2)
        ds = s_arr[i + 1] - s_arr[i]
        t = (s_m - s_arr[i]) / ds
        x0, y0 = xs[i], ys[i]
        tx, ty = (xs[i + 1] - x0) / ds, (ys[i + 1] - y0) / ds
        norm = math.hypot(tx, ty)
        heading = float(hs[i] + min(max(t, 0.0), 1.0) * (hs[i + 1] - hs[i]))
        x = x0 + t * ds * tx - d_m * ty / norm
        y = y0 + t * ds * ty + d_m * tx / norm
        return float(x), float(y), heading

    def segment_norms(self) -> list[float]:
        """Per segment (sample i to i + 1): the length of the unit tangent as :meth:`pose_at`
        computes it (``math.hypot`` of the differences over the arclength step; 1 up to
        rounding), for kernels that must give :meth:`pose_at`'s values bit for bit."""
        s_arr, xs, ys = self._s_list, self._x_list, self._y_list
        out = []
        for i in range(len(s_arr) - 1):
            ds = s_arr[i + 1] - s_arr[i]
            if ds == 0.0:  # a repeated sample (pose_at raises there)
                out.append(math.nan)
                continue
            out.append(math.hypot((xs[i + 1] - xs[i]) / ds, (ys[i + 1] - ys[i]) / ds))
        return out

    def _piece(self, s_min_m: float, s_max_m: float) -> tuple[int, int]:
        """Sample indices ``lo < hi``: the segments ``lo … hi - 1`` cover ``[s_min_m, s_max_m]``."""
        s_arr = self._s_list
        last = len(s_arr) - 1
        lo = min(max(bisect.bisect_right(s_arr, s_min_m) - 1, 0), last - 1)
        hi = min(bisect.bisect_left(s_arr, s_max_m) + 1, last)
        return lo, max(hi, lo + 1)

    def near(
        self, points_xy: npt.ArrayLike, *, s_min_m: float, s_max_m: float, radius_m: npt.ArrayLike
    ) -> npt.NDArray[np.bool_]:
        """A cheap superset test: False where a point is certainly farther than ``radius_m`` (per
        point, or one for all) from the route piece ``[s_min_m, s_max_m]`` — outside the piece's
        bounding box grown by the radius.  :meth:`project` only the points that pass."""
        pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        lo, hi = self._piece(s_min_m, s_max_m)
        piece = self.points[lo : hi + 1]
        low, high = piece.min(axis=0), piece.max(axis=0)
        outside = np.maximum(np.maximum(low - pts, pts - high), 0.0)
        reach = np.asarray(radius_m, dtype=np.float64) + 1e-6  # rounding: keep borderline points
        return np.asarray((outside**2).sum(axis=1) < reach**2)

    def project(
        self, points_xy: npt.ArrayLike, *, s_min_m: float, s_max_m: float
    ) -> tuple[F64, F64]:
        """Arclength and signed distance (metres, left > 0) of the closest point of the route piece
        ``[s_min_m, s_max_m]`` to each of ``points_xy`` (M, 2).

        Points beyond the piece project onto its ends (with their true distance).
        """
        pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        lo, hi = self._piece(s_min_m, s_max_m)
        a = self.points[lo:hi]
        seg = self.points[lo + 1 : hi + 1] - a
        seg_len = self.s_m[lo + 1 : hi + 1] - self.s_m[lo:hi]
        rel = pts[:, None, :] - a[None, :, :]
        t = np.clip((rel * seg[None]).sum(-1) / (seg_len**2)[None], 0.0, 1.0)
        diff = rel - t[..., None] * seg[None]
        dist2 = (diff**2).sum(-1)
        j = np.argmin(dist2, axis=1)
        rows = np.arange(len(pts))
        s = self.s_m[lo + j] + t[rows, j] * seg_len[j]
        sj = seg[j]
        cross = sj[:, 0] * rel[rows, j, 1] - sj[:, 1] * rel[rows, j, 0]
        lateral = np.where(cross < 0.0, -1.0, 1.0) * np.sqrt(dist2[rows, j])
        return s, lateral

    def project_point(
        self, x_m: float, y_m: float, *, s_min_m: float, s_max_m: float
    ) -> tuple[float, float]:
        """:meth:`project` of one point, in Python floats: equal to it bit for bit (the same
        float64 operations in the same order, ties to the first segment), compiled
        (:func:`redrive.sim.kernels.project_point`): many times faster on the short pieces the
        ego's route tracking asks for every physics step."""
        from redrive.sim import kernels  # numba: imported by what steps a world, not by readers

        lo, hi = self._piece(s_min_m, s_max_m)
        s, lateral, ok = kernels.project_point(self.s_m, self._x, self._y, lo, hi, x_m, y_m)
        if not ok:  # a repeated sample: numpy's inf and nan, as project has
            s_np, lat_np = self.project([[x_m, y_m]], s_min_m=s_min_m, s_max_m=s_max_m)
            return float(s_np[0]), float(lat_np[0])
        return s, lateral


@dataclass(frozen=True, slots=True, kw_only=True)
class Signal:
    """A signal head of the intersection: its approach, lamp position (metres, map frame)."""

    light_id: int
    approach: str
    phase_group: int
    position: tuple[float, float, float]


@dataclass(frozen=True, slots=True, kw_only=True)
class RoadNetwork:
    """Segments (painted), lanes, routes, signals and the intersection square (if any)."""

    segments: tuple[RoadSegment, ...]
    lanes: Mapping[str, Lane]
    routes: Mapping[str, Route]
    signals: tuple[Signal, ...] = ()
    intersection_half_m: float | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class UrbanLayout:
    """A 4-way signalised intersection at the map origin with four straight arms (metres)."""

    lanes_per_direction: int = 1
    lane_width_m: float = 3.5
    arm_length_m: float = 150.0
    shoulder_m: float = 2.5
    sidewalk_width_m: float = 3.0
    #: the legal speed limit of every lane, m/s; None: 50 km/h (redrive.sim.roadmap)
    speed_limit_mps: float | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class HighwayLayout:
    """Straight – circular curve – straight, both directions (metres, degrees)."""

    lanes_per_direction: int = 3
    lane_width_m: float = 3.75
    straight_length_m: float = 200.0
    curve_radius_m: float = 600.0
    curve_angle_deg: float = 15.0
    exit_length_m: float = 150.0
    shoulder_m: float = 2.5
    sidewalk_width_m: float = 1.5
    #: the legal speed limit of every lane, m/s; None: 120 km/h (redrive.sim.roadmap)
    speed_limit_mps: float | None = None


def build_network(layout: UrbanLayout | HighwayLayout) -> RoadNetwork:
    """The network of a layout."""
    if isinstance(layout, UrbanLayout):
        return urban_network(layout)
    return highway_network(layout)


# The arms of the intersection, in order of 90° rotation: approach from west heads east, etc.
_APPROACHES = ("west", "south", "east", "north")
_ROT90 = ((1, 0, 0, 1), (0, -1, 1, 0), (-1, 0, 0, -1), (0, 1, -1, 0))  # exact rotations


def _rot(k: int, x: float, y: float) -> tuple[float, float]:
    c0, c1, c2, c3 = _ROT90[k % 4]
    return c0 * x + c1 * y, c2 * x + c3 * y


def _arc_lane(
    lane_id: str,
    start: tuple[float, float, float],
    *,
    radius_m: float,
    turn_rad: float,
    width_m: float,
) -> Lane:
    """A connector lane: a circular arc of ``radius_m`` turning by ``turn_rad`` (left > 0)."""
    seg = RoadSegment(
        name=lane_id,
        start_xy=(start[0], start[1]),
        start_heading_rad=start[2],
        length_m=abs(turn_rad) * radius_m,
        curvature_1pm=math.copysign(1.0 / radius_m, turn_rad),
        lanes_forward=1,
        lanes_backward=0,
        lane_width_m=width_m,
    )
    return _recentre(seg, lane_id)


def _straight_lane(
    lane_id: str, start: tuple[float, float, float], *, length_m: float, width_m: float
) -> Lane:
    seg = RoadSegment(
        name=lane_id,
        start_xy=(start[0], start[1]),
        start_heading_rad=start[2],
        length_m=length_m,
        lanes_forward=1,
        lanes_backward=0,
        lane_width_m=width_m,
    )
    return _recentre(seg, lane_id)


def _recentre(seg: RoadSegment, lane_id: str) -> Lane:
    # A connector's reference line *is* its centre line: sample at d = 0.
    n = max(2, math.ceil(seg.length_m / _SAMPLE_M) + 1)
    s = np.linspace(0.0, seg.length_m, n)
    x, y, heading = seg.pose_at(s)
    return Lane(
        lane_id=lane_id,
        points=np.stack([x, y], axis=1),
        s_m=s,
        heading_rad=heading,
        curvature_1pm=np.full(n, seg.curvature_1pm),
        width_m=seg.lane_width_m,
    )


def urban_network(layout: UrbanLayout) -> RoadNetwork:
    """Four straight arms around a signalised intersection square centred at the origin.

    Routes are named ``{from}_{to}_{lane}`` (e.g. ``west_east_0``; lane 0 is next to the centre
    line); turns: left from lane 0 into lane 0, right from the outermost lane into the outermost.
    Signal ``k`` governs the approach ``_APPROACHES[k]``; west/east share phase group 0.
    """
    n, w = layout.lanes_per_direction, layout.lane_width_m
    half = n * w + layout.shoulder_m + 2.0  # intersection half size
    arm_l = layout.arm_length_m
    segments: list[RoadSegment] = []
    lanes: dict[str, Lane] = {}
    signals: list[Signal] = []
    for k, name in enumerate(_APPROACHES):
        heading = k * math.pi / 2.0
        sx, sy = _rot(k, -half - arm_l, 0.0)
        seg = RoadSegment(
            name=name,
            start_xy=(sx, sy),
            start_heading_rad=heading,
            length_m=arm_l,
            lanes_forward=n,
            lanes_backward=n,
            lane_width_m=w,
            shoulder_m=layout.shoulder_m,
            sidewalk_width_m=layout.sidewalk_width_m,
        )
        segments.append(seg)
        px, py, _ = seg.pose_at(arm_l - 1.0, seg.right_edge_m - 0.6)
        signals.append(
            Signal(
                light_id=k, approach=name, phase_group=k % 2, position=(float(px), float(py), 5.0)
            )
        )
        for i in range(n):
            inc = segment_lane(seg, i, forward=True, stop_back_m=1.0 + STOP_LINE_WIDTH_M)
            lanes[f"{name}_in_{i}"] = replace(inc, lane_id=f"{name}_in_{i}", light_id=k)
            # the backward lanes of this arm leave the intersection towards `name`
            out = segment_lane(seg, i, forward=False)
            lanes[f"{name}_out_{i}"] = replace(out, lane_id=f"{name}_out_{i}")
    for k, name in enumerate(_APPROACHES):
        heading = k * math.pi / 2.0
        for i in range(n):
            d = (i + 0.5) * w
            x, y = _rot(k, -half, -d)
            start = (x, y, heading)
            opposite = _APPROACHES[(k + 2) % 4]
            lid = f"{name}_{opposite}_{i}"
            lanes[lid] = _straight_lane(lid, start, length_m=2 * half, width_m=w)
            if i == 0:
                left = _APPROACHES[(k + 3) % 4]
                lid = f"{name}_{left}_{i}"
                lanes[lid] = _arc_lane(
                    lid, start, radius_m=half + d, turn_rad=math.pi / 2, width_m=w
                )
            if i == n - 1:
                right = _APPROACHES[(k + 1) % 4]
                lid = f"{name}_{right}_{i}"
                lanes[lid] = _arc_lane(
                    lid, start, radius_m=half - d, turn_rad=-math.pi / 2, width_m=w
                )
    routes: dict[str, Route] = {}
    for k, name in enumerate(_APPROACHES):
        for i in range(n):
            targets = [_APPROACHES[(k + 2) % 4]]
            if i == 0:
                targets.append(_APPROACHES[(k + 3) % 4])
            if i == n - 1:
                targets.append(_APPROACHES[(k + 1) % 4])
            for to in targets:
                rid = f"{name}_{to}_{i}"
                routes[rid] = Route(
                    rid, [lanes[f"{name}_in_{i}"], lanes[rid], lanes[f"{to}_out_{i}"]]
                )
    return RoadNetwork(
        segments=tuple(segments),
        lanes=lanes,
        routes=routes,
        signals=tuple(signals),
        intersection_half_m=half,
    )


def highway_network(layout: HighwayLayout) -> RoadNetwork:
    """Three segments along +x from the origin; routes ``forward_{i}`` and ``backward_{i}``."""
    n, w = layout.lanes_per_direction, layout.lane_width_m
    turn = math.radians(layout.curve_angle_deg)

    def piece(
        name: str, pose: tuple[float, float, float], length_m: float, k: float
    ) -> RoadSegment:
        return RoadSegment(
            name=name,
            start_xy=(pose[0], pose[1]),
            start_heading_rad=pose[2],
            length_m=length_m,
            curvature_1pm=k,
            lanes_forward=n,
            lanes_backward=n,
            lane_width_m=w,
            shoulder_m=layout.shoulder_m,
            sidewalk_width_m=layout.sidewalk_width_m,
        )

    a = piece("entry", (0.0, 0.0, 0.0), layout.straight_length_m, 0.0)
    k = math.copysign(1.0 / layout.curve_radius_m, turn) if turn else 0.0
    b = piece("curve", (layout.straight_length_m, 0.0, 0.0), layout.curve_radius_m * abs(turn), k)
    ex, ey, eh = b.pose_at(b.length_m)
    c = piece("exit", (float(ex), float(ey), float(eh)), layout.exit_length_m, 0.0)
    segs = (a, b, c)
    lanes: dict[str, Lane] = {}
    routes: dict[str, Route] = {}
    for i in range(n):
        fwd = [segment_lane(s, i, forward=True) for s in segs]
        bwd = [segment_lane(s, i, forward=False) for s in reversed(segs)]
        for lane in (*fwd, *bwd):
            lanes[lane.lane_id] = lane
        routes[f"forward_{i}"] = Route(f"forward_{i}", fwd)
        routes[f"backward_{i}"] = Route(f"backward_{i}", bwd)
    return RoadNetwork(segments=segs, lanes=lanes, routes=routes)
