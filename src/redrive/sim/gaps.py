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

    def gaps(self, queries: Sequence[GapQuery], obstacles: Obstacles) -> list[tuple[float, float]]:
        """For each query: the gap (metres, inf if none) and the leader's speed along the route
        (m/s), equal to ``gap_ahead(q.route, obstacles, ...)`` of that query."""
        nq = len(queries)
        none = [(math.inf, 0.0)] * nq
        if nq == 0 or len(obstacles.ids) == 0:
            return none
        horizon = self.horizon_m
        lo_g, n_seg = np.empty(nq, dtype=np.int64), np.empty(nq, dtype=np.int64)
        s_center, s_front, s_max = np.empty(nq), np.empty(nq), np.empty(nq)
        widths, self_ids = np.empty(nq), np.empty(nq, dtype=np.int64)
        for k, q in enumerate(queries):
            top = q.s_front_m + horizon
            lo, hi = q.route._piece(q.s_center_m, top)
            lo_g[k] = self._offset[id(q.route)] + lo
            n_seg[k] = hi - lo
            s_center[k], s_front[k], s_max[k] = q.s_center_m, q.s_front_m, top
            widths[k], self_ids[k] = q.width_m, q.self_id
        centers = obstacles.centers
        span = int(n_seg.max())
        cols = np.arange(span + 1)
        # the piece's samples lo … hi (hi - lo segments), padded with its first sample
        in_piece = cols[None, :] <= n_seg[:, None]
        samples = np.where(in_piece, lo_g[:, None] + cols[None, :], lo_g[:, None])
        piece = self._points[samples]  # (Q, span + 1, 2)
        low = np.where(in_piece[..., None], piece, np.inf).min(axis=1)
        high = np.where(in_piece[..., None], piece, -np.inf).max(axis=1)
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
        valid = in_piece[qk, 1:]  # segment j of the piece exists when j < hi - lo
        # (P, span) segment indices (segment i runs from sample i to i + 1), padded with the first
        seg_idx = np.where(valid, samples[qk, :span], lo_g[qk][:, None])
        a = self._points[seg_idx]
        seg = self._seg[seg_idx]
        seg_len = self._seg_len[seg_idx]
        rel = centers[mk][:, None, :] - a
        t = np.clip((rel * seg).sum(-1) / self._seg_len2[seg_idx], 0.0, 1.0)
        diff = rel - t[..., None] * seg
        dist2 = np.where(valid, (diff**2).sum(-1), np.inf)
        j = np.argmin(dist2, axis=1)
        rows = np.arange(len(qk))
        s = self._s[lo_g[qk] + j] + t[rows, j] * seg_len[rows, j]
        sj = seg[rows, j]
        cross = sj[:, 0] * rel[rows, j, 1] - sj[:, 1] * rel[rows, j, 0]
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
