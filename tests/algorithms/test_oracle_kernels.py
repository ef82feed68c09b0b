"""The noisy oracle's compiled perturbation against the numpy code it replaced, bit for bit."""

from __future__ import annotations

import math

import numpy as np

from redrive.algorithms.reference._oracle_kernels import perturb_rows
from redrive.geometry.se3 import normalize_angle


def _frozen(a: np.ndarray) -> np.ndarray:  # type: ignore[type-arg]
    a = np.ascontiguousarray(a, dtype=np.float64)
    a.flags.writeable = False
    return a


def test_perturb_rows_is_the_numpy_code_bit_for_bit() -> None:
    rng = np.random.default_rng(11)
    for trial in range(40):
        m = int(rng.integers(1, 30))
        centers = rng.normal(0, 50, (m, 3))
        centers[rng.random((m, 3)) < 0.05] = np.nan
        centers[rng.random((m, 3)) < 0.03] = np.inf
        sizes = rng.uniform(0, 6, (m, 3))
        sizes[rng.random((m, 3)) < 0.1] = 0.0
        yaws = rng.choice([math.pi, -math.pi, 1e3, -7.5, 0.0, 3.14159], m) + rng.normal(0, 1e-9, m)
        velocities = rng.normal(0, 5, (m, 3))
        orientations = rng.normal(0, 3, (m, 3))
        orientations[:, 0] = yaws
        rows = rng.choice(m, int(rng.integers(0, m + 1)), replace=bool(trial % 2))
        n = len(rows)
        missed = rng.random(n) < 0.3
        n_center, n_size = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) * 30
        n_yaw, n_vel = rng.normal(size=n), rng.normal(size=(n, 2))
        stds = np.array([0.2, 0.05, 0.05 if trial % 3 else 4.0, 0.3])
        d_size = n_size * stds[1]
        noisy_sizes = np.maximum(sizes[rows] * (1.0 + d_size), 0.1 * sizes[rows])
        got = perturb_rows(
            _frozen(centers),
            _frozen(yaws),
            _frozen(velocities),
            _frozen(orientations),
            rows.astype(np.int64),
            missed,
            n_center,
            noisy_sizes,
            n_yaw,
            n_vel,
            stds,
        )
        # the numpy code of NoisyOracle._perturb before the kernel
        d_center = n_center * stds[0]
        d_yaw, d_vel = n_yaw * stds[2], n_vel * stds[3]
        c = centers[rows] + d_center
        s = np.maximum(sizes[rows] * (1.0 + d_size), 0.1 * sizes[rows])
        v = velocities[rows]
        v[:, :2] += d_vel
        o = orientations[rows]
        kept = np.flatnonzero(~missed).tolist()
        y = [normalize_angle(yaws[rows[i]].item() + d_yaw.tolist()[i]) for i in kept]
        for i in kept:
            o[i, 0] = normalize_angle(float(o[i, 0]) + d_yaw.tolist()[i])
        assert got[0].tolist() == kept
        for have, want in zip(
            got[1:], (c[kept], s[kept], np.array(y), v[kept], o[kept]), strict=True
        ):
            assert have.tobytes() == np.asarray(want, dtype=np.float64).tobytes(), trial
