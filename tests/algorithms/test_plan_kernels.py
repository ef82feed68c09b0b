"""The planner's compiled path geometry gives, bit for bit, what the numpy code it replaced
gave (kept here as the reference): a Polyline's vertices and arc lengths, its points at arc
lengths (inside, past either end), the leaders picked from boxes' corners and centres, a
stop line's first crossing with the path, and the curve speed limit; and the written-out
``np.unwrap`` and ``sum`` of ``_numeric_kernels``."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.algorithms.reference._kernels import project_on_segments
from redrive.algorithms.reference._numeric_kernels import pairwise_sum, unwrap
from redrive.algorithms.reference._plan_kernels import (
    box_frames,
    curve_speed,
    gate_crossing,
    leaders_on_path,
    path_bounds,
    points_at,
    polyline_arc,
    project_pruned,
)
from redrive.geometry.boxes import BOX_CORNER_SIGNS

F64 = npt.NDArray[np.float64]


def _arc_numpy(xy: F64) -> tuple[F64, F64]:
    pts = xy
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-9
    pts = pts[keep]
    seg = np.hypot(*np.diff(pts, axis=0).T) if len(pts) > 1 else np.zeros(0)
    return pts, np.concatenate([[0.0], np.cumsum(seg)])


def _points_at_numpy(xy: F64, s_line: F64, s: F64) -> F64:
    if len(xy) == 1:
        return np.repeat(xy, len(s), axis=0)
    out = np.column_stack([np.interp(s, s_line, xy[:, 0]), np.interp(s, s_line, xy[:, 1])])
    for mask, i0, s_ref in ((s > s_line[-1], len(xy) - 2, s_line[-1]), (s < 0.0, 0, 0.0)):
        if np.any(mask):
            d = xy[i0 + 1] - xy[i0]
            d = d / np.hypot(*d)
            base = xy[-1] if s_ref > 0.0 else xy[0]
            out[mask] = base + np.outer(s[mask] - s_ref, d)
    return out


def _leaders_numpy(  # noqa: PLR0917 - the kernel's parameters, in its order
    corners: F64,
    centers: F64,
    vel: F64,
    xy: F64,
    s_line: F64,
    half: float,
    front: float,
    far: float,
) -> tuple[F64, F64]:
    n = len(centers)
    points = np.concatenate([corners[:, :4, :2].reshape(-1, 2), centers[:, :2]])
    a = xy[:-1]
    ab = xy[1:] - a
    s_all, lat_all, _ = project_on_segments(
        np.ascontiguousarray(points), a, ab, np.hypot(ab[:, 0], ab[:, 1]), s_line[:-1]
    )
    s = s_all[: 4 * n].reshape(-1, 4)
    lat = lat_all[: 4 * n].reshape(-1, 4)
    s_lo, s_hi = s.min(axis=1), s.max(axis=1)
    keep = np.flatnonzero(
        (lat.min(axis=1) < half) & (lat.max(axis=1) > -half) & (s_hi > front) & (s_lo < far)
    )
    i = np.clip(np.searchsorted(s_line, s_all[4 * n :][keep], side="right") - 1, 0, len(xy) - 2)
    d = xy[i + 1] - xy[i]
    tangents = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    speed = np.maximum((vel[keep, :2] * tangents).sum(axis=1), 0.0)
    return s_lo[keep], speed


def _bits(values: object) -> bytes:
    return np.asarray(values, dtype=np.float64).tobytes()


def _random_line(rng: np.random.Generator) -> F64:
    m = int(rng.integers(2, 260))  # the planner's lane arc has 241 vertices
    if rng.random() < 0.5:  # a lane arc as the planner samples it
        kappa = float(rng.choice([0.0, rng.uniform(-0.2, 0.2)]))
        s = np.linspace(0.0, float(rng.uniform(1.0, 120.0)), m)
        if kappa == 0.0:
            return np.column_stack([s, np.zeros_like(s)])
        return np.column_stack([np.sin(kappa * s) / kappa, (1.0 - np.cos(kappa * s)) / kappa])
    steps = rng.normal(0.0, 2.0, (m, 2))
    steps[rng.random(m) < 0.2] = 0.0  # repeated vertices
    return np.cumsum(steps, axis=0)


def test_polyline_arc_and_points_at_equal_the_numpy_code_bit_for_bit() -> None:
    rng = np.random.default_rng(11)
    for _ in range(150):
        raw = _random_line(rng)
        xy, s_line = polyline_arc(raw)
        want_xy, want_s = _arc_numpy(raw)
        assert _bits(xy) == _bits(want_xy)
        assert _bits(s_line) == _bits(want_s)
        if len(xy) < 2:
            continue
        s = np.concatenate(
            [rng.uniform(-5.0, s_line[-1] + 5.0, 40), s_line[rng.integers(0, len(s_line), 5)]]
        )
        assert _bits(points_at(xy, s_line, s)) == _bits(_points_at_numpy(xy, s_line, s))
        # non-decreasing, as a plan's arc lengths are (each search starts at the last one's
        # knot): repeats, knots hit exactly, points beyond either end between them
        s = np.sort(np.concatenate([s, s[:10], s_line]))
        assert _bits(points_at(xy, s_line, s)) == _bits(_points_at_numpy(xy, s_line, s))


def test_leaders_on_path_equal_the_numpy_code_bit_for_bit() -> None:
    """box_frames gives the planner's former numpy operands of the corners (math.cos and
    math.sin, the signs times half the size) and leaders_on_path on their product, the centres
    added inside, gives the numpy code's leaders of the corners numpy summed."""
    rng = np.random.default_rng(12)
    for _ in range(150):
        xy, s_line = polyline_arc(_random_line(rng))
        if len(xy) < 2:
            continue
        n = int(rng.integers(1, 25))
        yaws = rng.uniform(-math.pi, math.pi, n)
        cos = [math.cos(yaw) for yaw in yaws.tolist()]
        sin = [math.sin(yaw) for yaw in yaws.tolist()]
        rotations = np.zeros((n, 3, 3))
        rotations[:, 0, 0] = rotations[:, 1, 1] = cos
        rotations[:, 0, 1] = sin
        rotations[:, 1, 0] = [-v for v in sin]
        rotations[:, 2, 2] = 1.0
        centers = np.column_stack([rng.uniform(-10.0, 80.0, (n, 2)), np.full(n, 0.8)])
        # some boxes right on the path, as leaders are
        on = rng.random(n) < 0.5
        centers[on, :2] = xy[rng.integers(0, len(xy), int(on.sum()))]
        sizes = rng.uniform(0.5, 5.0, (n, 3))
        local = BOX_CORNER_SIGNS * (0.5 * sizes)[:, None, :]
        got_local, got_rotations = box_frames(yaws, sizes, BOX_CORNER_SIGNS)
        assert _bits(got_local) == _bits(local)
        assert _bits(got_rotations) == _bits(rotations)
        product = local @ rotations
        corners = product + centers[:, None, :]
        vel = rng.normal(0.0, 5.0, (n, 3))
        vel[rng.random(n) < 0.2] = 0.0
        rest = (vel, xy, s_line, 1.5, 3.75, min(s_line[-1], 120.0) - 1e-6)
        got_s, got_v = leaders_on_path(product, centers, *rest)
        want_s, want_v = _leaders_numpy(corners, centers, *rest)
        assert _bits(got_s) == _bits(want_s)
        assert _bits(got_v) == _bits(want_v)


