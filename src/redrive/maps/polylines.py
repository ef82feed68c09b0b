"""Points against polylines as GEOS measures them, in one compiled pass over many pairs.

``shapely.distance(point, line)`` and ``shapely.line_locate_point(line, point)`` cost a GEOS
call each (and a Python one per array of them); the map's queries ask them for thousands of
(point, polyline) pairs.  The kernels here do the same floating-point operations in the same
order as GEOS (3.14: ``DistanceOp`` on a point and a linestring — the least over the segments
of ``Distance::pointToSegment`` —, and ``LengthIndexOfPoint::indexOf`` for the projection — the
first segment in order at the least distance, its ``segmentNearestMeasure``), so the results
are the same doubles; only segments whose bounding box is farther from the point than the best
distance so far (by a relative margin of 1e-9, far above rounding) are skipped, and a skipped
segment could not have been chosen.  The segments are taken in chunks of :data:`_CHUNK` in
order, and a chunk whose bounding box is that far is skipped whole (each of its segments' boxes
lies in it, so each would have been skipped: the same results, without a visit to every segment
of a long polyline for every point).  A point on the same polyline as the point before it starts
from that point's nearest segment (points along a path: most segments are then skipped), and the
first segment in order at the least distance is still the one taken; a run of points on one
polyline measures its segments' lengths and its chunks' boxes once.

The polylines are given as one vertex array ``coords`` (V, 2) and ``offsets`` (L + 1,): polyline
``k`` is ``coords[offsets[k]:offsets[k + 1]]`` (a one-vertex polyline is a point).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["packed", "polyline_distances", "polyline_locate"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
#: a segment whose bounding box is farther than the best distance times this is skipped
_SKIP = 1.0 + 1e-9
#: consecutive segments whose common bounding box is tested first (the box of a run of them)
_CHUNK = 16


def packed(lines: Sequence[npt.ArrayLike]) -> tuple[F64, I64]:
    """``(coords, offsets)`` of polylines given as (N_k, 2) vertex arrays."""
    arrays = [np.asarray(line, dtype=np.float64).reshape(-1, 2) for line in lines]
    offsets = np.zeros(len(arrays) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([a.shape[0] for a in arrays])
    coords = np.ascontiguousarray(np.concatenate(arrays)) if arrays else np.zeros((0, 2))
    return coords, offsets


def polyline_distances(
    points: npt.ArrayLike, line_of: npt.ArrayLike, coords: F64, offsets: I64
) -> F64:
    """(P,) ``shapely.distance`` of each point (P, 2) and its polyline ``line_of[i]``."""
    p, which = _arguments(points, line_of)
    if p.shape[0] == 0:
        return np.zeros(0)
    out: F64 = _distances(p, which, coords, offsets)
    return out


def polyline_locate(
    points: npt.ArrayLike, line_of: npt.ArrayLike, coords: F64, offsets: I64
) -> tuple[F64, F64]:
    """(P,) ``shapely.line_locate_point`` of each point (P, 2) on its polyline ``line_of[i]``
    (of at least two vertices), and (P,) their ``shapely.distance``."""
    p, which = _arguments(points, line_of)
    if p.shape[0] == 0:
        return np.zeros(0), np.zeros(0)
    s, d = _locate(p, which, coords, offsets)
    return s, d


def _arguments(points: npt.ArrayLike, line_of: npt.ArrayLike) -> tuple[F64, I64]:
    p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
    which = np.ascontiguousarray(np.asarray(line_of, dtype=np.int64).reshape(-1))
    if which.shape[0] != p.shape[0]:
        msg = f"{p.shape[0]} points but {which.shape[0]} polyline numbers"
        raise ValueError(msg)
    return p, which


@numba.njit(cache=True, nogil=True)
def _far(  # noqa: PLR0917 (numba has no keyword-only parameters)
    px: float, py: float, ax: float, ay: float, bx: float, by: float, best: float
) -> bool:
    """The segment's bounding box is farther from the point than ``best`` (by the margin)."""
    gx = max(min(ax, bx) - px, px - max(ax, bx), 0.0)
    gy = max(min(ay, by) - py, py - max(ay, by), 0.0)
    return gx * gx + gy * gy > best * best * _SKIP


