"""Helpers shared by the planning and control metrics: the logged ego track, planar frames,
polylines, the kinematics of a planned path, and oriented-rectangle overlap.

Everything here is planar (bird's-eye view): x, y in metres, headings in radians about +z.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.types import VehicleState

__all__ = [
    "EgoTrack",
    "PathKinematics",
    "base_from_map_xy",
    "ego_footprint_corners",
    "path_kinematics",
    "polyline_pose_at",
    "project_on_polyline",
    "rectangle_corners",
    "rectangles_overlap",
    "wrap_angle",
]

F64 = npt.NDArray[np.float64]

#: below this plan speed (m/s) the direction of motion (heading) is held from the last faster
#: waypoint: a stopped plan has no direction of its own.
HEADING_MIN_SPEED_MPS = 0.2


def wrap_angle(angle_rad: npt.ArrayLike) -> F64:
    """Angles wrapped to [−π, π)."""
    a = np.asarray(angle_rad, dtype=np.float64)
    return np.asarray((a + math.pi) % (2.0 * math.pi) - math.pi, dtype=np.float64)


def base_from_map_xy(xy: npt.ArrayLike, origin_xy: npt.ArrayLike, heading_rad: float) -> F64:
    """Points ``xy`` (N, 2) of the map frame expressed in the base_link of a pose (origin, heading).

    ``p_base = R(−heading) (p_map − origin)`` (planar; z is ignored).
    """
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2) - np.asarray(origin_xy, dtype=np.float64)
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    return np.column_stack([c * p[:, 0] + s * p[:, 1], -s * p[:, 0] + c * p[:, 1]])


@dataclass(frozen=True, slots=True)
class EgoTrack:
    """The logged ego, frame by frame, ready to interpolate in time.

    Attributes:
        frames: frame indices (N,), in stamp order.
        stamps_ns: the states' stamps (N,), increasing.
        xy: rear-axle positions (N, 2), m, in the ego table's frame (``map``/``odom``).
        heading_rad: headings (N,), unwrapped (continuous), rad.
        speed_mps: speeds over ground (N,), m/s (norm of vx, vy).
    """

    frames: npt.NDArray[np.int64]
    stamps_ns: npt.NDArray[np.int64]
    xy: F64
    heading_rad: F64
    speed_mps: F64

    @classmethod
    def from_states(cls, states: Mapping[int, VehicleState]) -> EgoTrack:
        items = sorted(states.items(), key=lambda kv: (kv[1].stamp_ns, kv[0]))
        frames = np.array([k for k, _ in items], dtype=np.int64)
        stamps = np.array([s.stamp_ns for _, s in items], dtype=np.int64)
        if stamps.size > 1 and np.any(np.diff(stamps) <= 0):
            keep = np.concatenate([[True], np.diff(stamps) > 0])
            items = [it for it, k in zip(items, keep, strict=True) if k]
            frames, stamps = frames[keep], stamps[keep]
        xy = np.array([s.position[:2] for _, s in items], dtype=np.float64).reshape(-1, 2)
        heading = np.unwrap(np.array([s.heading_rad for _, s in items], dtype=np.float64))
        speed = np.array([s.speed_mps for _, s in items], dtype=np.float64)
        return cls(frames, stamps, xy, heading, speed)

    def __len__(self) -> int:
        return int(self.stamps_ns.size)

    def covers(self, stamp_ns: int) -> bool:
        """Whether ``stamp_ns`` lies within the logged span (interpolation, not extrapolation)."""
        return len(self) > 0 and int(self.stamps_ns[0]) <= stamp_ns <= int(self.stamps_ns[-1])

    def interpolate(self, stamps_ns: npt.ArrayLike) -> tuple[F64, F64]:
        """Position (M, 2) and heading (M,) at ``stamps_ns``, linear in time; NaN outside the
        logged span."""
        q = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        if len(self) == 0:
            nan = np.full(q.size, np.nan)
            return np.column_stack([nan, nan]), nan
        t0 = int(self.stamps_ns[0])
        tk = (self.stamps_ns - t0).astype(np.float64)
        tq = (q - t0).astype(np.float64)
        x = np.interp(tq, tk, self.xy[:, 0])
        y = np.interp(tq, tk, self.xy[:, 1])
        h = np.interp(tq, tk, self.heading_rad)
        outside = (q < self.stamps_ns[0]) | (q > self.stamps_ns[-1])
        x[outside] = y[outside] = h[outside] = np.nan
        return np.column_stack([x, y]), h

    def samples_between(self, first_ns: int, last_ns: int) -> F64:
        """Logged positions (N, 2) with ``first_ns <= stamp <= last_ns``, both ends interpolated
        in: the logged route driven over that span."""
        inside = (self.stamps_ns > first_ns) & (self.stamps_ns < last_ns)
        ends, _ = self.interpolate([first_ns, last_ns])
        return np.vstack([ends[:1], self.xy[inside], ends[1:]])


@dataclass(frozen=True, slots=True)
class PathKinematics:
    """Finite-difference kinematics of a planned path, per waypoint (K,) after dropping repeated
    times. Accelerations are split along (lon) and across (lat) the direction of motion."""

    t_s: F64
    xy: F64
    velocity_xy: F64
    speed_mps: F64
    heading_rad: F64
    lon_accel_mps2: F64
    lat_accel_mps2: F64
    yaw_rate_rad_s: F64
    yaw_accel_rad_s2: F64
    lon_jerk_mps3: F64
    jerk_mag_mps3: F64


def path_kinematics(waypoints: npt.ArrayLike) -> PathKinematics | None:
    """Derivatives of a plan ``(K, 4)`` = x, y, z, t_s by ``numpy.gradient`` (second-order
    central differences inside, second-order one-sided at both ends: exact for paths whose x(t)
    and y(t) are quadratic). None when fewer than 3 distinct times remain.

    heading = atan2(vy, vx), held from the previous waypoint while the speed is below
    :data:`HEADING_MIN_SPEED_MPS` (0 at the start of a plan that never moves); yaw rate and yaw
    acceleration are its first and second derivatives; lon/lat acceleration are the projections
    of (ax, ay) on the heading and its left normal; lon jerk = d(lon accel)/dt; jerk magnitude =
    d|a|/dt, the derivative of the acceleration magnitude as nuPlan's ``extract_ego_jerk``
    (``acceleration_coordinate="magnitude"``) takes it.
    """
    wp = np.asarray(waypoints, dtype=np.float64).reshape(-1, 4)
    if wp.shape[0] == 0:
        return None
    keep = np.concatenate([[True], np.diff(wp[:, 3]) > 0])
    wp = wp[keep]
    if wp.shape[0] < 3:
        return None
    t, x, y = wp[:, 3], wp[:, 0], wp[:, 1]
    vx = np.gradient(x, t, edge_order=2)
    vy = np.gradient(y, t, edge_order=2)
    speed = np.hypot(vx, vy)
    raw = np.arctan2(vy, vx)
    heading = np.zeros_like(raw)
    last = 0.0
    moving = speed >= HEADING_MIN_SPEED_MPS
    if moving.any():
        last = float(raw[int(np.argmax(moving))])
    for k in range(raw.size):
        if moving[k]:
            last = float(raw[k])
        heading[k] = last
    heading = np.unwrap(heading)
    ax = np.gradient(vx, t, edge_order=2)
    ay = np.gradient(vy, t, edge_order=2)
    c, s = np.cos(heading), np.sin(heading)
    lon = ax * c + ay * s
    lat = -ax * s + ay * c
    yaw_rate = np.gradient(heading, t, edge_order=2)
    return PathKinematics(
        t_s=t,
        xy=np.column_stack([x, y]),
        velocity_xy=np.column_stack([vx, vy]),
        speed_mps=speed,
        heading_rad=heading,
        lon_accel_mps2=lon,
        lat_accel_mps2=lat,
        yaw_rate_rad_s=yaw_rate,
        yaw_accel_rad_s2=np.gradient(yaw_rate, t, edge_order=2),
        lon_jerk_mps3=np.gradient(lon, t, edge_order=2),
        jerk_mag_mps3=np.gradient(np.hypot(ax, ay), t, edge_order=2),
    )


def _clean_polyline(xy: npt.ArrayLike) -> F64:
    """Consecutive repeated points removed; a single point gets a unit step along +x."""
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] == 0:
        return np.array([[0.0, 0.0], [1.0, 0.0]])
    step = np.hypot(*np.diff(p, axis=0).T) if p.shape[0] > 1 else np.zeros(0)
    p = p[np.concatenate([[True], step > 1e-9])]
    if p.shape[0] == 1:
        p = np.vstack([p, p + np.array([1.0, 0.0])])
    return p


def project_on_polyline(points: npt.ArrayLike, polyline: npt.ArrayLike) -> tuple[F64, F64, F64]:
    """Nearest point of a polyline to each of ``points`` (N, 2).

    The first segment is extended backwards and the last forwards (a point beyond the end
    projects onto the extension, so arc length may be < 0 or > the length).

    Returns:
        arc length along the polyline (N,) m, signed lateral offset (N,) m (positive: the point
        lies left of the direction of travel), tangent heading at the nearest point (N,) rad.
    """
    q = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    p = _clean_polyline(polyline)
    a, b = p[:-1], p[1:]
    d = b - a
    seg_len = np.hypot(d[:, 0], d[:, 1])
    s0 = np.concatenate([[0.0], np.cumsum(seg_len)])[:-1]
    rel = q[:, None, :] - a[None, :, :]
    u = (rel * d[None]).sum(-1) / (seg_len**2)[None]
    lo = np.zeros_like(u)
    hi = np.ones_like(u)
    lo[:, 0] = -np.inf
    hi[:, -1] = np.inf
    uc = np.clip(u, lo, hi)
    near = a[None] + uc[..., None] * d[None]
    dist = np.hypot(*(q[:, None, :] - near).transpose(2, 0, 1))
    j = np.argmin(dist, axis=1)
    rows = np.arange(q.shape[0])
    tangent = d[j] / seg_len[j, None]
    rel_j = q - near[rows, j]
    lateral = tangent[:, 0] * rel_j[:, 1] - tangent[:, 1] * rel_j[:, 0]
    arc = s0[j] + uc[rows, j] * seg_len[j]
    return arc, lateral, np.arctan2(tangent[:, 1], tangent[:, 0])


def polyline_pose_at(polyline: npt.ArrayLike, arc_m: npt.ArrayLike) -> tuple[F64, F64]:
    """Position (N, 2) and heading (N,) at arc lengths ``arc_m`` along a polyline, extrapolated
    straight beyond either end."""
    p = _clean_polyline(polyline)
    d = np.diff(p, axis=0)
    seg_len = np.hypot(d[:, 0], d[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    s = np.asarray(arc_m, dtype=np.float64).reshape(-1)
    j = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, seg_len.size - 1)
    u = (s - cum[j]) / seg_len[j]
    xy = p[j] + u[:, None] * d[j]
    return xy, np.arctan2(d[j, 1], d[j, 0])


def rectangle_corners(
    center_xy: npt.ArrayLike,
    yaw_rad: npt.ArrayLike,
    length_m: npt.ArrayLike,
    width_m: npt.ArrayLike,
) -> F64:
    """Corners (N, 4, 2) of oriented rectangles: front-left, rear-left, rear-right, front-right
    ("front" is the +x of the rectangle's heading)."""
    c = np.asarray(center_xy, dtype=np.float64).reshape(-1, 2)
    yaw = np.broadcast_to(np.asarray(yaw_rad, dtype=np.float64), (c.shape[0],))
    half_l = np.broadcast_to(np.asarray(length_m, dtype=np.float64), (c.shape[0],)) / 2
    half_w = np.broadcast_to(np.asarray(width_m, dtype=np.float64), (c.shape[0],)) / 2
    signs = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
    local = signs[None] * np.stack([half_l, half_w], axis=-1)[:, None, :]
    cos, sin = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x = cos * local[..., 0] - sin * local[..., 1]
    y = sin * local[..., 0] + cos * local[..., 1]
    return np.stack([x, y], axis=-1) + c[:, None, :]


def ego_footprint_corners(
    rear_axle_xy: npt.ArrayLike,
    heading_rad: npt.ArrayLike,
    *,
    length_m: float,
    width_m: float,
    rear_overhang_m: float,
) -> F64:
    """Corners (N, 4, 2) of the ego footprint for rear-axle poses: the rectangle's centre lies
    ``length/2 − rear_overhang`` ahead of the rear axle along the heading."""
    xy = np.asarray(rear_axle_xy, dtype=np.float64).reshape(-1, 2)
    h = np.broadcast_to(np.asarray(heading_rad, dtype=np.float64), (xy.shape[0],))
    shift = length_m / 2.0 - rear_overhang_m
    centre = xy + shift * np.column_stack([np.cos(h), np.sin(h)])
    return rectangle_corners(centre, h, length_m, width_m)


def rectangles_overlap(a: npt.ArrayLike, b: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """Whether rectangles ``a`` and ``b`` (..., 4, 2 corners, broadcast against each other)
    overlap, by the separating axis theorem on the two edge normals of each: they are apart
    only when some axis separates their projections strictly (touching counts as overlap, as
    shapely's ``intersects`` in nuPlan's ``in_collision``)."""
    ca = np.asarray(a, dtype=np.float64)
    cb = np.asarray(b, dtype=np.float64)
    ca, cb = np.broadcast_arrays(ca, cb)
    apart = np.zeros(ca.shape[:-2], dtype=bool)
    for corners in (ca, cb):
        for e0, e1 in ((0, 1), (1, 2)):
            edge = corners[..., e1, :] - corners[..., e0, :]
            axis = np.stack([-edge[..., 1], edge[..., 0]], axis=-1)
            pa = (ca * axis[..., None, :]).sum(-1)
            pb = (cb * axis[..., None, :]).sum(-1)
            scale = np.hypot(axis[..., 0], axis[..., 1]) * 1e-12
            apart |= (pa.max(-1) < pb.min(-1) - scale) | (pb.max(-1) < pa.min(-1) - scale)
    return ~apart