def test_project_pruned_equals_the_full_search_bit_for_bit() -> None:
    rng = np.random.default_rng(13)
    for trial in range(150):
        xy, s_line = polyline_arc(_random_line(rng))
        if len(xy) < 2:
            continue
        a = xy[:-1]
        ab = xy[1:] - a
        seg_len = np.hypot(ab[:, 0], ab[:, 1])
        near = xy[rng.integers(0, len(xy), 30)] + rng.normal(0.0, 0.5, (30, 2))
        # clusters of five within a few metres (a box's corners and centre: each point after
        # the first bounded by its neighbour's nearest segment)
        boxes = np.repeat(near[:6], 5, axis=0) + rng.normal(0.0, 2.0, (30, 2))
        p = np.concatenate([near, rng.uniform(-50.0, 150.0, (30, 2)), xy[:3], boxes])
        if trial % 25 == 0:
            p[0] = np.nan  # the full search decides what a NaN gives
        s_full, lat_full, _ = project_on_segments(p, a, ab, seg_len, s_line[:-1])
        s_got, lat_got = project_pruned(p, a, ab, seg_len, s_line[:-1], s_line[-1])
        assert _bits(s_got) == _bits(s_full)
        assert _bits(lat_got) == _bits(lat_full)


def _gate_crossing_numpy(
    path_xy: F64, path_s: F64, line: F64, low: F64, high: F64
) -> tuple[float, F64] | None:
    """What _lights.stop_arcs did before gate_crossing: the bounding boxes' test, then the
    first crossing (its arc length and the path's unit direction there) or None."""
    if (line.max(axis=0) < low).any() or (line.min(axis=0) > high).any():
        return None
    a, ab = path_xy[:-1], np.diff(path_xy, axis=0)
    best: tuple[float, F64] | None = None
    for p, q in itertools.pairwise(line):
        pq = q - p
        denom = ab[:, 0] * pq[1] - ab[:, 1] * pq[0]
        ok = np.abs(denom) > 1e-12
        if not ok.any():
            continue
        ap = p - a
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (ap[:, 0] * pq[1] - ap[:, 1] * pq[0]) / denom
            u = (ap[:, 0] * ab[:, 1] - ap[:, 1] * ab[:, 0]) / denom
        hit = ok & (t >= 0.0) & (t <= 1.0) & (u >= 0.0) & (u <= 1.0)
        if not hit.any():
            continue
        j = int(np.flatnonzero(hit)[0])
        s = float(path_s[j] + t[j] * (path_s[j + 1] - path_s[j]))
        if best is None or s < best[0]:
            seg = ab[j] / max(float(np.hypot(ab[j, 0], ab[j, 1])), 1e-12)
            best = (s, seg)
    return best


