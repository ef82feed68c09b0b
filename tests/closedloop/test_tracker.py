"""The built-in path tracker (redrive.closedloop.LqrTracker, nuPlan's LQR tracker) driving the
actuated ego in a loop."""

from __future__ import annotations

import json
import math

import numpy as np
import numpy.typing as npt
import pytest

from redrive.closedloop import LqrTracker
from redrive.closedloop.profiles import fit_profiles, resample_poses
from redrive.closedloop.tracker import LQR_DEFAULTS
from redrive.sim.ego import ActuatedEgo, BicycleModel, EgoGeometry
from redrive.types import PlannedPath, VehicleState

DT_S = 0.1
STEP_NS = 100_000_000


def _straight(speed_mps: float, duration_s: float) -> npt.NDArray[np.float64]:
    t = np.arange(0.0, duration_s + 1e-9, DT_S)
    return np.c_[speed_mps * t, np.zeros_like(t), np.zeros_like(t), t]


def _circle(radius_m: float, speed_mps: float, duration_s: float) -> npt.NDArray[np.float64]:
    """Anticlockwise from the origin heading +x (centre at (0, radius))."""
    t = np.arange(0.0, duration_s + 1e-9, DT_S)
    a = speed_mps * t / radius_m
    return np.c_[radius_m * np.sin(a), radius_m * (1.0 - np.cos(a)), np.zeros_like(t), t]


def _stopping(speed_mps: float, cruise_s: float, decel_mps2: float) -> npt.NDArray[np.float64]:
    """Straight along +x: ``speed_mps`` for ``cruise_s``, then braking at ``decel_mps2`` to a stop."""
    stop_s = cruise_s + speed_mps / decel_mps2
    t = np.arange(0.0, stop_s + 1e-9, DT_S)
    v = np.clip(speed_mps - decel_mps2 * np.clip(t - cruise_s, 0.0, None), 0.0, None)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * DT_S)])
    return np.c_[s, np.zeros_like(t), np.zeros_like(t), t]


def _drive(
    tracker: LqrTracker,
    waypoints: npt.NDArray[np.float64],
    *,
    y_m: float = 0.0,
    speed_mps: float,
    duration_s: float,
    delay_steps: int = 0,
) -> npt.NDArray[np.float64]:
    """Closed loop on a map-frame path; rows (t_s, x, y, yaw, speed, steer) after each step."""
    ego = ActuatedEgo(
        BicycleModel(tracker.geometry, y_m=y_m, speed_mps=speed_mps),
        pedals=tracker.pedals,
        delay_steps=delay_steps,
    )
    path = PlannedPath(stamp_ns=0, waypoints=waypoints, frame_id="map")
    rows = []
    for k in range(round(duration_s / DT_S)):
        stamp = k * STEP_NS
        ego.apply(tracker.commands(ego.state(stamp), path, DT_S, stamp_ns=stamp), DT_S)
        m = ego.model
        rows.append(((k + 1) * DT_S, m.x_m, m.y_m, m.yaw_rad, m.speed_mps, m.steer_rad))
    return np.array(rows)


def test_converges_to_a_straight_path_from_a_lateral_offset() -> None:
    tracker = LqrTracker()
    rows = _drive(tracker, _straight(10.0, 20.0), y_m=1.0, speed_mps=10.0, duration_s=8.0)
    lateral = rows[:, 2]
    assert abs(lateral[round(3.0 / DT_S) - 1 :]).max() < 0.05  # within 3 s …
    assert abs(lateral[-20:]).max() < 0.01  # … and settles on the line
    # nuPlan's one-step LQR (the error 1 s ahead weighed, not an infinite horizon) overshoots a
    # little: 3.6 cm of the 1 m offset here
    assert -lateral.min() < 0.05
    assert np.abs(rows[:, 5]).max() <= tracker.geometry.max_steer_rad


def test_converges_with_a_one_step_actuation_delay() -> None:
    rows = _drive(
        LqrTracker(),
        _straight(10.0, 20.0),
        y_m=1.0,
        speed_mps=10.0,
        duration_s=8.0,
        delay_steps=1,
    )
    # nuPlan's tracker does not model the delay: it rings, within 8 cm of the line after 6 s
    assert abs(rows[-20:, 2]).max() < 0.1


