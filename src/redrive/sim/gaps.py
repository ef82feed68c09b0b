"""Every agent's gap to its leader in one batch: ``gap_ahead`` (the plain-Python reference in
``tests/sim/_reference_agents.py``) compiled.

The world asks, every physics step, for each lane follower and the scripted ego: the nearest
obstacle ahead on its route (bumper-to-bumper gap and the leader's speed along the route).  One
``gap_ahead`` per agent costs a dozen small numpy calls each; :meth:`GapSearch.gaps` answers
all agents' :class:`GapQuery` with one call of a numba kernel over the routes of one network
concatenated once (:class:`GapSearch`): per query, the route piece found by bisection, the
bounding-box filter of :meth:`~redrive.sim.roads.Route.near`, the projection of each nearby
obstacle onto the piece and the nearest one ahead, in loops.

The answers are bit for bit those of ``gap_ahead``: every value is computed with the same
float64 operations in the same order (the kernel is compiled without ``fastmath``, so nothing is
reassociated or fused), and ties go to the same (first) segment and the same (first) obstacle.
The projection skips a block of :data:`BLOCK` segments whose bounding box (:attr:`GapSearch.blocks`)
lies farther from the obstacle than the closest segment so far — or than the closest segment of
the block whose box is nearest, looked at first — by more than rounding could explain: no
segment of it could have been the (first) closest one, so the answer is the same.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from redrive.sim import kernels
from redrive.sim.agents import Obstacles
from redrive.sim.roads import Route

__all__ = ["BLOCK", "GapQuery", "GapSearch"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: segments per block of :attr:`GapSearch.blocks` (the projection's coarse test)
BLOCK = 8
#: a block is skipped when its box is farther (squared, m²) than the closest segment so far by
#: more than this plus a relative 1e-9: far above the rounding of either distance
_SKIP_MARGIN_M2 = 1e-6


@dataclass(frozen=True, slots=True, kw_only=True)
class GapQuery:
    """One agent's question, as ``gap_ahead`` takes it (metres)."""

    route: Route
    s_center_m: float
    s_front_m: float
    width_m: float
    self_id: int


class GapSearch:
    """The gap search of the agents on ``routes`` (every route a query may name).

    Args:
        routes: the routes of the network (lane changes included).
        horizon_m: how far ahead of the front bumper an obstacle counts (as ``gap_ahead``).
        margin_m: lateral margin added to half the widths (as ``gap_ahead``).
    """

    def __init__(
        self, routes: Iterable[Route], *, horizon_m: float = 80.0, margin_m: float = 0.4
    ) -> None:
        self.horizon_m = horizon_m
        self.margin_m = margin_m
        self._offset: dict[int, int] = {}
        #: the distinct routes, in the order of their samples in :attr:`net`
        self.routes: list[Route] = []
        points, s_m, heading, norms = [], [], [], []
        n = 0
        for route in routes:
            if id(route) in self._offset:
                continue
            self._offset[id(route)] = n
            self.routes.append(route)
            points.append(route.points)
            s_m.append(route.s_m)
            heading.append(route.heading_rad)
            norms.append([*route.segment_norms(), 1.0])
            n += len(route.s_m)
        pts = np.concatenate(points) if points else np.zeros((0, 2))
        s = np.concatenate(s_m) if s_m else np.zeros(0)
        # per sample i: the segment to sample i + 1 (meaningless at a route's last sample, which
        # no piece uses); the same subtraction as Route.project does on its slices
        seg = pts[1:] - pts[:-1] if n else np.zeros((0, 2))
        seg_len = np.append(s[1:] - s[:-1], 0.0) if n else np.zeros(0)
        seg = np.concatenate([seg, np.zeros((1 if n else 0, 2))])
        #: (9, samples): s, x, y, segment x, segment y, segment length and its square, heading,
        #: and ``math.hypot`` of the segment's unit tangent as ``Route.pose_at`` takes it
        self.net: F64 = np.ascontiguousarray(
            np.stack(
                [
                    s,
                    pts[:, 0],
                    pts[:, 1],
                    seg[:, 0],
                    seg[:, 1],
                    seg_len,
                    seg_len**2,
                    np.concatenate(heading) if heading else np.zeros(0),
                    np.array([v for part in norms for v in part], dtype=np.float64),
                ]
            )
        )
        #: (4, ceil(samples / BLOCK)): per block of BLOCK samples of :attr:`net`, the bounding
        #: box (min x, min y, max x, max y) of its samples and the next block's first one —
        #: every point of the segments that start in the block
        self.blocks: F64 = _block_boxes(pts)
        #: (2, routes): each route's first sample in :attr:`net` and its sample count
        self.route_table: I64 = np.array(
            [[self._offset[id(r)] for r in self.routes], [len(r.s_m) for r in self.routes]],
            dtype=np.int64,
        ).reshape(2, -1)

    def route_row(self, route: Route) -> tuple[int, int]:
        """``route``'s first sample in :attr:`net` and its sample count."""
        return self._offset[id(route)], len(route.s_m)

    def gaps(self, queries: Sequence[GapQuery], obstacles: Obstacles) -> list[tuple[float, float]]:
        """For each query: the gap (metres, inf if none) and the leader's speed along the route
        (m/s), equal to ``gap_ahead(q.route, obstacles, ...)`` of that query."""
        if not queries:
            return []
        q_int = np.array(
            [(self._offset[id(q.route)], len(q.route.s_m), q.self_id) for q in queries],
            dtype=np.int64,
        ).T
        q_float = np.array(
            [(q.s_center_m, q.s_front_m, q.s_front_m + self.horizon_m, q.width_m) for q in queries],
            dtype=np.float64,
        ).T
        obst = np.stack(
            [
                obstacles.centers[:, 0],
                obstacles.centers[:, 1],
                obstacles.lengths,
                obstacles.widths,
                obstacles.velocities[:, 0],
                obstacles.velocities[:, 1],
            ]
        ).reshape(6, -1)
        gap, speed = self.gaps_of(q_int, q_float, np.asarray(obstacles.ids, np.int64), obst)
        return list(zip(gap.tolist(), speed.tolist(), strict=True))

    def gaps_of(self, q_int: I64, q_float: F64, ids: I64, obst: F64) -> tuple[F64, F64]:
        """:meth:`gaps` of queries and obstacles given as arrays: ``q_int`` (3, Q) the route's
        first sample in :attr:`net` and its sample count (:meth:`route_row`) and the agent's id;
        ``q_float`` (4, Q) the arclength of its box centre, of its front, the front plus the
        horizon, and its width; ``ids`` (M,) and ``obst`` (6, M) the obstacles' ids, centre
        x, y, length, width and velocity x, y.  Returns the gaps (inf: none) and the leaders'
        speeds (0 where none)."""
        nq = q_int.shape[1]
        if nq == 0 or len(ids) == 0:
            return np.full(nq, np.inf), np.zeros(nq)
        return _gap_kernel(
            np.ascontiguousarray(q_int, dtype=np.int64),
            np.ascontiguousarray(q_float, dtype=np.float64),
            self.margin_m,
            np.ascontiguousarray(ids, dtype=np.int64),
            np.ascontiguousarray(obst, dtype=np.float64),
            self.net,
            self.blocks,
        )