def test_gate_crossing_equals_the_numpy_code_bit_for_bit() -> None:
    rng = np.random.default_rng(14)
    crossed = 0
    for trial in range(300):
        xy, s_line = polyline_arc(_random_line(rng))
        if len(xy) < 2:
            continue
        # a stop line of 2–4 points, often across the path (through one of its vertices or
        # between two), else anywhere
        k = int(rng.integers(2, 5))
        mid = xy[rng.integers(0, len(xy))] if rng.random() < 0.7 else rng.uniform(-20, 100, 2)
        line = mid + np.cumsum(rng.normal(0.0, 2.0, (k, 2)), axis=0) - rng.normal(0.0, 2.0, 2)
        if trial % 40 == 0:
            line[0] = np.nan  # a NaN in the line: numpy's max and min let it through
        if trial % 40 == 20:
            line = np.array([xy[0], xy[-1]])  # along the path: parallel segments
        low, high = xy.min(axis=0), xy.max(axis=0)
        found, s, tx, ty = gate_crossing(xy, s_line, line, *low.tolist(), *high.tolist())
        want = _gate_crossing_numpy(xy, s_line, line, low, high)
        assert found == (want is not None)
        if want is not None:
            crossed += 1
            assert _bits(np.array([s, tx, ty])) == _bits(np.array([want[0], *want[1]]))
    assert crossed > 50  # the crossings themselves were compared, not only the misses


def test_path_bounds_are_numpys_min_and_max_along_the_vertices() -> None:
    rng = np.random.default_rng(11)
    for m in (1, 2, 241):
        xy = rng.normal(size=(m, 2)) * 50.0
        x_lo, y_lo, x_hi, y_hi = path_bounds(xy)
        assert [x_lo, y_lo] == xy.min(axis=0).tolist()
        assert [x_hi, y_hi] == xy.max(axis=0).tolist()
    xy = rng.normal(size=(5, 2))
    xy[2, 1] = np.nan  # a NaN wins in its column, as in numpy
    x_lo, y_lo, x_hi, y_hi = path_bounds(xy)
    np.testing.assert_array_equal([x_lo, y_lo], xy.min(axis=0))
    np.testing.assert_array_equal([x_hi, y_hi], xy.max(axis=0))
    assert np.isnan(y_lo)
    assert np.isnan(y_hi)
    assert not np.isnan(x_lo)