def test_a_tighter_gain_reaches_the_line_faster() -> None:
    # the weights are real: a dearer steering rate closes the offset later
    gentle = _drive(
        LqrTracker(r_lateral=(100.0,)),
        _straight(10.0, 20.0),
        y_m=1.0,
        speed_mps=10.0,
        duration_s=3.0,
    )
    default = _drive(LqrTracker(), _straight(10.0, 20.0), y_m=1.0, speed_mps=10.0, duration_s=3.0)
    assert abs(default[9, 2]) < abs(gentle[9, 2])


def test_follows_a_circle_of_radius_30_m() -> None:
    radius = 30.0
    tracker = LqrTracker()
    rows = _drive(tracker, _circle(radius, 10.0, 15.0), speed_mps=10.0, duration_s=12.0)
    error = np.hypot(rows[:, 1], rows[:, 2] - radius) - radius
    steady = error[round(3.0 / DT_S) :]
    assert abs(steady).max() < 0.2
    assert rows[-1, 3] > math.pi  # it really went round: more than half a circle
    expected_steer = math.atan(tracker.geometry.wheelbase_m / radius)
    assert rows[-1, 5] == pytest.approx(expected_steer, rel=0.05)
    assert rows[-1, 4] == pytest.approx(10.0, abs=0.1)


def test_follows_a_speed_profile_to_a_stop_at_the_path_end() -> None:
    tracker = LqrTracker()
    waypoints = _stopping(10.0, 2.0, 2.0)
    end_x = waypoints[-1, 0]
    rows = _drive(tracker, waypoints, speed_mps=10.0, duration_s=12.0)
    # below 0.2 m/s nuPlan's stopping controller takes over: a = 0.5 · (0 − v), a slow decay
    assert rows[-1, 4] <= tracker.params["stopping_velocity_mps"]
    assert abs(rows[-1, 1] - end_x) < 1.5
    # it braked along the profile, not at the last moment: halfway through braking (t = 4.5 s)
    # the path's speed is 5 m/s
    assert rows[round(4.5 / DT_S) - 1, 4] == pytest.approx(5.0, abs=0.3)


def _from_rest(accel_mps2: float, top_mps: float, duration_s: float) -> npt.NDArray[np.float64]:
    t = np.arange(0.0, duration_s + 1e-9, DT_S)
    v = np.minimum(accel_mps2 * t, top_mps)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * DT_S)])
    return np.c_[s, np.zeros_like(t), np.zeros_like(t), t]


def test_a_plan_that_accelerates_from_rest_starts_the_ego() -> None:
    """The reference speed is read one horizon (1 s) ahead: a plan whose speed at t = 0 is 0 is
    not "stopped" (the old tracker held the brake while both speeds were below 0.3 m/s)."""
    tracker = LqrTracker()
    plan = _from_rest(1.0, 10.0, 8.0)
    state = ActuatedEgo(BicycleModel(tracker.geometry)).state(0)
    first = tracker.commands(state, PlannedPath(stamp_ns=0, waypoints=plan, frame_id="map"),
                             DT_S, stamp_ns=0)  # fmt: skip
    assert first.throttle > 0.0
    assert first.brake == 0.0
    rows = _drive(tracker, plan, speed_mps=0.0, duration_s=6.0)
    # the fitted reference 1 s ahead is 1 m/s: a = 10/11 · (1 − 0) at the start, and the ego
    # then keeps pace with the plan's 1 m/s²
    assert rows[19, 4] == pytest.approx(2.0, abs=0.1)
    assert rows[59, 4] == pytest.approx(6.0, abs=0.1)


def test_the_longitudinal_law_is_nuplans_one_step_lqr() -> None:
    # a = N·dt·q / ((N·dt)²·q + r) · (v_ref − v) = 1·10 / (1·10 + 1) · (8 − 5) = 30/11 m/s²
    tracker = LqrTracker()
    assert tracker.longitudinal(5.0, 8.0) == pytest.approx(30.0 / 11.0)
    # … and that acceleration reaches the pedals: 5 m/s on a straight 8 m/s path
    state = ActuatedEgo(BicycleModel(tracker.geometry, speed_mps=5.0)).state(0)
    command = tracker.commands(state, PlannedPath(stamp_ns=0, waypoints=_straight(8.0, 6.0)),
                               DT_S, stamp_ns=0)  # fmt: skip
    accel = tracker.pedals.acceleration(command, 5.0)
    assert accel == pytest.approx(30.0 / 11.0, rel=1e-6)


