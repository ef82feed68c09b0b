"""PurePursuitPid: steering sign and size, speed control, PID state; closed loop with IdmPlanner
on a kinematic bicycle (redrive.sim.ego.BicycleModel)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from redrive.algorithms import Role, StageOutputs
from redrive.algorithms.reference.controller import (
    PurePursuitPid,
    path_speed_mps,
    pure_pursuit_steer_rad,
)
from redrive.algorithms.reference.planner import IdmPlanner, Polyline
from redrive.errors import AlgorithmError, ConfigError
from redrive.sim.ego import BicycleModel, EgoGeometry
from redrive.types import (
    Box3D,
    ControlCommands,
    DetectedObject,
    Frame,
    ObjectClass,
    PlannedPath,
    VehicleState,
)

STAMP_NS = 1_700_000_000_000_000_000
F64 = npt.NDArray[np.float64]


def make_frame(speed_mps: float, *, stamp_ns: int = STAMP_NS, index: int = 0) -> Frame:
    state = VehicleState(stamp_ns=stamp_ns, velocity=np.array([speed_mps, 0.0, 0.0]))
    return Frame(stamp_ns=stamp_ns, index=index, vehicle_state=state)


def planned(path: PlannedPath) -> StageOutputs:
    return StageOutputs({"planner": path}, {"planner": Role.PLANNING})


def arc_path(curvature_1pm: float, speed_mps: float, *, stamp_ns: int = STAMP_NS) -> PlannedPath:
    """Waypoints every 0.1 s at constant speed on an arc of the given curvature from the origin."""
    t = np.arange(61) * 0.1
    s = speed_mps * t
    if curvature_1pm == 0.0:
        x, y = s, np.zeros_like(s)
    else:
        k = curvature_1pm
        x, y = np.sin(k * s) / k, (1.0 - np.cos(k * s)) / k
    return PlannedPath(stamp_ns=stamp_ns, waypoints=np.column_stack([x, y, np.zeros_like(s), t]))


def test_steering_sign_and_size_on_arcs() -> None:
    ctl = PurePursuitPid()
    left = ctl.step(make_frame(8.0), planned(arc_path(0.05, 8.0)))
    assert left.steering_angle_rad > 0.0  # REP-103: left positive
    # on a circle pure pursuit steers exactly the circle's curvature: atan(L κ)
    assert left.steering_angle_rad == pytest.approx(math.atan(2.8 * 0.05), abs=2e-3)
    right = ctl.step(make_frame(8.0), planned(arc_path(-0.05, 8.0)))
    assert right.steering_angle_rad == pytest.approx(-left.steering_angle_rad, abs=1e-9)
    straight = ctl.step(make_frame(8.0), planned(arc_path(0.0, 8.0)))
    assert straight.steering_angle_rad == pytest.approx(0.0, abs=1e-12)
    sharp = ctl.step(make_frame(8.0), planned(arc_path(0.3, 8.0)))
    assert sharp.steering_angle_rad == pytest.approx(0.6)  # clipped to max_steer_rad


def test_pure_pursuit_returns_to_an_offset_path_and_handles_short_paths() -> None:
    # the path runs 1 m to the left, parallel: steer left
    xy = np.column_stack([np.linspace(0.0, 30.0, 31), np.ones(31)])
    assert pure_pursuit_steer_rad(xy, 5.0, wheelbase_m=2.8, max_steer_rad=0.6) > 0.1
    # a path shorter than the lookahead is extended straight; a point path steers straight
    short = np.array([[0.0, 0.0], [1.0, 1.0]])
    expected = math.atan(2.8 * 2.0 * math.sin(math.pi / 4.0) / 4.0)
    assert pure_pursuit_steer_rad(short, 4.0, wheelbase_m=2.8, max_steer_rad=1.0) == (
        pytest.approx(expected)
    )
    assert pure_pursuit_steer_rad(np.zeros((5, 2)), 4.0, wheelbase_m=2.8, max_steer_rad=0.6) == 0.0


def test_target_speed_from_waypoints() -> None:
    path = arc_path(0.02, 7.0)
    assert path_speed_mps(path, 0.5) == pytest.approx(7.0, rel=1e-3)
    assert path_speed_mps(path, 100.0) == pytest.approx(7.0, rel=1e-3)  # clipped to the end
    t = np.arange(31) * 0.2
    x = 0.5 * 1.0 * t**2  # accelerating at 1 m/s² from standstill
    accel = PlannedPath(stamp_ns=0, waypoints=np.column_stack([x, 0 * t, 0 * t, t]))
    assert path_speed_mps(accel, 2.0) == pytest.approx(2.0, abs=1e-9)
    still = PlannedPath(
        stamp_ns=0, waypoints=np.column_stack([np.zeros((10, 3)), np.arange(10) * 0.1])
    )
    assert path_speed_mps(still, 0.5) == 0.0


def test_faster_than_target_brakes_slower_throttles() -> None:
    path = planned(arc_path(0.0, 10.0))
    fast = PurePursuitPid().step(make_frame(14.0), path)
    assert fast.brake > 0.0
    assert fast.throttle == 0.0
    slow = PurePursuitPid().step(make_frame(6.0), path)
    assert slow.throttle > 0.0
    assert slow.brake == 0.0
    assert slow.throttle == 1.0  # kp · e = 4 saturates
    small = PurePursuitPid().step(make_frame(9.7), path)
    assert small.throttle == pytest.approx(1.0 * 0.3)  # first frame: P only, kp · e


def test_never_throttle_and_brake_together() -> None:
    ctl = PurePursuitPid()
    rng = np.random.default_rng(3)
    for i in range(200):
        v = float(rng.uniform(0.0, 20.0))
        target = float(rng.uniform(0.0, 20.0))
        cmd = ctl.step(
            make_frame(v, stamp_ns=STAMP_NS + i * 100_000_000, index=i),
            planned(arc_path(0.0, target, stamp_ns=STAMP_NS + i * 100_000_000)),
        )
        assert cmd.throttle == 0.0 or cmd.brake == 0.0


def test_integral_builds_up_is_bounded_and_reset_clears_it() -> None:
    ctl = PurePursuitPid()
    ctl.configure({"kp": 0.1, "ki": 0.2, "integral_limit": 0.3})
    path_at = lambda i: planned(arc_path(0.0, 10.0, stamp_ns=STAMP_NS + i * 100_000_000))  # noqa: E731
    outputs = [
        ctl.step(make_frame(9.0, stamp_ns=STAMP_NS + i * 100_000_000, index=i), path_at(i)).throttle
        for i in range(100)
    ]
    assert outputs[0] == pytest.approx(0.1)  # first frame: P only
    assert outputs[1] == pytest.approx(0.1 + 0.2 * 0.1)  # one step of 0.1 s of 1 m/s error
    assert outputs[-1] == pytest.approx(0.1 + 0.3)  # anti-windup: I share capped at 0.3
    ctl.reset()
    again = ctl.step(make_frame(9.0, stamp_ns=STAMP_NS + 10**10, index=100), path_at(100))
    assert again.throttle == pytest.approx(0.1)
    # a long pause between frames restarts I/D like a first frame
    later = ctl.step(make_frame(9.0, stamp_ns=STAMP_NS + 2 * 10**10, index=101), path_at(200))
    assert later.throttle == pytest.approx(0.1)


def test_standstill_is_held_with_the_brake() -> None:
    still = PlannedPath(
        stamp_ns=STAMP_NS, waypoints=np.column_stack([np.zeros((61, 3)), np.arange(61) * 0.1])
    )
    cmd = PurePursuitPid().step(make_frame(0.0), planned(still))
    assert cmd == ControlCommands(throttle=0.0, brake=0.4, steering_angle_rad=0.0)


def test_no_path_is_an_error_and_bad_config_is_refused() -> None:
    with pytest.raises(AlgorithmError, match="no planned path"):
        PurePursuitPid().step(make_frame(3.0), StageOutputs())
    with pytest.raises(ConfigError):
        PurePursuitPid().configure({"kp": -1.0})
    with pytest.raises(ConfigError):
        PurePursuitPid().configure({"hold_brake": 2.0})
    with pytest.raises(ConfigError):
        PurePursuitPid().configure({"gain": 1.0})


# -- closed loop --------------------------------------------------------------------------------

FRAME_NS = 100_000_000  # 10 Hz
PLANT_SUBSTEPS = 10


def accel_from(cmd: ControlCommands, speed_mps: float) -> float:
    """The test's vehicle: full throttle 3 m/s², full brake 8 m/s², rolling resistance and drag
    (0.1 m/s² + 0.0006 v²) while moving."""
    resistance = 0.1 + 0.0006 * speed_mps**2 if speed_mps > 0.0 else 0.0
    return 3.0 * cmd.throttle - 8.0 * cmd.brake - resistance


def curved_route() -> F64:
    """Straight 30 m, left 90° on R = 40 m, straight 20 m, right 60° on R = 40 m, straight 60 m;
    sampled every 0.25 m (map frame, metres)."""
    pts = [np.array([0.0, 0.0])]
    heading = 0.0
    pieces = [(30.0, 0.0), (40.0 * math.pi / 2.0, 1 / 40.0), (20.0, 0.0)]
    pieces += [(40.0 * math.pi / 3.0, -1 / 40.0), (60.0, 0.0)]
    for length_m, kappa in pieces:
        n = round(length_m / 0.25)
        for _ in range(n):
            ds = length_m / n
            mid = heading + 0.5 * kappa * ds
            pts.append(pts[-1] + ds * np.array([math.cos(mid), math.sin(mid)]))
            heading += kappa * ds
    return np.array(pts)


def drive(
    planner: IdmPlanner,
    controller: PurePursuitPid,
    model: BicycleModel,
    *,
    seconds: float,
    obstacles_map: list[DetectedObject] = (),  # type: ignore[assignment]
) -> tuple[F64, F64]:
    """Run planner → controller → bicycle at 10 Hz; rear-axle (x, y) and speed after each frame."""
    xy, speed = [], []
    for i in range(round(seconds * 10)):
        stamp = STAMP_NS + i * FRAME_NS
        state = model.state(stamp)
        c, s = math.cos(model.yaw_rad), math.sin(model.yaw_rad)
        seen = []
        for obj in obstacles_map:
            d = obj.box.center[:2] - [model.x_m, model.y_m]
            center = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], obj.box.center[2]])
            box = Box3D(center=center, size=obj.box.size, yaw_rad=obj.box.yaw_rad - model.yaw_rad)
            seen.append(DetectedObject(object_class=obj.object_class, box=box))
        frame = Frame(stamp_ns=stamp, index=i, vehicle_state=state)
        upstream = StageOutputs({"gt": tuple(seen)}, {"gt": Role.PERCEPTION})
        path = planner.step(frame, upstream)
        cmd = controller.step(frame, upstream.merged({"idm": path}, {"idm": Role.PLANNING}))
        for _ in range(PLANT_SUBSTEPS):
            model.step(
                FRAME_NS * 1e-9 / PLANT_SUBSTEPS,
                accel_mps2=accel_from(cmd, model.speed_mps),
                steer_rad=cmd.steering_angle_rad,
            )
        xy.append((model.x_m, model.y_m))
        speed.append(model.speed_mps)
    return np.array(xy), np.array(speed)


def test_closed_loop_follows_a_curved_route() -> None:
    route = curved_route()
    planner = IdmPlanner()
    planner.configure({"route": route.tolist(), "v0_mps": 10.0})
    controller = PurePursuitPid()
    model = BicycleModel(EgoGeometry(), x_m=0.0, y_m=0.3, yaw_rad=0.0, speed_mps=5.0)
    xy, speed = drive(planner, controller, model, seconds=30.0)
    _, lateral, _ = Polyline(route).project(xy)
    settled = np.abs(lateral[20:])  # after 2 s the initial 0.3 m offset is gone
    assert settled.max() < 0.5
    assert speed.max() <= 10.0 + 0.3
    assert speed[100:150].min() > 9.0  # cruises at v0 through the curves
    # it reaches the end of the route and stops there, front bumper s0 before it
    length_m = Polyline(route).length_m
    s_end, _, _ = Polyline(route).project(xy[-1])
    assert speed[-1] == 0.0
    assert length_m - 2.0 - 1.0 < s_end[0] + 3.75 <= length_m


def test_closed_loop_stops_behind_a_stopped_car() -> None:
    planner = IdmPlanner()
    controller = PurePursuitPid()
    model = BicycleModel(EgoGeometry(), speed_mps=12.0)
    parked = DetectedObject(
        object_class=ObjectClass.VEHICLE,
        box=Box3D(center=np.array([80.0, 0.2, 0.8]), size=np.array([4.5, 1.8, 1.6])),
    )
    xy, speed = drive(planner, controller, model, seconds=20.0, obstacles_map=[parked])
    gaps = (80.0 - 2.25) - (xy[:, 0] + 3.75)
    assert gaps.min() > 1.0  # never hits it
    assert speed[-20:].max() == 0.0  # stopped, and held
    assert gaps[-1] == pytest.approx(2.0, abs=0.8)
    assert np.abs(xy[:, 1]).max() < 0.05  # straight on, no swerving


def test_bind_loads_every_kernel_a_step_uses() -> None:
    """numba loads (or compiles) a kernel per argument types on first call: bind makes those
    calls with the types a run gives (read-only waypoints, stacked corners), so a run's first
    frame does not pay for it inside its latency."""
    import numba

    from redrive.algorithms import VEHICLE_STATE
    from redrive.algorithms.reference import _control_kernels, _plan_kernels

    planner, controller = IdmPlanner(), PurePursuitPid()
    planner.bind({}, extras=[VEHICLE_STATE])
    controller.bind({}, extras=[VEHICLE_STATE])
    kernels = [
        f
        for module in (_plan_kernels, _control_kernels)
        for f in vars(module).values()
        if isinstance(f, numba.core.registry.CPUDispatcher)
    ]
    loaded = {f: list(f.signatures) for f in kernels}
    parked = DetectedObject(
        object_class=ObjectClass.VEHICLE,
        box=Box3D(center=np.array([30.0, 0.2, 0.8]), size=np.array([4.5, 1.8, 1.6])),
    )
    model = BicycleModel(EgoGeometry(), speed_mps=8.0)
    drive(planner, controller, model, seconds=1.0, obstacles_map=[parked])
    assert {f: list(f.signatures) for f in kernels} == loaded
