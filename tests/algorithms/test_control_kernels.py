"""The controller's compiled path lookups give, bit for bit, what the numpy code they replaced
gave (kept here as the reference): the pure-pursuit target and the path's speeds around given
times, on random paths with repeated points, zero-length paths, standstill and repeated times."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from redrive.algorithms.reference._control_kernels import lookahead_point, path_speeds

F64 = npt.NDArray[np.float64]


def _lookahead_numpy(xy: F64, lookahead_m: float) -> F64 | None:
    seg = np.diff(xy, axis=0)
    seg_len = np.hypot(seg[:, 0], seg[:, 1]) if len(seg) else np.zeros(0)
    ok = seg_len > 1e-9
    if not np.any(ok):
        return None
    a, ab, seg_len = xy[:-1][ok], seg[ok], seg_len[ok]
    s_start = np.concatenate([[0.0], np.cumsum(seg_len)[:-1]])
    t = np.clip(-(a * ab).sum(axis=1) / seg_len**2, 0.0, 1.0)
    foot = a + t[:, None] * ab
    j = int(np.argmin(np.hypot(foot[:, 0], foot[:, 1])))
    s_target = s_start[j] + t[j] * seg_len[j] + lookahead_m
    k = int(np.searchsorted(s_start, s_target, side="right") - 1)
    k = min(max(k, 0), len(seg_len) - 1)
    out: F64 = a[k] + (s_target - s_start[k]) / seg_len[k] * ab[k]
    return out


def _speeds_numpy(wp: F64, times_s: tuple[float, ...]) -> list[float]:
    if len(wp) < 2 or wp[-1, 3] - wp[0, 3] <= 0.0:
        return [0.0] * len(times_s)
    times = wp[:, 3]
    seg = np.linalg.norm(np.diff(wp[:, :3], axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    steps = np.diff(times)
    half = 0.5 * float(np.median(steps[steps > 0]))
    first, last = times[0], times[-1]
    ends = []
    for t_s in times_s:
        t0 = min(max(t_s - half, first), last - 2.0 * half)
        t0 = max(t0, first)
        ends += [t0, min(t0 + 2.0 * half, last)]
    s_at = np.interp(ends, times, s)
    out = []
    for i in range(0, len(ends), 2):
        t0, t1 = ends[i], ends[i + 1]
        out.append(float((s_at[i + 1] - s_at[i]) / (t1 - t0)) if t1 > t0 else 0.0)
    return out


def _bits(values: object) -> bytes:
    return np.asarray(values, dtype=np.float64).tobytes()


def _random_path(rng: np.random.Generator) -> F64:
    k = int(rng.integers(1, 70))
    kind = rng.integers(4)
    steps = rng.normal(0.0, 1.0, (k, 3)) * rng.choice([1e-10, 0.1, 1.0, 5.0])
    if kind == 0:  # standstill: every point the same
        steps[:] = 0.0
    elif kind == 1:  # repeated points inside
        steps[rng.random(k) < 0.3] = 0.0
    xyz = np.cumsum(steps, axis=0) + rng.normal(0.0, 3.0, 3)
    dt = rng.choice([0.1, 0.05, 0.2])
    t = np.arange(k) * dt
    if kind == 2:  # repeated and uneven times
        t = np.cumsum(rng.choice([0.0, 0.1, 0.25], k)) - 0.1
    return np.ascontiguousarray(np.column_stack([xyz, t]))


def test_lookahead_point_and_path_speeds_equal_the_numpy_code_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    for _ in range(250):
        wp = _random_path(rng)
        lookahead = float(rng.uniform(0.0, 15.0))
        want = _lookahead_numpy(wp[:, :2], lookahead)
        found, x, y = lookahead_point(wp, lookahead)
        assert found == (want is not None)
        if want is not None:
            assert _bits([x, y]) == _bits(want)
        times = tuple(float(v) for v in rng.uniform(-1.0, 8.0, 3))
        got = path_speeds(wp, np.array(times))
        assert _bits(got) == _bits(_speeds_numpy(wp, times))


def test_lookahead_point_keeps_numpys_choice_on_ties_and_beyond_the_end() -> None:
    # the origin equally far from two segments: the first one wins, as np.argmin
    xy = np.array([[1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    found, x, y = lookahead_point(xy, 0.5)
    want = _lookahead_numpy(xy, 0.5)
    assert found
    assert want is not None
    assert _bits([x, y]) == _bits(want)
    # a lookahead past the end extends the last segment straight
    found, x, y = lookahead_point(np.array([[0.0, 0.0], [2.0, 0.0]]), 5.0)
    assert found
    assert (x, y) == (5.0, 0.0)
    assert lookahead_point(np.array([[3.0, 4.0]]), 1.0)[0] is False
    assert not math.isnan(path_speeds(np.zeros((1, 4)), np.zeros(2))[0])