def test_the_lateral_law_is_nuplans_one_step_lqr_by_hand() -> None:
    """Horizon 3, dt 0.1 s, 10 m/s, L = 2.8 m, straight reference, 0.5 m left of it.  Each step
    is I + E with E[0,1] = v·dt = 1 and E[1,2] = v·dt/L = 5/14; over three steps B = (1/28,
    3/28, 3/10) and the error without input (0.5, 0, 0).  With Q = diag(1, 10, 0), R = 1:
    u = −Bᵀ Q e / (Bᵀ Q B + R) = −(1/56) / (91/784 + 1) = −14/875 = −0.016 rad/s."""
    tracker = LqrTracker(tracking_horizon=3)
    rate = tracker.lateral(
        np.array([0.5, 0.0, 0.0]), speeds_mps=np.full(3, 10.0), curvatures_1pm=np.zeros(3)
    )
    assert rate == pytest.approx(-0.016, abs=1e-12)


def test_the_fitted_reference_of_a_constant_speed_circle() -> None:
    radius, speed = 30.0, 10.0
    times, poses = resample_poses(
        _circle(radius, speed, 6.0), discretization_time_s=0.1, standing_heading_rad=0.0
    )
    profiles = fit_profiles(
        times, poses, discretization_time_s=0.1, jerk_penalty=1e-4, curvature_rate_penalty=1e-2
    )
    assert len(times) == 61
    # chords read along the tangent: 2R·sin(θ/2)·cos(θ/2) / dt for θ = v·dt/R, 1.9e-4 below v
    theta = speed * 0.1 / radius
    along = 2.0 * radius * math.sin(theta / 2.0) * math.cos(theta / 2.0) / 0.1
    np.testing.assert_allclose(profiles.speed_mps, along, rtol=1e-6)
    np.testing.assert_allclose(profiles.curvature_1pm, 1.0 / radius, rtol=1e-3)
    # the headings are the circle's tangents, the ends included
    np.testing.assert_allclose(poses[:, 2], speed * times / radius, atol=1e-9)


def test_a_standing_path_stops_and_holds_the_wheel() -> None:
    path = PlannedPath(stamp_ns=0, waypoints=np.array([[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]))
    state = ActuatedEgo(BicycleModel(EgoGeometry())).state(0)
    command = LqrTracker().commands(state, path, DT_S, stamp_ns=0, steer_rad=0.1)
    # the stopping controller: a = 0.5 · (0 − 0) = 0, the steering rate 0 (the wheel held);
    # standing, no pedal is needed to stay
    assert (command.throttle, command.brake, command.steering_angle_rad) == (0.0, 0.0, 0.1)
    # a single waypoint ("be here") is a standing path too
    one = PlannedPath(stamp_ns=0, waypoints=np.zeros((1, 4)))
    assert LqrTracker().commands(state, one, DT_S, stamp_ns=0).throttle == 0.0


def test_slowing_to_a_stop_uses_the_stopping_controller() -> None:
    tracker = LqrTracker()
    state = ActuatedEgo(BicycleModel(EgoGeometry(), speed_mps=0.15)).state(0)
    path = PlannedPath(stamp_ns=0, waypoints=_straight(0.0, 2.0))
    command = tracker.commands(state, path, DT_S, stamp_ns=0)
    assert tracker.pedals.acceleration(command, 0.15) == pytest.approx(-0.5 * 0.15)


def test_base_link_paths_replanned_every_other_step() -> None:
    """A planner that replans in base_link every 0.2 s; in between, the tracker reads the older path
    one step later on its time column."""
    tracker = LqrTracker()
    plan = _stopping(10.0, 2.0, 2.0)
    plan[:, 1] = 0.5  # the line to follow is 0.5 m left of the start
    ego = ActuatedEgo(BicycleModel(tracker.geometry, speed_mps=10.0), pedals=tracker.pedals)
    path: PlannedPath | None = None
    for k in range(120):
        stamp = k * STEP_NS
        state = ego.state(stamp)
        if k % 2 == 0:
            path = _in_base_link(
                plan, state.position[:2], state.heading_rad, now_s=k * DT_S, stamp_ns=stamp
            )
        assert path is not None
        ego.apply(tracker.commands(state, path, DT_S, stamp_ns=stamp), DT_S)
    assert ego.model.speed_mps < tracker.params["stopping_velocity_mps"]
    assert abs(ego.model.x_m - plan[-1, 0]) < 1.5
    assert ego.model.y_m == pytest.approx(0.5, abs=0.05)


def _in_base_link(
    plan: npt.NDArray[np.float64],
    xy: npt.NDArray[np.float64],
    yaw_rad: float,
    *,
    now_s: float,
    stamp_ns: int,
) -> PlannedPath:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    d = plan[:, :2] - xy
    local = np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]]
    future = plan[:, 3] >= now_s
    if not future.any():  # the plan is over: stand where its end is
        future[-1] = True
    t = np.clip(plan[future, 3] - now_s, 0.0, None)
    waypoints = np.c_[local[future], np.zeros(int(future.sum())), t]
    return PlannedPath(stamp_ns=stamp_ns, waypoints=waypoints, frame_id="base_link")


