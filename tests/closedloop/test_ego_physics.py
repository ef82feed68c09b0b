"""The ego's physics under ControlCommands (redrive.sim.ego): turning radius, coasting, braking,
actuator limits and the one-step actuation delay."""

from __future__ import annotations

import json
import math

import numpy as np
import numpy.typing as npt
import pytest
from scipy.integrate import solve_ivp

from redrive.sim.ego import ActuatedEgo, BicycleModel, EgoGeometry, PedalModel, TyreLimit
from redrive.types import ControlCommands


def _fit_circle(xy: npt.NDArray[np.float64]) -> tuple[float, float, float]:
    """Least-squares circle through points (Kåsa): x² + y² = 2·cx·x + 2·cy·y + c."""
    a = np.c_[2.0 * xy[:, 0], 2.0 * xy[:, 1], np.ones(len(xy))]
    rhs = (xy**2).sum(axis=1)
    (cx, cy, c), *_ = np.linalg.lstsq(a, rhs, rcond=None)
    return float(cx), float(cy), math.sqrt(c + cx * cx + cy * cy)


@pytest.mark.parametrize("steer_rad", [0.08, 0.3, -0.2])
def test_constant_steering_drives_the_bicycle_turning_radius(steer_rad: float) -> None:
    geo = EgoGeometry(wheelbase_m=2.8)
    pedals = PedalModel()
    ego = ActuatedEgo(BicycleModel(geo, speed_mps=6.0), pedals=pedals)
    hold = pedals.coast(6.0) / pedals.max_accel_mps2  # throttle that balances the resistance
    command = ControlCommands(throttle=hold, steering_angle_rad=steer_rad)
    xy = []
    for _ in range(1500):  # 15 s at 100 Hz; the steering reaches its angle within 0.4 s
        ego.apply(command, 0.01)
        xy.append((ego.model.x_m, ego.model.y_m))
    assert ego.model.speed_mps == pytest.approx(6.0, rel=1e-9)
    assert ego.model.steer_rad == pytest.approx(steer_rad, abs=1e-12)
    _, cy, radius = _fit_circle(np.array(xy[100:]))
    expected = geo.wheelbase_m / math.tan(abs(steer_rad))
    assert radius == pytest.approx(expected, rel=0.01)
    assert math.copysign(1.0, cy) == math.copysign(1.0, steer_rad)  # centre on the turning side


@pytest.mark.parametrize(
    "pedals",
    [PedalModel(), PedalModel(rolling_resistance_mps2=0.3, drag_coefficient_1pm=3e-3)],
    ids=["default", "draggy"],
)
def test_zero_throttle_and_brake_coast_as_the_model_says(pedals: PedalModel) -> None:
    v0, dt, steps = 25.0, 0.01, 3000
    ego = ActuatedEgo(BicycleModel(EgoGeometry(), speed_mps=v0), pedals=pedals)
    released = ControlCommands()
    ego.apply(released, dt)
    assert ego.model.accel_mps2 == -(
        pedals.rolling_resistance_mps2 + pedals.drag_coefficient_1pm * v0 * v0
    )
    speeds = [ego.model.speed_mps]
    for _ in range(steps - 1):
        ego.apply(released, dt)
        speeds.append(ego.model.speed_mps)

    def coast(_t: float, v: npt.NDArray[np.float64]) -> list[float]:
        return [-(pedals.rolling_resistance_mps2 + pedals.drag_coefficient_1pm * v[0] ** 2)]

    times = dt * np.arange(1, steps + 1)
    ode = solve_ivp(coast, (0.0, times[-1]), [v0], t_eval=times, rtol=1e-10, atol=1e-12)
    # the model holds each step's starting acceleration over the step (first order in dt: at
    # dt = 0.01 s a few mm/s after 30 s of the draggy model's 2 m/s² at 25 m/s)
    np.testing.assert_allclose(speeds, ode.y[0], atol=5e-3)
    assert speeds[-1] < v0 - 5.0  # it really slowed down


def test_coasting_stops_and_never_reverses() -> None:
    pedals = PedalModel(rolling_resistance_mps2=0.5, drag_coefficient_1pm=0.0)
    ego = ActuatedEgo(BicycleModel(EgoGeometry(), speed_mps=2.0), pedals=pedals)
    for _ in range(100):  # 10 s; it stops after v/r = 4 s, 4 m
        ego.apply(ControlCommands(), 0.1)
    assert ego.model.speed_mps == 0.0
    assert ego.model.x_m == pytest.approx(2.0 * 2.0 / (2 * 0.5), rel=1e-9)