@numba.njit(cache=True, nogil=True)
def _chunk_boxes(coords: F64, lo: int, hi: int, boxes: F64) -> None:
    """``boxes[c]`` (x min, y min, x max, y max) of the segments ``lo + c·_CHUNK`` … of the
    polyline ``coords[lo:hi]`` (a chunk's vertices and the first of the next chunk)."""
    for c in range((hi - lo - 2) // _CHUNK + 1):
        first = lo + c * _CHUNK
        last = min(first + _CHUNK, hi - 1)
        x0 = x1 = coords[first, 0]
        y0 = y1 = coords[first, 1]
        for v in range(first + 1, last + 1):
            x0, x1 = min(x0, coords[v, 0]), max(x1, coords[v, 0])
            y0, y1 = min(y0, coords[v, 1]), max(y1, coords[v, 1])
        boxes[c, 0], boxes[c, 1], boxes[c, 2], boxes[c, 3] = x0, y0, x1, y1


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _point_to_segment(  # noqa: PLR0917 (numba has no keyword-only parameters)
    px: float, py: float, ax: float, ay: float, bx: float, by: float
) -> float:
    """GEOS's ``Distance::pointToSegment``."""
    if ax == bx and ay == by:
        return math.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
    len2 = (bx - ax) * (bx - ax) + (by - ay) * (by - ay)
    r = ((px - ax) * (bx - ax) + (py - ay) * (by - ay)) / len2
    if r <= 0.0:
        return math.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
    if r >= 1.0:
        return math.sqrt((px - bx) * (px - bx) + (py - by) * (py - by))
    s = ((ay - py) * (bx - ax) - (ax - px) * (by - ay)) / len2
    return abs(s) * math.sqrt(len2)


@numba.njit(cache=True, nogil=True)
def _distances(points: F64, line_of: I64, coords: F64, offsets: I64) -> F64:
    out = np.empty(points.shape[0])
    boxes = np.empty((coords.shape[0] // _CHUNK + offsets.shape[0], 4))
    current = -1  # the polyline whose chunks' boxes are in boxes
    seed = -1  # the previous point's nearest segment, when it was on the same polyline
    for i in range(points.shape[0]):
        px, py = points[i, 0], points[i, 1]
        lo, hi = offsets[line_of[i]], offsets[line_of[i] + 1]
        if hi - lo == 1:
            dx, dy = px - coords[lo, 0], py - coords[lo, 1]
            out[i] = math.sqrt(dx * dx + dy * dy)
            seed = -1
            continue
        if i > 0 and line_of[i] != line_of[i - 1]:
            seed = -1
        if line_of[i] != current:
            current = line_of[i]
            _chunk_boxes(coords, lo, hi, boxes)
        best = math.inf
        nearest = -1
        if seed >= 0:  # a near bound first: most segments are then skipped
            best = _point_to_segment(
                px, py, coords[seed, 0], coords[seed, 1], coords[seed + 1, 0], coords[seed + 1, 1]
            )
            nearest = seed
        for c in range((hi - lo - 2) // _CHUNK + 1):
            if not best > 0.0:  # DistanceOp's terminateDistance
                break
            if _far(px, py, boxes[c, 0], boxes[c, 1], boxes[c, 2], boxes[c, 3], best):
                continue
            first = lo + c * _CHUNK
            for j in range(first, min(first + _CHUNK, hi - 1)):
                if j == seed:
                    continue
                ax, ay, bx, by = coords[j, 0], coords[j, 1], coords[j + 1, 0], coords[j + 1, 1]
                if _far(px, py, ax, ay, bx, by, best):
                    continue
                d = _point_to_segment(px, py, ax, ay, bx, by)
                if d < best:
                    best, nearest = d, j
                    if best <= 0.0:
                        break
        out[i] = best
        seed = nearest
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _measure(  # noqa: PLR0917 (numba has no keyword-only parameters)
    px: float, py: float, ax: float, ay: float, bx: float, by: float, start: float, length: float
) -> tuple[float, float]:
    """The distance of the point to the segment and ``segmentNearestMeasure`` (with
    ``LineSegment::projectionFactor``) of the segment that starts at measure ``start``."""
    d = _point_to_segment(px, py, ax, ay, bx, by)
    if px == ax and py == ay:
        r = 0.0
    elif px == bx and py == by:
        r = 1.0
    else:
        dx, dy = bx - ax, by - ay
        r = ((px - ax) * dx + (py - ay) * dy) / (dx * dx + dy * dy)
    if r <= 0.0:
        return d, start
    if r <= 1.0:
        return d, start + r * length
    return d, start + length


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _locate(points: F64, line_of: I64, coords: F64, offsets: I64) -> tuple[F64, F64]:
    s_out = np.empty(points.shape[0])
    d_out = np.empty(points.shape[0])
    # each segment's start measure and length on the polyline of the points being located (the
    # same running sum as LengthIndexOfPoint's), computed once per run of points on one line
    starts = np.empty(coords.shape[0])
    lengths = np.empty(coords.shape[0])
    boxes = np.empty((coords.shape[0] // _CHUNK + offsets.shape[0], 4))
    current = -1
    seed = -1  # the previous point's segment (on the same polyline)
    for i in range(points.shape[0]):
        px, py = points[i, 0], points[i, 1]
        lo, hi = offsets[line_of[i]], offsets[line_of[i] + 1]
        if line_of[i] != current:
            current, seed = line_of[i], -1
            start = 0.0
            for j in range(lo, hi - 1):
                ax, ay, bx, by = coords[j, 0], coords[j, 1], coords[j + 1, 0], coords[j + 1, 1]
                length = math.sqrt((ax - bx) * (ax - bx) + (ay - by) * (ay - by))
                starts[j], lengths[j] = start, length
                start += length
            _chunk_boxes(coords, lo, hi, boxes)
        best = math.inf
        measure = -1.0  # LengthIndexOfPoint::indexOf's minIndex
        chosen = hi  # the first segment in order at the least distance (hi: none yet)
        if seed >= 0:  # a near bound first: most segments are then skipped
            ax, ay, bx, by = (
                coords[seed, 0],
                coords[seed, 1],
                coords[seed + 1, 0],
                coords[seed + 1, 1],
            )
            d, m = _measure(px, py, ax, ay, bx, by, starts[seed], lengths[seed])
            if m > -1.0:
                measure, best, chosen = m, d, seed
        for c in range((hi - lo - 2) // _CHUNK + 1):
            if _far(px, py, boxes[c, 0], boxes[c, 1], boxes[c, 2], boxes[c, 3], best):
                continue
            first = lo + c * _CHUNK
            for j in range(first, min(first + _CHUNK, hi - 1)):
                if j == chosen:
                    continue
                ax, ay, bx, by = coords[j, 0], coords[j, 1], coords[j + 1, 0], coords[j + 1, 1]
                if _far(px, py, ax, ay, bx, by, best):
                    continue
                d, m = _measure(px, py, ax, ay, bx, by, starts[j], lengths[j])
                # strictly nearer, or as near and earlier than the seed: the first in order wins
                if m > -1.0 and (d < best or (d == best and j < chosen)):
                    measure, best, chosen = m, d, j
        s_out[i] = measure
        d_out[i] = best
        seed = chosen if chosen < hi else -1
    return s_out, d_out
