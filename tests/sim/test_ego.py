"""Kinematic bicycle model (exact arc integration) and the ego driver."""

from __future__ import annotations

import math

import numpy as np
import pytest

from redrive.sim.ego import ActuatedEgo, BicycleModel, EgoGeometry, TyreLimit
from redrive.types import ControlCommands


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


def _random_ego(rng: np.random.Generator, *, jerk: bool, delay: int) -> ActuatedEgo:
    geometry = EgoGeometry(max_jerk_mps3=float(rng.uniform(1.0, 20.0)) if jerk else None)
    model = BicycleModel(
        geometry,
        x_m=float(rng.uniform(-3000.0, 3000.0)),
        y_m=float(rng.uniform(-3000.0, 3000.0)),
        yaw_rad=float(rng.uniform(-math.pi, math.pi)),
        speed_mps=float(rng.choice([0.0, rng.uniform(0.0, 35.0)])),
        steer_rad=float(rng.uniform(-0.6, 0.6)),
    )
    tyres = TyreLimit(friction_coefficient=float(rng.choice([0.9, 0.1])))  # 0.1: the circle binds
    return ActuatedEgo(model, delay_steps=delay, tyres=tyres)


def _state(ego: ActuatedEgo) -> tuple[float, ...]:
    m = ego.model
    return (m.x_m, m.y_m, m.yaw_rad, m.speed_mps, m.steer_rad, m.accel_mps2)


@pytest.mark.parametrize("delay", [0, 1])
def test_apply_steps_is_apply_repeated_bit_for_bit(delay: int) -> None:
    """The compiled substeps (the world's commanded-ego kernel) give the doubles of the Python
    steps: throttle, brake, coasting to rest, steering at its rate and range limits, the jerk
    bound and the friction circle binding."""
    rng = np.random.default_rng(7 + delay)
    for case in range(300):
        jerk = case % 3 == 0
        seed = int(rng.integers(1 << 32))
        a = _random_ego(np.random.default_rng(seed), jerk=jerk, delay=delay)
        b = _random_ego(np.random.default_rng(seed), jerk=jerk, delay=delay)
        for _ in range(4):
            throttle, brake = (
                (float(rng.uniform(0, 1)), 0.0)
                if rng.random() < 0.5
                else (0.0, float(rng.uniform(0, 1)))
            )
            cmd = ControlCommands(
                throttle=throttle, brake=brake, steering_angle_rad=float(rng.uniform(-0.9, 0.9))
            )
            steps = int(rng.integers(1, 12))
            dt = float(rng.choice([0.1, 0.05, 0.5])) / steps
            for _ in range(steps):
                a.apply(cmd, dt)
            b.apply_steps(cmd, dt, steps)
            assert _state(a) == _state(b), (case, cmd, steps, dt)


def test_apply_steps_refuses_a_bad_step() -> None:
    ego = ActuatedEgo(BicycleModel(EgoGeometry()))
    with pytest.raises(ValueError, match="dt_s must be a positive number"):
        ego.apply_steps(ControlCommands(), float("nan"), 3)
