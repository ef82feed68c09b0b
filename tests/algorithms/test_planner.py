"""IdmPlanner: free road, stopped and moving leaders, the corridor, routes and lane arcs."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from redrive.algorithms import Role, StageOutputs
from redrive.algorithms.reference.planner import IdmPlanner, Polyline
from redrive.errors import AlgorithmError, ConfigError
from redrive.types import Box3D, DetectedObject, Frame, ObjectClass, PlannedPath, VehicleState
from tests._objects import one_batch

STAMP_NS = 1_700_000_000_000_000_000
FRONT_M = 4.7 - 0.95  # rear axle to front bumper with the default ego size
F64 = npt.NDArray[np.float64]


def make_frame(
    speed_mps: float,
    *,
    x_m: float = 0.0,
    y_m: float = 0.0,
    heading_rad: float = 0.0,
    yaw_rate_rad_s: float = 0.0,
) -> Frame:
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    state = VehicleState(
        stamp_ns=STAMP_NS,
        frame_id="map",
        position=np.array([x_m, y_m, 0.0]),
        velocity=np.array([speed_mps * c, speed_mps * s, 0.0]),
        heading_rad=heading_rad,
        yaw_rate_rad_s=yaw_rate_rad_s,
    )
    return Frame(stamp_ns=STAMP_NS, index=3, vehicle_state=state)


def car(
    x_m: float, y_m: float = 0.0, *, speed_mps: float = 0.0, yaw_rad: float = 0.0
) -> DetectedObject:
    """A 4.5 × 1.8 m car with its centre at (x, y) in base_link, moving along its heading."""
    return DetectedObject(
        object_id=7,
        object_class=ObjectClass.VEHICLE,
        box=Box3D(
            center=np.array([x_m, y_m, 0.8]), size=np.array([4.5, 1.8, 1.6]), yaw_rad=yaw_rad
        ),
        velocity=np.array([speed_mps * math.cos(yaw_rad), speed_mps * math.sin(yaw_rad), 0.0]),
    )


def perceived(*objects: DetectedObject) -> StageOutputs:
    return StageOutputs({"detector": tuple(objects)}, {"detector": Role.PERCEPTION})


def speeds(path: PlannedPath) -> F64:
    wp = path.waypoints
    return np.asarray(np.linalg.norm(np.diff(wp[:, :3], axis=0), axis=1) / np.diff(wp[:, 3]))


def test_output_shape_times_and_frame() -> None:
    planner = IdmPlanner()
    path = planner.step(make_frame(5.0), StageOutputs())
    wp = path.waypoints
    assert path.stamp_ns == STAMP_NS
    assert path.frame_id == "base_link"
    assert wp.shape == (61, 4)
    assert wp[0, 3] == 0.0
    assert wp[-1, 3] == pytest.approx(6.0)
    assert np.all(np.diff(wp[:, 3]) > 0.0)
    np.testing.assert_allclose(wp[0, :3], 0.0, atol=1e-12)  # starts at the rear axle


def test_free_road_accelerates_towards_v0_and_never_exceeds_it() -> None:
    planner = IdmPlanner()
    path = planner.step(make_frame(0.0), StageOutputs())
    v = speeds(path)
    assert np.all(np.diff(v) > -1e-9)  # accelerating all along
    assert v[-1] > 5.0
    assert v.max() <= 13.9 + 1e-9
    np.testing.assert_allclose(path.waypoints[:, 1], 0.0, atol=1e-12)  # straight ahead
    cruising = speeds(planner.step(make_frame(13.9), StageOutputs()))
    assert cruising.max() <= 13.9 + 1e-9
    assert cruising.min() > 13.9 - 0.05


def test_faster_than_v0_slows_down() -> None:
    v = speeds(IdmPlanner().step(make_frame(20.0), StageOutputs()))
    assert np.all(np.diff(v) < 0.0)
    assert v[-1] < 20.0


def test_stopped_obstacle_ahead_gives_a_stop_at_s0() -> None:
    planner = IdmPlanner()
    planner.configure({"horizon_s": 15.0})
    rear_m = 30.0
    obstacle = car(rear_m + 2.25)
    path = planner.step(make_frame(10.0), perceived(obstacle))
    x = path.waypoints[:, 0]
    gaps = rear_m - (x + FRONT_M)
    assert gaps.min() >= 2.0 - 1e-9  # never closer than s0 ...
    assert gaps[-1] == pytest.approx(2.0, abs=0.05)  # ... and stops there
    assert np.all(np.diff(x) >= 0.0)  # never reverses
    assert speeds(path)[-10:].max() < 0.05
    # within the default 6 s it is well on its way to the stop
    short = IdmPlanner().step(make_frame(10.0), perceived(obstacle))
    assert speeds(short)[-1] < 1.5
    assert rear_m - (short.waypoints[-1, 0] + FRONT_M) >= 2.0


def test_obstacle_already_within_s0_keeps_the_ego_in_place() -> None:
    path = IdmPlanner().step(make_frame(0.0), perceived(car(FRONT_M + 1.0 + 2.25)))
    np.testing.assert_allclose(path.waypoints[:, :3], 0.0, atol=1e-12)


def test_obstacle_beside_the_corridor_is_ignored_but_one_reaching_into_it_is_not() -> None:
    free = IdmPlanner().step(make_frame(10.0), StageOutputs())
    beside = IdmPlanner().step(make_frame(10.0), perceived(car(30.0, 3.5), car(20.0, -3.5)))
    np.testing.assert_array_equal(beside.waypoints, free.waypoints)
    # its near edge at 2.0 - 0.9 = 1.1 m reaches into the ±1.5 m corridor
    reaching = IdmPlanner().step(make_frame(10.0), perceived(car(30.0, 2.0)))
    assert reaching.waypoints[-1, 0] < free.waypoints[-1, 0] - 20.0
    # behind the front bumper: ignored
    behind = IdmPlanner().step(make_frame(10.0), perceived(car(-6.0)))
    np.testing.assert_array_equal(behind.waypoints, free.waypoints)


def test_moving_leader_at_equal_speed_at_the_equilibrium_gap_keeps_the_speed() -> None:
    v = 10.0
    gap_m = (2.0 + v * 1.5) / math.sqrt(1.0 - (v / 13.9) ** 4)  # IDM equilibrium
    leader = car(FRONT_M + gap_m + 2.25, speed_mps=v)
    path = IdmPlanner().step(make_frame(v), perceived(leader))
    plan = speeds(path)
    assert np.abs(plan - v).max() < 0.05
    end_gap = leader.box.center[0] - 2.25 + 6.0 * v - (path.waypoints[-1, 0] + FRONT_M)
    assert end_gap == pytest.approx(gap_m, abs=0.3)
    # closer than equilibrium → slower; a faster leader far ahead barely matters
    closer = speeds(IdmPlanner().step(make_frame(v), perceived(car(FRONT_M + 12.0, speed_mps=v))))
    assert closer.min() < v - 1.0


def test_leader_velocity_is_projected_on_the_path() -> None:
    # a car crossing the lane (moving sideways) is a stopped obstacle for the plan
    crossing = car(25.0, speed_mps=5.0, yaw_rad=math.pi / 2.0)
    stopped = car(25.0, yaw_rad=math.pi / 2.0)
    a = IdmPlanner().step(make_frame(8.0), perceived(crossing))
    b = IdmPlanner().step(make_frame(8.0), perceived(stopped))
    np.testing.assert_allclose(a.waypoints, b.waypoints)


def test_curved_route_gives_a_curved_path_on_the_route() -> None:
    radius_m = 30.0
    angles = np.linspace(0.0, math.pi / 2.0, 200)
    route = np.column_stack(
        [100.0 + radius_m * np.sin(angles), 50.0 + radius_m * (1.0 - np.cos(angles))]
    )
    planner = IdmPlanner()
    planner.configure({"route": route.tolist()})
    # ego on the route at its start, 0.5 m to the right of it, heading along it
    path = planner.step(make_frame(10.0, x_m=100.0, y_m=49.5), StageOutputs())
    wp = path.waypoints
    assert wp[0, 1] == pytest.approx(0.5, abs=1e-6)  # the path starts at the route
    assert wp[-1, 1] > 10.0  # curves left
    # every waypoint lies on the circle (the route is a 200-point polyline of it)
    world = wp[:, :2] + np.array([100.0, 49.5])
    r = np.hypot(world[:, 0] - 100.0, world[:, 1] - 80.0)
    np.testing.assert_allclose(r, radius_m, atol=0.02)


def test_route_is_read_in_the_ego_state_frame_with_heading() -> None:
    # a straight route going north; ego on it heading north: the path is straight ahead
    planner = IdmPlanner()
    planner.configure({"route": [[5.0, -10.0], [5.0, 200.0]]})
    frame = make_frame(10.0, x_m=6.0, y_m=0.0, heading_rad=math.pi / 2.0)
    wp = planner.step(frame, StageOutputs()).waypoints
    np.testing.assert_allclose(wp[:, 1], 1.0, atol=1e-9)  # the route is 1 m to the left
    assert wp[-1, 0] > 50.0


def test_route_end_is_a_stop() -> None:
    planner = IdmPlanner()
    planner.configure({"route": [[0.0, 0.0], [40.0, 0.0]], "horizon_s": 20.0})
    wp = planner.step(make_frame(8.0), StageOutputs()).waypoints
    assert wp[-1, 0] + FRONT_M == pytest.approx(40.0 - 2.0, abs=0.05)


def test_route_too_far_away_is_an_error() -> None:
    planner = IdmPlanner()
    planner.configure({"route": [[0.0, 100.0], [50.0, 100.0]]})
    with pytest.raises(AlgorithmError, match="from the route"):
        planner.step(make_frame(5.0), StageOutputs())


def test_route_progress_is_kept_on_a_route_that_passes_twice() -> None:
    # out and back on parallel lanes 3 m apart: after driving back the ego must not jump lanes
    route = [[0.0, 0.0], [100.0, 0.0], [100.0, 3.0], [0.0, 3.0]]
    planner = IdmPlanner()
    planner.configure({"route": route})
    first = planner.step(make_frame(5.0, x_m=10.0), StageOutputs()).waypoints
    assert first[-1, 1] == pytest.approx(0.0)
    for x in np.arange(10.0, 101.0, 5.0):
        planner.step(make_frame(5.0, x_m=float(x)), StageOutputs())
    back = planner.step(
        make_frame(5.0, x_m=100.0, y_m=3.0, heading_rad=math.pi), StageOutputs()
    ).waypoints
    assert back[-1, 0] > 20.0  # drives on along the way back (west = +x of base_link)
    planner.reset()
    fresh = planner.step(make_frame(5.0, x_m=10.0), StageOutputs()).waypoints
    np.testing.assert_allclose(fresh, first)


def test_yaw_rate_gives_a_constant_curvature_arc() -> None:
    v, yaw_rate = 10.0, 0.2  # κ = 0.02, R = 50 m, to the left
    wp = IdmPlanner().step(make_frame(v, yaw_rate_rad_s=yaw_rate), StageOutputs()).waypoints
    np.testing.assert_allclose(np.hypot(wp[:, 0], wp[:, 1] - 50.0), 50.0, atol=1e-3)
    assert wp[-1, 1] > 5.0
    right = IdmPlanner().step(make_frame(v, yaw_rate_rad_s=-yaw_rate), StageOutputs()).waypoints
    np.testing.assert_allclose(right[:, 1], -wp[:, 1], atol=1e-9)
    # slow: straight; huge yaw rate: clamped to the curvature limit (R = 5 m)
    slow = IdmPlanner().step(make_frame(0.5, yaw_rate_rad_s=0.5), StageOutputs()).waypoints
    np.testing.assert_allclose(slow[:, 1], 0.0, atol=1e-12)
    tight = IdmPlanner().step(make_frame(2.0, yaw_rate_rad_s=2.0), StageOutputs()).waypoints
    travelled = np.concatenate(
        [[0.0], np.cumsum(np.linalg.norm(np.diff(tight[:, :2], axis=0), axis=1))]
    )
    first_half_turn = travelled <= 5.0 * math.pi
    assert first_half_turn.sum() > 10
    circle = np.hypot(tight[first_half_turn, 0], tight[first_half_turn, 1] - 5.0)
    np.testing.assert_allclose(circle, 5.0, atol=1e-3)


def test_obstacle_on_the_arc_is_found_and_one_on_the_straight_line_is_not() -> None:
    v, yaw_rate = 10.0, 0.2  # R = 50 m left arc
    phi = 40.0 / 50.0  # 40 m along the arc
    on_arc = car(50.0 * math.sin(phi), 50.0 * (1.0 - math.cos(phi)), yaw_rad=phi)
    on_line = car(40.0, 0.0)  # 15 m right of the arc there
    free = IdmPlanner().step(make_frame(v, yaw_rate_rad_s=yaw_rate), StageOutputs()).waypoints
    a = IdmPlanner().step(make_frame(v, yaw_rate_rad_s=yaw_rate), perceived(on_arc)).waypoints
    b = IdmPlanner().step(make_frame(v, yaw_rate_rad_s=yaw_rate), perceived(on_line)).waypoints
    np.testing.assert_array_equal(b, free)
    travelled = np.linalg.norm(np.diff(a[:, :2], axis=0), axis=1).sum()
    assert travelled <= 40.0 - 2.25 - FRONT_M - 2.0 + 1e-6


def test_failed_perception_refuses_to_plan_and_no_perception_plans_empty_road() -> None:
    planner = IdmPlanner()
    failed = StageOutputs({}, {"detector": Role.PERCEPTION})
    with pytest.raises(AlgorithmError, match="refusing to plan blind"):
        planner.step(make_frame(5.0), failed)
    assert planner.step(make_frame(5.0), StageOutputs()).waypoints.shape == (61, 4)
    result = planner.run_step(make_frame(5.0), failed)
    assert result.error is not None
    assert result.error.type == "AlgorithmError"


def test_named_perception_and_missing_state() -> None:
    planner = IdmPlanner()
    planner.configure({"perception": "lidar_det"})
    with pytest.raises(AlgorithmError, match="lidar_det"):
        planner.step(make_frame(5.0), StageOutputs())
    with pytest.raises(AlgorithmError, match="no vehicle state"):
        planner.step(Frame(stamp_ns=STAMP_NS, index=0), StageOutputs())


@pytest.mark.parametrize(
    "config",
    [
        {"route": [[0.0, 0.0]]},
        {"route": [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]]},
        {"route": "north"},
        {"v0_mps": 0.0},
        {"dt_s": 10.0},
        {"T_s": "slow"},
        {"horizon": 3.0},
    ],
)
def test_bad_config_is_refused(config: dict[str, object]) -> None:
    with pytest.raises(ConfigError):
        IdmPlanner().configure(config)


def test_polyline_projection() -> None:
    line = Polyline([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    s, lat, dist = line.project([[5.0, 1.0], [11.0, 5.0], [-3.0, 0.0]])
    np.testing.assert_allclose(s, [5.0, 15.0, 0.0])
    np.testing.assert_allclose(lat, [1.0, -1.0, 0.0])
    np.testing.assert_allclose(dist, [1.0, 1.0, 3.0])
    np.testing.assert_allclose(line.points_at([25.0, -1.0]), [[10.0, 15.0], [-1.0, 0.0]])


@pytest.mark.parametrize(
    "values",
    [
        [3.0],
        [2.0, 1.0, 1.0],
        [1.0, math.inf, -math.inf],
        [0.0, -0.0],
        [4.0, math.nan, 1.0, math.nan],
    ],
)
def test_first_min_chooses_as_numpy_argmin(values: list[float]) -> None:
    from redrive.algorithms.reference._plan_kernels import _first_min

    assert _first_min(np.array(values), len(values)) == int(np.argmin(np.array(values)))


def _first_min_py(values: list[float]) -> int:
    best = 0
    for i, value in enumerate(values):
        if math.isnan(value):
            return i
        if value < values[best]:
            best = i
    return best


def _profile_py(
    p: IdmPlanner, speed_mps: float, lead_s: list[float], lead_v: list[float]
) -> list[float]:
    """The planner's IDM integration as the Python loop it was before the kernel."""

    def idm(v: float, gap_m: float, v_lead: float) -> float:
        free = 1.0 - (max(v, 0.0) / p.v0_mps) ** p.delta
        interaction = 0.0
        if math.isfinite(gap_m):
            s_star = p.s0_m + max(
                0.0, v * p.headway_s + v * (v - v_lead) / (2.0 * math.sqrt(p.a_mps2 * p.b_mps2))
            )
            interaction = (s_star / max(gap_m, 1e-3)) ** 2
        return min(max(float(p.a_mps2 * (free - interaction)), -p.max_decel_mps2), p.a_mps2)

    n, dt, front = max(1, round(p.horizon_s / p.dt_s)), p.dt_s, p.front_offset_m
    out, s, v, ids = [0.0], 0.0, max(speed_mps, 0.0), range(len(lead_s))
    for k in range(n):
        t = k * dt
        gap, v_lead, j = math.inf, 0.0, -1
        if lead_s:
            gaps = [lead_s[i] + lead_v[i] * t - (s + front) for i in ids]
            j = _first_min_py(gaps)
            gap, v_lead = gaps[j], lead_v[j]
        accel = idm(v, gap, v_lead)
        if v + accel * dt < 0.0:
            s_new, v_new = s - v * v / (2.0 * accel), 0.0
        else:
            s_new, v_new = s + v * dt + 0.5 * accel * dt * dt, v + accel * dt
        if j >= 0:
            limits = [lead_s[i] + lead_v[i] * (t + dt) - front - p.s0_m for i in ids]
            jj = _first_min_py(limits)
            limit = max(limits[jj], s)
            if s_new > limit:
                s_new, v_new = limit, min(v_new, lead_v[jj])
        s, v = s_new, v_new
        out.append(s)
    return out