def test_full_brake_stops_in_the_model_distance() -> None:
    pedals = PedalModel()
    v0, dt = 20.0, 0.001
    ego = ActuatedEgo(BicycleModel(EgoGeometry(), speed_mps=v0), pedals=pedals)
    while ego.model.speed_mps > 0.0:
        ego.apply(ControlCommands(brake=1.0), dt)
    decel_b, rolling, drag = (
        pedals.max_brake_mps2,
        pedals.rolling_resistance_mps2,
        pedals.drag_coefficient_1pm,
    )

    def braking(_t: float, xv: npt.NDArray[np.float64]) -> list[float]:
        return [xv[1], -(decel_b + rolling + drag * xv[1] ** 2)]

    def stopped(_t: float, xv: npt.NDArray[np.float64]) -> float:
        return float(xv[1])

    stopped.terminal = True  # type: ignore[attr-defined]
    ode = solve_ivp(braking, (0.0, 10.0), [0.0, v0], events=stopped, rtol=1e-10, atol=1e-12)
    distance = float(ode.y_events[0][0][0])
    assert ego.model.x_m == pytest.approx(distance, abs=0.01)
    # v²/(2·max_brake) plus the little the resistance takes off
    assert (
        v0 * v0 / (2 * (decel_b + rolling + drag * v0 * v0))
        < ego.model.x_m
        < v0 * v0 / (2 * decel_b)
    )


def test_brake_is_full_with_the_steering_held() -> None:
    geo = EgoGeometry(max_decel_mps2=9.0)
    pedals = PedalModel()
    # (a gentle curve: −8.1 m/s² and 0.9 m/s² lateral are inside the tyres' friction circle)
    ego = ActuatedEgo(BicycleModel(geo, speed_mps=10.0, steer_rad=0.025), pedals=pedals)
    ego.brake(0.1)
    assert ego.model.steer_rad == 0.025
    assert ego.model.accel_mps2 == pytest.approx(-(pedals.max_brake_mps2 + pedals.coast(10.0)))


def test_limits_are_respected_under_random_commands() -> None:
    geo = EgoGeometry(
        max_steer_rad=0.5,
        max_steer_rate_rad_s=0.6,
        max_accel_mps2=2.0,
        max_decel_mps2=6.0,
        max_jerk_mps3=4.0,
    )
    # the actuators alone: tyres that never slide (the friction circle has its own tests)
    no_slip = TyreLimit(friction_coefficient=1e3)
    ego = ActuatedEgo(BicycleModel(geo, speed_mps=8.0), pedals=PedalModel(), tyres=no_slip)
    rng = np.random.default_rng(15)
    dt = 0.05
    steer, accel, speed = [0.0], [0.0], [8.0]
    for _ in range(4000):
        throttle, brake = (rng.uniform(), 0.0) if rng.uniform() < 0.6 else (0.0, rng.uniform())
        command = ControlCommands(
            throttle=throttle, brake=brake, steering_angle_rad=rng.uniform(-1.5, 1.5)
        )
        ego.apply(command, dt)
        steer.append(ego.model.steer_rad)
        accel.append(ego.model.accel_mps2)
        speed.append(ego.model.speed_mps)
    steer_a, accel_a, speed_a = np.array(steer), np.array(accel), np.array(speed)
    eps = 1e-12
    assert np.abs(steer_a).max() <= geo.max_steer_rad + eps
    assert np.abs(steer_a).max() > 0.45  # the commands did push against the limit
    assert np.abs(np.diff(steer_a)).max() <= geo.max_steer_rate_rad_s * dt + eps
    assert accel_a.max() <= geo.max_accel_mps2 + eps
    assert accel_a.min() >= -geo.max_decel_mps2 - eps
    assert speed_a.min() >= 0.0
    # jerk: every commanded change; coming to rest (accel set to 0 at zero speed) is not one
    jerk = np.abs(np.diff(accel_a)) / dt
    came_to_rest = (speed_a[1:] == 0.0) & (accel_a[1:] == 0.0)
    assert jerk[~came_to_rest].max() <= geo.max_jerk_mps3 + 1e-9
    assert jerk[~came_to_rest].max() > 0.9 * geo.max_jerk_mps3  # the bound was reached