def test_a_base_link_path_gives_the_same_commands_as_the_map_path() -> None:
    plan = _circle(30.0, 8.0, 6.0)
    yaw = 0.4
    rot = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    origin = np.array([100.0, -50.0])
    map_wp = plan.copy()
    map_wp[:, :2] = plan[:, :2] @ rot.T + origin + np.array([0.0, 0.3]) @ rot.T  # ego 0.3 m right
    map_path = PlannedPath(stamp_ns=5, waypoints=map_wp, frame_id="map")
    base_wp = plan.copy()
    base_wp[:, 1] += 0.3
    base_path = PlannedPath(stamp_ns=5, waypoints=base_wp)
    state = ActuatedEgo(
        BicycleModel(EgoGeometry(), x_m=origin[0], y_m=origin[1], yaw_rad=yaw, speed_mps=7.0)
    ).state(5)
    a = LqrTracker().commands(state, map_path, DT_S, stamp_ns=5)
    b = LqrTracker().commands(state, base_path, DT_S, stamp_ns=5)
    assert a.steering_angle_rad == pytest.approx(b.steering_angle_rad, abs=1e-9)
    # towards the path on the left, and round the curve: one step of the steering rate
    assert a.steering_angle_rad > 0.01
    assert (a.throttle, a.brake) == pytest.approx((b.throttle, b.brake), abs=1e-9)
    assert a.throttle > 0.0  # 7 m/s towards the path's 8 m/s


@pytest.mark.parametrize(
    ("waypoints", "frame", "match"),
    [
        (np.zeros((0, 4)), "base_link", "has no waypoints"),
        (
            np.array([[0.0, 0.0, 0.0, 0.0], [1.0, np.nan, 0.0, 0.1]]),
            "base_link",
            r"non-finite .* \[1\]",
        ),
        (np.array([[0.0, 0.0, 0.0, 0.0], [np.inf, 0.0, 0.0, 0.1]]), "base_link", "non-finite"),
        (np.array([[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, np.inf]]), "base_link", "non-finite"),
        (np.array([[0.0, 0.0, 0.0, 0.0], [5.0, 0.0, 0.0, 0.0]]), "base_link", "same time"),
        (_straight(5.0, 2.0), "odom", "frame 'odom' but the ego state is in 'map'"),
    ],
)
def test_bad_paths_raise_value_error(
    waypoints: npt.NDArray[np.float64], frame: str, match: str
) -> None:
    path = PlannedPath(stamp_ns=0, waypoints=waypoints, frame_id=frame)
    state = ActuatedEgo(BicycleModel(EgoGeometry(), speed_mps=5.0)).state(0)
    with pytest.raises(ValueError, match=match):
        LqrTracker().commands(state, path, DT_S, stamp_ns=0)


def test_describe_names_the_tracker_its_source_and_every_parameter() -> None:
    tracker = LqrTracker(q_lateral=(2.0, 4.0, 0.0), tracking_horizon=8)
    described = json.loads(json.dumps(tracker.describe()))
    assert described["name"] == "lqr"
    assert "nuplan/planning/simulation/controller/tracker/lqr.py" in described["source"]
    assert described["q_lateral"] == [2.0, 4.0, 0.0]
    assert described["tracking_horizon"] == 8
    for key in (
        "q_longitudinal",
        "r_longitudinal",
        "r_lateral",
        "discretization_time_s",
        "jerk_penalty",
        "curvature_rate_penalty",
        "stopping_proportional_gain",
        "stopping_velocity_mps",
        "wheelbase_m",
        "max_steer_rad",
        "pedals",
    ):
        assert key in described
    # the defaults are nuPlan's lqr_tracker.yaml
    assert LqrTracker().params == {
        **{k: list(v) if isinstance(v, tuple) else v for k, v in LQR_DEFAULTS.items()}
    }