def _libm_arctan2(y: F64, x: F64) -> F64:
    """``np.arctan2`` as libm computes it (``math.atan2`` of each pair): numpy's own loop is
    libm's on most hosts, but on an AVX-512 one numpy dispatches float64 arctan2 to its SIMD
    (SVML) loop, which differs from libm in the last bit for a few pairs."""
    return np.array([math.atan2(a, c) for a, c in zip(y.tolist(), x.tolist(), strict=True)])


def _curve_speed_numpy(  # noqa: PLR0917 - the kernel's parameters
    xy: F64,
    s_line: F64,
    length: float,
    sample: float,
    k: int,
    a_lat: float,
    b: float,
    front: float,
    *,
    arctan2: Any = np.arctan2,
) -> float:
    """IdmPlanner._curve_speed_mps's numpy code after its length test (the reference)."""
    s = np.arange(0.0, length, sample)
    pts = _points_at_numpy(xy, s_line, s)
    d = np.diff(pts, axis=0)
    heading = np.unwrap(arctan2(d[:, 1], d[:, 0]))
    if heading.size <= k:
        return math.inf
    kappa = np.abs(heading[k:] - heading[:-k]) / (k * sample)
    at = s[k:-1] if s.size - 1 > k else s[k:]
    at = at[: kappa.size]
    curve = np.sqrt(a_lat / np.maximum(kappa, 1e-9))
    ahead = np.maximum(at - front, 0.0)
    return float(np.min(np.sqrt(curve**2 + 2.0 * b * ahead)))


def test_curve_speed_equals_the_numpy_code_bit_for_bit() -> None:
    """The kernel's doubles are the numpy code's with libm's atan2 (the kernel's
    ``math.atan2``) on every host; numpy's own ``arctan2`` is that on most hosts and within an
    ulp of it where numpy uses its AVX-512 loop (there the limits agree to 1e-12)."""
    rng = np.random.default_rng(5)
    compared = 0
    for _ in range(300):
        n = int(rng.integers(2, 60))
        heading = np.cumsum(rng.normal(0.0, 0.5, size=n))  # winding, past ±π
        step = rng.uniform(0.1, 6.0, size=n)
        raw = np.cumsum(np.c_[step * np.cos(heading), step * np.sin(heading)], axis=0)
        xy, s_line = polyline_arc(np.ascontiguousarray(raw))
        length = float(min(s_line[-1], rng.uniform(5.0, 120.0)))
        sample, k = float(rng.choice([0.5, 1.0, 1.3])), int(rng.integers(1, 6))
        a_lat, b, front = rng.uniform(0.5, 3.0), rng.uniform(1.0, 4.0), rng.uniform(0.0, 4.0)
        want = _curve_speed_numpy(
            xy, s_line, length, sample, k, a_lat, b, front, arctan2=_libm_arctan2
        )
        got = curve_speed(xy, s_line, length, sample, k, a_lat, b, front)
        assert got == want or (math.isnan(got) and math.isnan(want))
        with_numpy = _curve_speed_numpy(xy, s_line, length, sample, k, a_lat, b, front)
        assert math.isclose(got, with_numpy, rel_tol=1e-12) or got == with_numpy
        compared += math.isfinite(want)
    assert compared > 200  # most paths are long enough for a limit


def test_unwrap_and_pairwise_sum_equal_numpy_bit_for_bit() -> None:
    rng = np.random.default_rng(9)
    for n in [*range(20), 31, 64, 100, 127, 128]:
        p = np.cumsum(rng.normal(0.0, 2.5, size=n))
        p[: n // 3] = np.pi * rng.integers(-3, 4, size=n // 3)  # steps of exactly ±π and 0
        out = np.empty(n)
        unwrap(p, n, out)
        assert out.tobytes() == np.unwrap(p).tobytes()
        values = rng.normal(0.0, 1.0, size=n) * 10.0 ** rng.integers(-8, 8, size=n)
        assert pairwise_sum(values, n) == values.sum()