def test_without_a_jerk_bound_the_acceleration_jumps() -> None:
    model = BicycleModel(EgoGeometry(), speed_mps=5.0)
    model.step(0.1, accel_mps2=3.0, steer_rad=0.0)
    assert model.accel_mps2 == 3.0
    bounded = BicycleModel(EgoGeometry(max_jerk_mps3=2.0), speed_mps=5.0)
    bounded.step(0.1, accel_mps2=3.0, steer_rad=0.0)
    assert bounded.accel_mps2 == pytest.approx(0.2)


def test_one_step_delay_shifts_the_response_by_exactly_one_step() -> None:
    geo = EgoGeometry(max_jerk_mps3=5.0)
    prompt = ActuatedEgo(BicycleModel(geo, speed_mps=5.0, steer_rad=0.05), delay_steps=0)
    late = ActuatedEgo(BicycleModel(geo, speed_mps=5.0, steer_rad=0.05), delay_steps=1)
    rng = np.random.default_rng(2)
    commands = [
        ControlCommands(
            throttle=rng.uniform(), brake=0.0, steering_angle_rad=rng.uniform(-0.4, 0.4)
        )
        for _ in range(200)
    ]
    # the delayed ego's first step acts on a neutral command: pedals released, steering held
    prompt.apply(ControlCommands(steering_angle_rad=0.05), 0.1)
    for command in commands:
        late.apply(command, 0.1)
        assert _same_state(late, prompt)
        prompt.apply(command, 0.1)
    assert prompt.model.x_m != late.model.x_m  # the last command has not acted on the late ego yet


def _same_state(a: ActuatedEgo, b: ActuatedEgo) -> bool:
    ma, mb = a.model, b.model
    return (ma.x_m, ma.y_m, ma.yaw_rad, ma.speed_mps, ma.steer_rad, ma.accel_mps2) == (
        mb.x_m,
        mb.y_m,
        mb.yaw_rad,
        mb.speed_mps,
        mb.steer_rad,
        mb.accel_mps2,
    )


def test_pedals_invert_the_pedal_model() -> None:
    pedals = PedalModel()
    for speed in (0.0, 5.0, 30.0):
        for accel in (-7.0, -1.0, -pedals.coast(speed), 0.0, 1.5, 2.5):
            throttle, brake = pedals.pedals(accel, speed)
            assert throttle == 0.0 or brake == 0.0
            got = pedals.acceleration(ControlCommands(throttle=throttle, brake=brake), speed)
            assert got == pytest.approx(accel, abs=1e-12)
    assert pedals.pedals(50.0, 1.0) == (1.0, 0.0)
    assert pedals.pedals(-50.0, 1.0) == (0.0, 1.0)


def test_describe_records_every_parameter() -> None:
    geo = EgoGeometry(max_jerk_mps3=3.0)
    ego = ActuatedEgo(BicycleModel(geo), pedals=PedalModel(max_brake_mps2=7.0), delay_steps=1)
    described = json.loads(json.dumps(ego.describe()))
    assert described["delay_steps"] == 1
    assert described["geometry"]["max_jerk_mps3"] == 3.0
    assert set(described["geometry"]) >= {
        "wheelbase_m",
        "max_steer_rad",
        "max_steer_rate_rad_s",
        "max_accel_mps2",
        "max_decel_mps2",
        "max_jerk_mps3",
    }
    assert described["tyres"] == {
        "friction_coefficient": 0.9,
        "gravity_mps2": 9.80665,
        "friction_circle_mps2": pytest.approx(0.9 * 9.80665),
    }
    assert described["pedals"] == {
        "max_accel_mps2": 3.0,
        "max_brake_mps2": 7.0,
        "rolling_resistance_mps2": 0.1,
        "drag_coefficient_1pm": 2.6e-4,
    }


def test_bad_parameters_are_refused() -> None:
    with pytest.raises(ValueError, match="delay_steps must be 0 or 1"):
        ActuatedEgo(BicycleModel(EgoGeometry()), delay_steps=2)
    with pytest.raises(ValueError, match="dt_s must be a positive"):
        ActuatedEgo(BicycleModel(EgoGeometry())).apply(ControlCommands(), 0.0)
    with pytest.raises(ValueError, match="max_brake_mps2 must be a positive"):
        PedalModel(max_brake_mps2=0.0)
    with pytest.raises(ValueError, match="drag_coefficient_1pm must be a non-negative"):
        PedalModel(drag_coefficient_1pm=float("nan"))


# -- the tyres: the friction circle -------------------------------------------------------------