def _block_boxes(pts: F64) -> F64:
    """:attr:`GapSearch.blocks` of the samples ``pts`` (N, 2)."""
    n = len(pts)
    nb = -(-n // BLOCK)
    out = np.zeros((4, nb))
    for b in range(nb):
        part = pts[b * BLOCK : min((b + 1) * BLOCK + 1, n)]
        out[0, b], out[1, b] = part[:, 0].min(), part[:, 1].min()
        out[2, b], out[3, b] = part[:, 0].max(), part[:, 1].max()
    return np.ascontiguousarray(out)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _gap_kernel(  # noqa: PLR0917 (one batch's arrays; numba has no keyword-only parameters)
    q_int: I64, q_float: F64, margin: float, ids: I64, obst: F64, net: F64, blocks: F64
) -> tuple[F64, F64]:  # pragma: no cover - compiled
    """Per query: the gap and the leader's speed along the route (inf and 0: none).

    What ``gap_ahead`` computes, pair by pair: ``Route._piece``, ``Route.near``,
    ``Route.project`` and the nearest obstacle ahead (first minimum, as ``np.argmin``).

    ``q_int``: (3, Q) the route's first sample in ``net``, its sample count, the agent's id;
    ``q_float``: (4, Q) arclength of the box centre, of the front, the horizon's end, the width;
    ``obst``: (6, M) centre x, y, length, width, velocity x, y; ``net``: ``GapSearch.net``;
    ``blocks``: ``GapSearch.blocks``.
    """
    route_off, route_n, self_ids = q_int[0], q_int[1], q_int[2]
    s_center, s_front, s_max, widths = q_float[0], q_float[1], q_float[2], q_float[3]
    obst_x, obst_y, lengths, obst_widths = obst[0], obst[1], obst[2], obst[3]
    net_s, net_x, net_y = net[0], net[1], net[2]
    seg_x, seg_y, seg_len, seg_len2 = net[3], net[4], net[5], net[6]
    nq, nm = len(s_center), len(ids)
    gap_out = np.full(nq, np.inf)
    speed_out = np.zeros(nq)
    net_h = net[7]
    for q in range(nq):
        off, n = route_off[q], route_n[q]
        last = n - 1
        # Route._piece(s_center, s_max): segments lo … hi - 1 of the route
        lo = min(max(kernels.bisect_right(net_s, off, off + n, s_center[q]) - 1, 0), last - 1)
        hi = min(kernels.bisect_left(net_s, off, off + n, s_max[q]) + 1, last)
        hi = max(hi, lo + 1)
        g0, g1 = off + lo, off + hi  # global samples of the piece: g0 … g1
        low_x, low_y = net_x[g0], net_y[g0]
        high_x, high_y = low_x, low_y
        for i in range(g0 + 1, g1 + 1):
            low_x = min(low_x, net_x[i])
            low_y = min(low_y, net_y[i])
            high_x = max(high_x, net_x[i])
            high_y = max(high_y, net_y[i])
        best_gap = np.inf
        best_m = -1
        best_s = 0.0
        for m in range(nm):
            reach = (widths[q] + obst_widths[m]) / 2.0 + margin
            if ids[m] == self_ids[q]:
                continue
            cx, cy = obst_x[m], obst_y[m]
            # Route.near: outside the piece's bounding box grown by the reach
            ox = max(low_x - cx, cx - high_x, 0.0)
            oy = max(low_y - cy, cy - high_y, 0.0)
            r = reach + 1e-6
            if not (ox * ox + oy * oy) < r * r:
                continue
            # Route.project onto segments g0 … g1 - 1: the first closest one.  A bound of the
            # least distance first: the least of the segments of the block whose box is
            # nearest (a distance some segment has, so no block farther than it can hold the
            # first closest segment: the blocks before that one are skipped too)
            near_b, near_d2 = g0 // BLOCK, np.inf
            for b in range(g0 // BLOCK, (g1 - 1) // BLOCK + 1):
                bx = max(blocks[0, b] - cx, cx - blocks[2, b], 0.0)
                by = max(blocks[1, b] - cy, cy - blocks[3, b], 0.0)
                if bx * bx + by * by < near_d2:
                    near_b, near_d2 = b, bx * bx + by * by
            bound_d2 = np.inf
            for i in range(max(near_b * BLOCK, g0), min((near_b + 1) * BLOCK, g1)):
                rx, ry = cx - net_x[i], cy - net_y[i]
                t = ((rx * seg_x[i] + ry * seg_y[i]) + 0.0) / seg_len2[i]
                t = min(max(t, 0.0), 1.0)
                dx, dy = rx - t * seg_x[i], ry - t * seg_y[i]
                bound_d2 = min(bound_d2, dx * dx + dy * dy)
            best_d2 = np.inf
            bj = g0
            bt = brx = bry = 0.0
            start = g0
            while start < g1:
                b = start // BLOCK
                stop = min((b + 1) * BLOCK, g1)
                if start > g0:  # the first segment always counts (a tie keeps it)
                    bx = max(blocks[0, b] - cx, cx - blocks[2, b], 0.0)
                    by = max(blocks[1, b] - cy, cy - blocks[3, b], 0.0)
                    least = min(best_d2, bound_d2)
                    if bx * bx + by * by > least * (1.0 + 1e-9) + _SKIP_MARGIN_M2:
                        start = stop
                        continue
                for i in range(start, stop):
                    rx, ry = cx - net_x[i], cy - net_y[i]
                    t = ((rx * seg_x[i] + ry * seg_y[i]) + 0.0) / seg_len2[i]
                    t = min(max(t, 0.0), 1.0)
                    dx, dy = rx - t * seg_x[i], ry - t * seg_y[i]
                    d2 = dx * dx + dy * dy
                    if i == g0 or d2 < best_d2:
                        best_d2, bj, bt, brx, bry = d2, i, t, rx, ry
                start = stop
            s = net_s[bj] + bt * seg_len[bj]
            cross = seg_x[bj] * bry - seg_y[bj] * brx
            lateral = (-1.0 if cross < 0.0 else 1.0) * math.sqrt(best_d2)
            if s > s_center[q] + 1e-6 and s < s_max[q] - 1e-6 and abs(lateral) < reach:
                gap = s - lengths[m] / 2.0 - s_front[q]
                if gap < best_gap:
                    best_gap, best_m, best_s = gap, m, s
        if best_m >= 0:
            # the leader's velocity along the route's heading there (Route.pose_at's)
            j = min(max(kernels.bisect_right(net_s, off, off + n, best_s) - 1, 0), n - 2) + off
            t = (best_s - net_s[j]) / (net_s[j + 1] - net_s[j])
            heading = net_h[j] + min(max(t, 0.0), 1.0) * (net_h[j + 1] - net_h[j])
            vx, vy = obst[4, best_m], obst[5, best_m]
            gap_out[q] = best_gap
            speed_out[q] = vx * math.cos(heading) + vy * math.sin(heading)
    return gap_out, speed_out
