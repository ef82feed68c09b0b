"""A frame's physics steps in one compiled call (FrameStepper, the world's only step) give what
the world's Python step (tests/sim/_reference_step.py) gives, bit for bit: the scripted ego (pure
pursuit, stop lines, IDM), a pedal-driven ego, an ego moved by a Python step, lane changes,
pedestrians started by the ego, followers leaving."""

from __future__ import annotations

import math

import numpy as np
import pytest

from redrive.errors import SimulationError
from redrive.sim import kernels
from redrive.sim.ego import ActuatedEgo, PedalModel
from redrive.sim.scenario import load_scenario
from redrive.sim.world import World
from redrive.types import ControlCommands
from tests.sim._reference_step import reference_step_to


def _state(w: World) -> tuple[object, ...]:
    o, m = w.ground_truth_objects(), w.ego_model
    walkers = tuple((a.start_time_s, a._time_s) for a in w._walkers)
    return (
        w.time_ns,
        o.object_id.tobytes(),
        o.center_m.tobytes(),
        o.yaw_rad.tobytes(),
        o.velocity_mps.tobytes(),
        (m.x_m, m.y_m, m.yaw_rad, m.speed_mps, m.steer_rad, m.accel_mps2),
        w._driver.s_m,
        tuple(sorted(w._driver._committed)),
        walkers,
        tuple(w._history),
        w._fleet._f.tobytes(),
        w._fleet._committed.tobytes(),
    )


def _command(k: int) -> ControlCommands:
    return ControlCommands(
        throttle=0.5 if k % 20 < 12 else 0.0,
        brake=0.0 if k % 20 < 15 else 0.4,
        steering_angle_rad=0.04 * ((k % 13) - 6) / 6,
    )


@pytest.mark.parametrize(
    ("name", "driven", "start_s", "end_s"),
    [
        ("cut_in", "", 0.0, 8.0),  # a lane change starts at 3 s
        ("cut_in", "pedals", 0.0, 8.0),  # the followers plan around the driven ego
        ("cut_in", "python", 0.0, 8.0),  # ... moved by a Python step (World.drive_ego)
        ("pedestrian_from_occlusion", "", 0.0, 8.0),  # the ego's progress starts a walker
        ("red_light", "", 0.0, 8.0),  # stop lines, yellow commitments
        ("lead_vehicle_hard_brake", "pedals", 0.0, 6.0),
        ("highway", "", 21.5, 24.5),  # two followers leave at the end of their route
    ],
)
def test_compiled_frames_equal_python_steps(
    name: str, driven: str, start_s: float, end_s: float
) -> None:
    sc = load_scenario(name)
    compiled, python = World(sc), World(sc)
    for w in (compiled, python):  # to the start, both compiled
        w.step(start_s)
    assert _state(compiled) == _state(python)
    n_followers = len(compiled._fleet)
    end = sc.start_stamp_ns + round(end_s * 1e9)
    k = 0
    while compiled.time_ns < end:
        if driven == "pedals":
            for w in (compiled, python):
                w.drive_ego_pedals(_command(k), PedalModel())
        elif driven == "python":
            cmd = _command(k)
            for w in (compiled, python):
                ego = ActuatedEgo(w.ego_model, pedals=PedalModel())
                w.drive_ego(lambda _model, dt_s, ego=ego, cmd=cmd: ego.apply(cmd, dt_s))
        # frames of 0.1 s and, now and then, of a step and a part (the last one shorter)
        dt_ns = 100_000_000 if k % 5 else 123_000_000
        compiled.step_to(compiled.time_ns + dt_ns)
        reference_step_to(python, python.time_ns + dt_ns)  # every physics step in Python
        assert _state(compiled) == _state(python), f"{name}: frame {k} differs"
        k += 1
    if name == "cut_in":  # the lane change happened and the followers' order held
        assert compiled._fleet._i[:, 3].any()
    if name == "pedestrian_from_occlusion" and not driven:
        assert compiled._walkers[0].start_time_s is not None
    if name == "highway":
        assert len(compiled._fleet) == n_followers - 2


def test_a_road_with_a_zero_length_segment_is_refused() -> None:
    """The compiled step needs every route segment of positive length (Route.pose_at divides
    by it): a world on such a road is refused when it is built, saying so."""
    sc = load_scenario("urban")
    world = World(sc)
    route = next(iter(world.network.routes.values()))
    search = world._gaps
    off, _ = search.route_row(route)
    search.net[5, off] = 0.0  # as if the route's first two samples coincided
    from redrive.sim.stepper import FrameStepper

    with pytest.raises(SimulationError, match="zero length"):
        FrameStepper(world)


def test_pedal_driven_ego_equals_the_drive_ego_callable() -> None:
    """drive_ego_pedals moves the ego as ActuatedEgo.apply under the same command does."""
    sc = load_scenario("urban")
    a, b = World(sc), World(sc)
    ego = ActuatedEgo(b.ego_model, pedals=PedalModel(max_brake_mps2=6.0))
    for k in range(20):
        cmd = _command(k)
        a.drive_ego_pedals(cmd, PedalModel(max_brake_mps2=6.0))
        b.drive_ego(lambda _model, dt_s, cmd=cmd: ego.apply(cmd, dt_s))
        a.step(0.1)
        b.step(0.1)
        assert _state(a) == _state(b)


def test_hypot_is_pythons() -> None:
    """libm's hypot (numba's math.hypot) differs from CPython's in the last bit now and then;
    the kernels' hypot does not."""
    rng = np.random.default_rng(7)
    pairs = rng.normal(0.0, 1.0, (20_000, 2)) * rng.choice([1e-3, 1.0, 40.0, 1e5], (20_000, 1))
    pairs[:100, 1] = 0.0
    got = [kernels.hypot(x, y) for x, y in pairs.tolist()]
    assert got == [math.hypot(x, y) for x, y in pairs.tolist()]
    assert kernels.hypot(0.0, 0.0) == 0.0
    assert kernels.hypot(math.inf, math.nan) == math.inf
    assert math.isnan(kernels.hypot(1.0, math.nan))
