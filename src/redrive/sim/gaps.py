"""Every agent's gap to its leader in one batch: :func:`redrive.sim.agents.gap_ahead` vectorised.

The world asks, every physics step, for each lane follower and the scripted ego: the nearest
obstacle ahead on its route (bumper-to-bumper gap and the leader's speed along the route).  One
:func:`gap_ahead` per agent costs a dozen small numpy calls each; :meth:`GapSearch.gaps` answers
all agents' :class:`GapQuery` with one set of numpy calls on arrays of (query, obstacle, route
sample), over the routes of one network concatenated once (:class:`GapSearch`).

The answers are bit for bit those of :func:`gap_ahead`: every value is computed with the same
elementwise float64 operations in the same order (a route piece is the same samples, padded
with segments that can never be the closest), and ties go to the same (first) segment and the
same (first) obstacle.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.sim.agents import Obstacles
from redrive.sim.roads import Route

__all__ = ["GapQuery", "GapSearch"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True, kw_only=True)
class GapQuery:
    """One agent's question, as :func:`redrive.sim.agents.gap_ahead` takes it (metres)."""

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
        points, s_m = [], []
        n = 0
        for route in routes:
            if id(route) in self._offset:
                continue
            self._offset[id(route)] = n
            points.append(route.points)
            s_m.append(route.s_m)
            n += len(route.s_m)
        pts = np.concatenate(points) if points else np.zeros((0, 2))
        s = np.concatenate(s_m) if s_m else np.zeros(0)
        self._points: F64 = pts
        self._s: F64 = s
        # per sample i: the segment to sample i + 1 (meaningless at a route's last sample, which
        # no piece uses); the same subtraction as Route.project does on its slices
        self._seg: F64 = pts[1:] - pts[:-1] if n else np.zeros((0, 2))
        self._seg_len: F64 = s[1:] - s[:-1] if n else np.zeros(0)
        self._seg_len2: F64 = self._seg_len**2
        self._x, self._y = pts[:, 0].copy(), pts[:, 1].copy()
        self._seg_x, self._seg_y = self._seg[:, 0].copy(), self._seg[:, 1].copy()
        # sparse tables of the samples' running min and max: level k holds, at sample i, the
        # bounding box of samples i … i + 2^k - 1 (a piece's box is two look-ups of one level)
        low, high = [pts], [pts]
        while 2 ** len(low) <= n:
            half = 2 ** (len(low) - 1)
            low.append(np.minimum(low[-1][:-half], low[-1][half:]))
            high.append(np.maximum(high[-1][:-half], high[-1][half:]))
        # (levels, samples, 2), the tail of each level (no full run there) never read
        self._low: F64 = np.stack([np.concatenate([lv, np.zeros((n - len(lv), 2))]) for lv in low])
        self._high: F64 = np.stack(
            [np.concatenate([lv, np.zeros((n - len(lv), 2))]) for lv in high]
        )

    def gaps(self, queries: Sequence[GapQuery], obstacles: Obstacles) -> list[tuple[float, float]]:
        """For each query: the gap (metres, inf if none) and the leader's speed along the route
        (m/s), equal to ``gap_ahead(q.route, obstacles, ...)`` of that query."""
        nq = len(queries)
        none = [(math.inf, 0.0)] * nq
        if nq == 0 or len(obstacles.ids) == 0:
            return none
        horizon = self.horizon_m
        pieces = [q.route._piece(q.s_center_m, q.s_front_m + horizon) for q in queries]
        lo_g = np.array(
            [self._offset[id(q.route)] + lo for q, (lo, _) in zip(queries, pieces, strict=True)],
            dtype=np.int64,
        )
        n_seg = np.array([hi - lo for lo, hi in pieces], dtype=np.int64)
        s_center = np.array([q.s_center_m for q in queries])
        s_front = np.array([q.s_front_m for q in queries])
        s_max = np.array([q.s_front_m + horizon for q in queries])
        widths = np.array([q.width_m for q in queries])
        self_ids = np.array([q.self_id for q in queries], dtype=np.int64)
        centers = obstacles.centers
        span = int(n_seg.max())
        cols = np.arange(span)
        # the bounding box of each piece's samples lo … hi (hi - lo + 1 of them)
        level = np.frexp(n_seg + 1)[1] - 1  # floor(log2(hi - lo + 1)), exactly
        last = lo_g + n_seg + 1 - np.left_shift(1, level)
        low = np.minimum(self._low[level, lo_g], self._low[level, last])
        high = np.maximum(self._high[level, lo_g], self._high[level, last])
        reach = (widths[:, None] + obstacles.widths[None, :]) / 2.0 + self.margin_m  # (Q, M)
        # Route.near: what lies outside every piece's bounding box grown by the reach can never
        # be in the lane; project only the rest (a superset of what is ahead)
        outside = np.maximum(
            np.maximum(low[:, None, :] - centers[None], centers[None] - high[:, None, :]), 0.0
        )
        near = ((outside**2).sum(axis=2) < (reach + 1e-6) ** 2) & (
            obstacles.ids[None, :] != self_ids[:, None]
        )
        qk, mk = np.nonzero(near)
        if len(qk) == 0:
            return none
        # Route.project of each (query, obstacle) pair onto the query's piece
        valid = cols[None, :] < n_seg[qk][:, None]  # segment j of the piece: j < hi - lo
        # (P, span) segment indices (segment i runs from sample i to i + 1), padded with the first
        first_seg = lo_g[qk][:, None]
        seg_idx = np.where(valid, first_seg + cols[None, :], first_seg)
        # x and y apart: the sums over the two coordinates written out are several times
        # faster than .sum(-1) and equal to it (+ 0.0 makes a sum of two -0.0 the +0.0 that
        # numpy's reduction, which starts from +0.0, gives)
        rel_x = centers[mk, 0:1] - self._x[seg_idx]
        rel_y = centers[mk, 1:2] - self._y[seg_idx]
        seg_x, seg_y = self._seg_x[seg_idx], self._seg_y[seg_idx]
        seg_len = self._seg_len[seg_idx]
        t = np.clip(((rel_x * seg_x + rel_y * seg_y) + 0.0) / self._seg_len2[seg_idx], 0.0, 1.0)
        diff_x, diff_y = rel_x - t * seg_x, rel_y - t * seg_y
        dist2 = np.where(valid, diff_x**2 + diff_y**2, np.inf)
        j = np.argmin(dist2, axis=1)
        rows = np.arange(len(qk))
        s = self._s[lo_g[qk] + j] + t[rows, j] * seg_len[rows, j]
        cross = seg_x[rows, j] * rel_y[rows, j] - seg_y[rows, j] * rel_x[rows, j]
        lateral = np.where(cross < 0.0, -1.0, 1.0) * np.sqrt(dist2[rows, j])
        ahead = (
            (s > s_center[qk] + 1e-6) & (s < s_max[qk] - 1e-6) & (np.abs(lateral) < reach[qk, mk])
        )
        pair_gaps = np.where(ahead, s - obstacles.lengths[mk] / 2.0 - s_front[qk], np.inf)
        gap_matrix = np.full(near.shape, np.inf)
        gap_matrix[qk, mk] = pair_gaps
        s_matrix = np.zeros(near.shape)
        s_matrix[qk, mk] = s
        leaders = np.argmin(gap_matrix, axis=1)
        out = none.copy()
        for k in np.flatnonzero(np.isfinite(gap_matrix[np.arange(nq), leaders])).tolist():
            m = int(leaders[k])
            _, _, heading = queries[k].route.pose_at(float(s_matrix[k, m]))
            vx, vy = obstacles.velocities[m]
            out[k] = (
                float(gap_matrix[k, m]),
                float(vx * math.cos(heading) + vy * math.sin(heading)),
            )
        return out