def test_bad_parameters_are_refused() -> None:
    with pytest.raises(ValueError, match="weights of r_lateral must be positive"):
        LqrTracker(r_lateral=(0.0,))
    with pytest.raises(ValueError, match="q_lateral has 3 weight"):
        LqrTracker(q_lateral=(1.0, 1.0))
    with pytest.raises(ValueError, match="tracking_horizon must be greater than 1"):
        LqrTracker(tracking_horizon=1)
    with pytest.raises(ValueError, match="jerk_penalty must be a positive"):
        LqrTracker(jerk_penalty=-1.0)
    with pytest.raises(ValueError, match="dt_s must be a positive"):
        LqrTracker().commands(
            ActuatedEgo(BicycleModel(EgoGeometry())).state(0),
            PlannedPath(stamp_ns=0, waypoints=_straight(5.0, 1.0)),
            0.0,
            stamp_ns=0,
        )


def test_track_equals_nuplan_devkits_own_computation() -> None:
    """A path that speeds up (v = 2 + t m/s) on a growing curve (κ = 0.02·t 1/m), poses every
    0.1 s; the ego 0.4 m left of it 0.3 s in, 0.05 rad off its heading, at 2.5 m/s with the
    wheel at 0.01 rad.  The expected values were computed by nuplan-devkit's own functions (its
    commit e924167: tracker_utils.get_velocity_curvature_profiles_with_derivatives_from_poses,
    LQRTracker._longitudinal_lqr_controller and _lateral_lqr_controller, default parameters,
    wheelbase 2.8 m) on these inputs; on 200 random paths the fits agreed with redrive's to
    1e-12 and the laws to 1e-15."""
    dt = 0.1
    t = np.arange(51) * dt
    v = 2.0 + 1.0 * t
    k = 0.02 * t
    h = np.concatenate([[0.0], np.cumsum(v[:-1] * k[:-1] * dt)])
    steps = np.c_[np.cos(h[:-1]), np.sin(h[:-1])] * v[:-1, None] * dt
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(steps, axis=0)])
    poses = np.c_[xy, h]
    profiles = fit_profiles(
        t, poses, discretization_time_s=dt, jerk_penalty=1e-4, curvature_rate_penalty=1e-2
    )
    xr, yr, hr = poses[3]
    ego = (xr - 0.4 * math.sin(hr), yr + 0.4 * math.cos(hr), hr + 0.05)
    accel, rate = LqrTracker().track(profiles, pose=ego, speed_mps=2.5, steer_rad=0.01, t_s=0.3)
    assert profiles.speed_at(1.3) == pytest.approx(3.299999999999983, abs=1e-9)
    assert accel == pytest.approx(0.7272727272727119, abs=1e-9)  # 10/11 · (3.3 − 2.5)
    assert rate == pytest.approx(-0.07155167673825265, abs=1e-9)


def _numpy_commands(
    tracker: LqrTracker,
    waypoints: npt.NDArray[np.float64],
    *,
    pose: tuple[float, float, float],
    speed_mps: float,
    steer_rad: float,
    t_s: float,
) -> tuple[float, float]:
    """The acceleration and steering rate by the readable numpy functions (the reference of the
    compiled ``commands``)."""
    times, poses = resample_poses(
        waypoints, discretization_time_s=DT_S, standing_heading_rad=pose[2]
    )
    profiles = fit_profiles(
        times,
        poses,
        discretization_time_s=DT_S,
        jerk_penalty=LQR_DEFAULTS["jerk_penalty"],
        curvature_rate_penalty=LQR_DEFAULTS["curvature_rate_penalty"],
    )
    return tracker.track(profiles, pose=pose, speed_mps=speed_mps, steer_rad=steer_rad, t_s=t_s)


