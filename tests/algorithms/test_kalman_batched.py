"""The tracker's stacked Kalman steps give each track bit-for-bit what the one-track steps give."""

from __future__ import annotations

import numpy as np

from redrive.algorithms.reference._kalman import (
    KalmanState,
    mahalanobis_sq,
    mahalanobis_sq_all,
    predict,
    predict_all,
    update,
    update_all,
)
from redrive.algorithms.reference.tracker import _Pose2D, to_base_link


def _states(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    a = rng.normal(size=(n, 4, 4))
    return rng.normal(size=(n, 4)) * 20.0, a @ a.transpose(0, 2, 1) + np.eye(4) * 0.1


def test_stacked_steps_equal_one_track_steps() -> None:
    rng = np.random.default_rng(15)
    for n, m, dt in ((1, 1, 0.1), (7, 12, 0.1), (13, 3, 0.05), (4, 5, 0.0)):
        x, p = _states(rng, n)
        z = rng.normal(size=(m, 2)) * 20.0
        xs, ps = predict_all(x, p, dt, accel_std_mps2=2.0)
        d2 = mahalanobis_sq_all(xs, ps, z, meas_std_m=0.3)
        zs = rng.normal(size=(n, 2)) * 20.0
        xu, pu = update_all(xs, ps, zs, meas_std_m=0.3)
        for i in range(n):
            one = KalmanState(x=x[i].copy(), p=p[i].copy())
            predict(one, dt, accel_std_mps2=2.0)
            assert np.array_equal(one.x, xs[i])
            assert np.array_equal(one.p, ps[i])
            assert np.array_equal(mahalanobis_sq(one, z, meas_std_m=0.3), d2[i])
            update(one, zs[i], meas_std_m=0.3)
            assert np.array_equal(one.x, xu[i])
            assert np.array_equal(one.p, pu[i])


def test_to_base_link_equals_one_track_transform() -> None:
    rng = np.random.default_rng(16)
    x = rng.normal(size=(9, 4)) * 30.0
    pose = _Pose2D(heading_rad=0.7, xyz_m=np.array([120.5, -33.25, 1.5]))
    xy, v = to_base_link(x, pose)
    rot_t = pose.rotation.T
    for i in range(len(x)):
        assert np.array_equal(rot_t @ (x[i, :2].copy() - pose.xyz_m[:2]), xy[i])
        assert np.array_equal(rot_t @ x[i, 2:].copy(), v[i])
    same_xy, same_v = to_base_link(x, None)
    assert np.array_equal(same_xy, x[:, :2])
    assert np.array_equal(same_v, x[:, 2:])