def test_compiled_profile_is_the_python_loop_bit_for_bit() -> None:
    """The kernel gives the plans the per-step Python loop gave, to the last bit: free road,
    leaders far and close (inside s0), stopped and moving, ties, several configs."""
    rng = np.random.default_rng(15)
    configs = [{}, {"delta": 3.0, "T_s": 0.0, "s0_m": 0.0}, {"a_mps2": 3.0, "max_decel_mps2": 2.5}]
    for config in configs:
        planner = IdmPlanner()
        planner.setup({**IdmPlanner.defaults, **config})
        for _ in range(150):
            m = int(rng.integers(0, 5))
            lead_s = rng.uniform(-2.0, 80.0, m)
            lead_v = np.where(rng.random(m) < 0.4, 0.0, rng.uniform(0.0, 15.0, m))
            if m > 1 and rng.random() < 0.2:
                lead_s[1], lead_v[1] = lead_s[0], lead_v[0]
            speed = float(rng.choice([0.0, -0.0, rng.uniform(0.0, 20.0)]))
            _, s = planner._profile(speed, lead_s, lead_v)
            want = _profile_py(planner, speed, lead_s.tolist(), lead_v.tolist())
            assert s.tolist() == want


def test_objects_sharing_columns_give_the_path_of_constructed_objects() -> None:
    """The leaders read the objects' shared columns (DetectedObject.many) or gather them from
    the objects: the same path, bit for bit, in any order or subset of a batch."""
    objects = [car(25.0, 0.4, speed_mps=3.0, yaw_rad=0.1), car(14.0, -3.0), car(40.0, 1.0)]
    batch = one_batch(objects)
    frame = make_frame(8.0, yaw_rate_rad_s=0.05)
    for order in ([0, 1, 2], [2, 0], [1]):
        want = IdmPlanner().step(frame, perceived(*(objects[i] for i in order)))
        got = IdmPlanner().step(frame, perceived(*(batch[i] for i in order)))
        assert got.waypoints.tobytes() == want.waypoints.tobytes()