def _varied_paths(rng: np.random.Generator) -> list[npt.NDArray[np.float64]]:
    paths = [_straight(8.0, 6.0), _circle(25.0, 6.0, 8.0), _stopping(10.0, 1.0, 3.0)]
    paths.append(np.array([[1.0, 2.0, 0.0, 0.0]]))  # "be here": one waypoint
    paths.append(np.array([[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.05]]))  # shorter than a step
    for _ in range(40):
        k = int(rng.integers(2, 90))
        t = np.cumsum(rng.uniform(0.02, 0.3, size=k)) - 0.1
        heading = np.cumsum(rng.normal(0.0, 0.6, size=k))  # turns past ±π on the way
        step = rng.uniform(0.0, 2.0, size=k) * (rng.random(k) > 0.2)  # some standing points
        xy = np.cumsum(np.c_[step * np.cos(heading), step * np.sin(heading)], axis=0)
        wp = np.c_[xy, np.zeros(k), t]
        if k > 4:
            wp[3, 3] = wp[2, 3]  # two waypoints at one time (the same point)
            wp[3, :2] = wp[2, :2]
        paths.append(wp)
    return paths


@pytest.mark.parametrize("horizon", [10, 3, 24, 130])
def test_compiled_commands_equal_the_numpy_reference(horizon: int) -> None:
    """``commands`` runs resample_poses + fit_profiles + track as one compiled kernel
    (closedloop._tracker_kernels); on straight, curved, stopping, standing, one-point and random
    winding paths, from offset poses, it gives what the numpy functions give (the same doubles
    on the machine this was written on; here to 1e-12, as numpy's own summation order of einsum
    may change with the CPU).  Horizons of 8 and more take numpy's pairwise summation; past 128
    (numpy's block) ``commands`` runs the numpy functions themselves."""
    rng = np.random.default_rng(7)
    tracker = LqrTracker(tracking_horizon=horizon)
    compared = 0
    for wp in _varied_paths(rng):
        for _ in range(4):
            pose = (
                float(rng.normal(0.0, 0.5)),
                float(rng.normal(0.0, 0.5)),
                float(rng.normal(0.0, 2.0)),
            )
            speed, steer = float(rng.uniform(0.0, 12.0)), float(rng.normal(0.0, 0.1))
            stamp_ns = int(rng.integers(-100_000_000, 400_000_000))
            state = VehicleState(
                stamp_ns=stamp_ns,
                frame_id="map",
                position=np.array([pose[0], pose[1], 0.0]),
                velocity=np.array([speed * math.cos(pose[2]), speed * math.sin(pose[2]), 0.0]),
                heading_rad=pose[2],
            )
            speed = state.speed_mps
            want_accel, want_rate = _numpy_commands(
                tracker, wp, pose=pose, speed_mps=speed, steer_rad=steer, t_s=stamp_ns * 1e-9
            )
            path = PlannedPath(stamp_ns=0, waypoints=wp, frame_id="map")
            got = tracker.commands(state, path, DT_S, stamp_ns=stamp_ns, steer_rad=steer)
            want_throttle, want_brake = (
                tracker.pedals.pedals(want_accel, speed)
                if not (speed <= 0.0 and want_accel <= 0.0)
                else (0.0, 0.0)
            )
            g = tracker.geometry
            want_steer = min(max(steer + want_rate * DT_S, -g.max_steer_rad), g.max_steer_rad)
            np.testing.assert_allclose(
                [got.throttle, got.brake, got.steering_angle_rad],
                [want_throttle, want_brake, want_steer],
                rtol=1e-12,
                atol=1e-12,
            )
            compared += 1
    assert compared == 4 * 45


def test_the_compiled_path_check_passes_what_the_numpy_check_passes() -> None:
    """``commands`` checks a path with ``path_is_trackable`` (compiled) and, when it fails, with
    ``_check_path``, which says why: both refuse the same paths."""
    from redrive.closedloop._tracker_kernels import path_is_trackable
    from redrive.closedloop.tracker import _check_path

    rng = np.random.default_rng(3)
    refused = 0
    for _ in range(2000):
        k = int(rng.integers(1, 6))
        wp = np.c_[rng.integers(0, 3, size=(k, 2)) * rng.choice([1.0, 1e-7]), np.zeros(k)]
        wp = np.c_[wp, np.cumsum(rng.integers(-1, 3, size=k) * 0.1)]
        if rng.random() < 0.1:
            wp[rng.integers(k), rng.integers(4)] = rng.choice([np.nan, np.inf, -np.inf])
        try:
            _check_path(PlannedPath(stamp_ns=0, waypoints=wp, frame_id="map"))
            numpy_ok = True
        except ValueError:
            numpy_ok = False
        assert path_is_trackable(np.ascontiguousarray(wp)) == numpy_ok, wp
        refused += not numpy_ok
    assert 200 < refused < 1800
