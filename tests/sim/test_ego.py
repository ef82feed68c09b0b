"""Kinematic bicycle model (exact arc integration) and the ego driver."""

from __future__ import annotations

import math

import numpy as np
import pytest

from redrive.sim.ego import BicycleModel, EgoGeometry


def test_constant_speed_zero_steer_travels_exactly_speed_times_time() -> None:
    model = BicycleModel(EgoGeometry(), x_m=5.0, y_m=-2.0, yaw_rad=0.0, speed_mps=13.7)
    for _ in range(1000):  # 10 s
        model.step(0.01, accel_mps2=0.0, steer_rad=0.0)
    assert model.x_m - 5.0 == pytest.approx(137.0, rel=1e-12, abs=1e-9)
    assert model.y_m == -2.0
    assert model.speed_mps == 13.7
    # along any heading too
    model = BicycleModel(EgoGeometry(), yaw_rad=0.7, speed_mps=9.0)
    for _ in range(500):
        model.step(0.01, accel_mps2=0.0, steer_rad=0.0)
    assert math.hypot(model.x_m, model.y_m) == pytest.approx(45.0, rel=1e-12)


def test_constant_acceleration_distance_is_exact() -> None:
    model = BicycleModel(EgoGeometry(), speed_mps=2.0)
    for _ in range(300):
        model.step(0.01, accel_mps2=1.5, steer_rad=0.0)
    assert model.x_m == pytest.approx(2.0 * 3.0 + 0.5 * 1.5 * 9.0, rel=1e-12)
    assert model.speed_mps == pytest.approx(6.5, rel=1e-12)


@pytest.mark.parametrize("steer_rad", [0.05, -0.2, 0.45])
def test_turning_circle_radius_is_wheelbase_over_tan_steer(steer_rad: float) -> None:
    geo = EgoGeometry(wheelbase_m=2.7)
    model = BicycleModel(geo, speed_mps=5.0, steer_rad=steer_rad)
    radius = geo.wheelbase_m / math.tan(steer_rad)
    centre = np.array([0.0, radius])  # left of the start pose for positive steer
    dists = []
    for _ in range(2000):
        model.step(0.01, accel_mps2=0.0, steer_rad=steer_rad)
        dists.append(math.hypot(model.x_m - centre[0], model.y_m - centre[1]))
    np.testing.assert_allclose(dists, abs(radius), rtol=1e-9)
    state = model.state(0)
    assert state.yaw_rate_rad_s == pytest.approx(5.0 / radius)
    # centripetal acceleration v²/R points at the centre
    to_centre = centre - state.position[:2]
    acc = state.acceleration[:2]
    assert np.linalg.norm(acc) == pytest.approx(25.0 / abs(radius))
    assert float(np.dot(acc, to_centre)) > 0


def test_steering_is_limited_in_range_and_rate() -> None:
    geo = EgoGeometry(max_steer_rad=0.5, max_steer_rate_rad_s=0.8)
    model = BicycleModel(geo, speed_mps=3.0)
    model.step(0.1, accel_mps2=0.0, steer_rad=1.0)
    assert model.steer_rad == pytest.approx(0.08)
    for _ in range(20):
        model.step(0.1, accel_mps2=0.0, steer_rad=1.0)
    assert model.steer_rad == pytest.approx(0.5)


def test_never_reverses() -> None:
    model = BicycleModel(EgoGeometry(), speed_mps=1.0)
    model.step(1.0, accel_mps2=-4.0, steer_rad=0.0)
    assert model.speed_mps == 0.0
    assert model.x_m == pytest.approx(1.0 / 8.0)
    assert model.state(0).acceleration[0] == 0.0