def _combined(model: BicycleModel) -> tuple[float, float]:
    """(|acceleration|, |lateral acceleration|) of the model's state, as a run records it."""
    state = model.state(0)
    lateral = state.speed_mps * abs(state.yaw_rate_rad_s)
    return float(np.hypot(*state.acceleration[:2])), lateral


def test_full_lock_at_speed_is_held_to_the_friction_circle() -> None:
    geo = EgoGeometry()
    limit = TyreLimit().max_accel_mps2  # 0.9 · 9.80665 = 8.826 m/s²
    # without the tyres: full lock (0.6 rad) at 18 m/s asks v²·tan δ / L = 79 m/s² of them
    free = BicycleModel(geo, speed_mps=18.0, steer_rad=0.6)
    free.step(0.01, accel_mps2=0.0, steer_rad=0.6)
    assert _combined(free)[1] > 75.0
    ego = ActuatedEgo(BicycleModel(geo, speed_mps=18.0), pedals=PedalModel())
    hold = PedalModel().coast(18.0) / PedalModel().max_accel_mps2
    for _ in range(300):
        ego.apply(ControlCommands(throttle=hold, steering_angle_rad=0.6), 0.01)
        total, _ = _combined(ego.model)
        assert total <= limit * (1.0 + 1e-12)
    # at the limit: the turn the tyres hold, R = v² / (μ·g), and the wheel at that angle
    v = ego.model.speed_mps
    assert total == pytest.approx(limit, rel=1e-6)
    assert ego.model.steer_rad == pytest.approx(math.atan(geo.wheelbase_m * limit / v**2), rel=1e-6)
    # the yaw rate is bounded by μ·g / v, well below the steering's v·tan(0.6) / L
    assert ego.model.state(0).yaw_rate_rad_s <= limit / v * (1.0 + 1e-12)


def test_braking_in_a_turn_shares_the_circle() -> None:
    """Full brake with full lock at 15 m/s: the demand (−8.2, 55) m/s² is scaled back onto the
    circle, its direction kept."""
    geo = EgoGeometry()
    tyres = TyreLimit()
    model = BicycleModel(geo, speed_mps=15.0, steer_rad=0.6)
    demand_lat = 15.0**2 * math.tan(0.6) / geo.wheelbase_m
    accel = -(8.0 + PedalModel().coast(15.0))
    model.step(0.01, accel_mps2=accel, steer_rad=0.6, friction_circle_mps2=tyres.max_accel_mps2)
    scale = tyres.max_accel_mps2 / math.hypot(accel, demand_lat)
    assert model.accel_mps2 == pytest.approx(accel * scale, rel=1e-12)
    assert math.tan(model.steer_rad) == pytest.approx(math.tan(0.6) * scale, rel=1e-12)


def test_slow_turns_are_not_touched_by_the_tyres() -> None:
    # 3 m/s at full lock: 9 · tan(0.6) / 2.8 = 2.2 m/s², inside the circle
    ego = ActuatedEgo(BicycleModel(EgoGeometry(), speed_mps=3.0, steer_rad=0.6))
    ego.apply(ControlCommands(throttle=0.1, steering_angle_rad=0.6), 0.1)
    assert ego.model.steer_rad == 0.6
    assert ego.model.accel_mps2 == pytest.approx(PedalModel().acceleration(
        ControlCommands(throttle=0.1), 3.0))  # fmt: skip


def test_random_commands_never_leave_the_friction_circle() -> None:
    rng = np.random.default_rng(33)
    for mu in (0.9, 0.3):
        tyres = TyreLimit(friction_coefficient=mu)
        ego = ActuatedEgo(BicycleModel(EgoGeometry(), speed_mps=20.0), tyres=tyres)
        worst = 0.0
        for _ in range(3000):
            throttle, brake = (rng.uniform(), 0.0) if rng.uniform() < 0.6 else (0.0, rng.uniform())
            ego.apply(
                ControlCommands(
                    throttle=throttle, brake=brake, steering_angle_rad=rng.uniform(-0.8, 0.8)
                ),
                0.05,
            )
            worst = max(worst, _combined(ego.model)[0])
        assert worst <= tyres.max_accel_mps2 * (1.0 + 1e-12)
        assert worst > 0.95 * tyres.max_accel_mps2  # the commands did reach the circle


def test_bad_tyres_are_refused() -> None:
    with pytest.raises(ValueError, match="friction_coefficient must be a positive"):
        TyreLimit(friction_coefficient=0.0)
