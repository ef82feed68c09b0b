"""The noisy oracle's compiled frame: its counter-based draws (distributions, determinism,
independence of rows) and its arithmetic."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from redrive.algorithms.reference._oracle_kernels import (
    frame_key,
    normal_at,
    oracle_frame,
    uniform_at,
)


def _frozen(a: np.ndarray) -> np.ndarray:  # type: ignore[type-arg]
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


def _params(**kw: float) -> np.ndarray:  # type: ignore[type-arg]
    base = {
        "center": 0.2,
        "size": 0.05,
        "yaw": 0.05,
        "vel": 0.3,
        "miss": 0.0,
        "confuse": 0.0,
        "fp_rate": 0.0,
        "near": 3.0,
        "far": 60.0,
        "range": math.inf,
    }
    base.update(kw)
    return np.array(list(base.values()))


FP_PROBS = np.array([0.6, 0.25, 0.15])
FP_SIZES = np.array([[4.5, 1.9, 1.5], [0.6, 0.6, 1.75], [1.8, 0.6, 1.6]])


def _scene(n: int) -> tuple[np.ndarray, ...]:  # type: ignore[type-arg]
    rng = np.random.default_rng(3)
    centers = rng.uniform(-40, 40, (n, 3))
    sizes = rng.uniform(0.5, 5, (n, 3))
    yaws = rng.uniform(-math.pi, math.pi, n)
    velocities = rng.normal(0, 5, (n, 3))
    orientations = np.zeros((n, 3))
    orientations[:, 0] = yaws
    return tuple(_frozen(a) for a in (centers, sizes, yaws, velocities, orientations))


@numba.njit
def _uniforms(key: np.uint64, n: int) -> np.ndarray:  # type: ignore[type-arg]  # pragma: no cover
    return np.array([uniform_at(key, c) for c in range(n)])


@numba.njit
def _normals(key: np.uint64, n: int) -> np.ndarray:  # type: ignore[type-arg]  # pragma: no cover
    return np.array([normal_at(key, 2 * c) for c in range(n)])


def test_uniforms_and_normals_have_their_distributions() -> None:
    """The draws made in compiled loops (a kernel called from Python took ≈ 60 µs a call with
    its key, a Python int above 2^63: 300,000 calls were 13 s); the first thousand equal the
    calls from Python."""
    key = frame_key(7, 123)
    u = _uniforms(key, 200_000)
    assert u[:1000].tolist() == [uniform_at(key, c) for c in range(1000)]
    assert u.min() >= 0.0
    assert u.max() < 1.0
    assert u.mean() == pytest.approx(0.5, abs=0.003)
    assert u.var() == pytest.approx(1 / 12, rel=0.01)
    # consecutive draws uncorrelated
    assert abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 0.01
    z = _normals(key, 100_000)
    assert z[:1000].tolist() == [normal_at(key, 2 * c) for c in range(1000)]
    assert z.mean() == pytest.approx(0.0, abs=0.015)
    assert z.std() == pytest.approx(1.0, rel=0.01)
    assert np.mean(np.abs(z) < 1.0) == pytest.approx(0.6827, abs=0.005)


def test_keys_differ_by_seed_and_frame_and_draws_are_pure_functions() -> None:
    keys = {frame_key(s, i) for s in range(20) for i in range(200)}
    assert len(keys) == 20 * 200
    assert uniform_at(frame_key(1, 2), 5) == uniform_at(frame_key(1, 2), 5)
    assert uniform_at(frame_key(1, 2), 5) != uniform_at(frame_key(2, 1), 5)


def test_a_rows_noise_does_not_depend_on_the_other_rows() -> None:
    cols = _scene(12)
    everyone = _frozen(np.ones(12, dtype=np.bool_))
    some = np.ones(12, dtype=np.bool_)
    some[[0, 5, 6]] = False
    a = oracle_frame(4, 9, *cols, everyone, _params(), FP_PROBS, FP_SIZES)
    b = oracle_frame(4, 9, *cols, _frozen(some), _params(), FP_PROBS, FP_SIZES)
    assert a[0].tolist() == list(range(12))
    assert b[0].tolist() == np.flatnonzero(some).tolist()
    for have, full in zip(b[1:7], a[1:7], strict=True):
        assert have.tobytes() == full[some].tobytes()
    again = oracle_frame(4, 9, *cols, everyone, _params(), FP_PROBS, FP_SIZES)
    assert all(x.tobytes() == y.tobytes() for x, y in zip(a, again, strict=True))


def test_arithmetic_range_and_misses() -> None:
    cols = _scene(2000)
    centers, sizes, _, velocities, orientations = cols
    everyone = _frozen(np.ones(2000, dtype=np.bool_))
    rows, _, c, s, y, v, o, *_ = oracle_frame(
        1, 0, *cols, everyone, _params(range=30.0), FP_PROBS, FP_SIZES
    )
    near = np.hypot(centers[:, 0], centers[:, 1]) <= 30.0
    assert rows.tolist() == np.flatnonzero(near).tolist()
    assert np.all(s >= 0.1 * sizes[rows])
    assert np.all((y >= -math.pi) & (y < math.pi))
    assert o[:, 0].tobytes() == y.tobytes()
    assert np.array_equal(v[:, 2], velocities[rows, 2])
    assert np.array_equal(o[:, 1:], orientations[rows, 1:])
    assert (c - centers[rows]).std() == pytest.approx(0.2, rel=0.08)
    kept = oracle_frame(1, 0, *cols, everyone, _params(miss=0.3), FP_PROBS, FP_SIZES)[0]
    assert 1 - len(kept) / 2000 == pytest.approx(0.3, abs=0.04)


def test_false_positive_count_is_poisson() -> None:
    cols = _scene(1)
    nobody = _frozen(np.zeros(1, dtype=np.bool_))
    counts = np.array(
        [
            len(oracle_frame(0, i, *cols, nobody, _params(fp_rate=2.0), FP_PROBS, FP_SIZES)[7])
            for i in range(4000)
        ]
    )
    assert counts.mean() == pytest.approx(2.0, abs=0.08)
    assert counts.var() == pytest.approx(2.0, rel=0.1)
    assert np.mean(counts == 0) == pytest.approx(math.exp(-2.0), abs=0.015)
