"""The world's physics step in plain Python over its objects — the reference the compiled step
(:class:`redrive.sim.stepper.FrameStepper`, the world's only shipped step) is compared with.

:func:`reference_step_to` is what ``World.step_to`` did before the kernel: one physics step at a
time, the obstacle snapshot, the pedestrians' triggers, the lane changes
(:func:`start_plan`: ``Route.project``), every agent's gap search
(:meth:`GapSearch.gaps_of`), the followers' plan and motion (:meth:`LaneFleet.finish_and_advance`),
the scripted ego's pure pursuit and IDM (:mod:`tests.sim._reference_agents`), its pedals or the
Python step of ``World.drive_ego``, and the walkers' clocks.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from redrive.sim import fleet as fl
from redrive.sim.ego import BicycleModel
from redrive.sim.world import EGO_ID, World
from tests.sim import _reference_agents as ref

__all__ = ["reference_step_to", "start_plan"]


def start_plan(fleet: fl.LaneFleet, time_s: float) -> None:
    """:meth:`ReferenceFollower.start_plan` of all the fleet's followers: the lane changes that
    start now, in Python (the follower's pose, then :meth:`Route.project` onto the target, as
    the follower does); the frame kernel's ``_start_lane_changes`` is compared with it."""
    if time_s >= fleet._next_lc:
        f, i = fleet._f, fleet._i
        poses = None
        for k in range(len(f)):
            if i[k, fl.LC_TARGET] < 0 or i[k, fl.LC_STARTED] or not time_s >= f[k, fl.LC_START]:
                continue
            if poses is None:
                poses = fleet.poses()
            x, y = float(poses[0, k]), float(poses[1, k])
            target = fleet._routes[int(i[k, fl.LC_TARGET])]
            s_new, lat = target.project([[x, y]], s_min_m=0.0, s_max_m=target.length_m)
            i[k, fl.ROUTE], f[k, fl.S] = i[k, fl.LC_TARGET], float(s_new[0])
            f[k, fl.LC_OFF0] = float(lat[0]) - float(f[k, fl.LAT])
            i[k, fl.LC_STARTED] = 1
        pending = (i[:, fl.LC_TARGET] >= 0) & (i[:, fl.LC_STARTED] == 0)
        fleet._next_lc = float(f[pending, fl.LC_START].min()) if pending.any() else math.inf
    fleet._time_s = time_s


def reference_step_to(world: World, stamp_ns: int) -> None:
    """``world.step_to(stamp_ns)``, every physics step in Python."""
    assert stamp_ns >= world._time_ns
    while world._time_ns < stamp_ns:
        _substep(world, min(world._dt_ns, stamp_ns - world._time_ns))


def _pedal_step(world: World, model: BicycleModel, dt_s: float) -> None:
    """``ActuatedEgo.apply`` of the held command of ``World.drive_ego_pedals``."""
    assert world._ego_pedals is not None
    commands, pedals = world._ego_pedals
    accel = pedals.acceleration(commands, model.speed_mps)
    model.step(
        dt_s,
        accel_mps2=accel,
        steer_rad=commands.steering_angle_rad,
        friction_circle_mps2=world._ego_friction_mps2,
    )


def _substep(w: World, dt_ns: int) -> None:
    t = w.time_s
    dt_s = dt_ns / 1e9
    ego_step = w._ego_step
    if ego_step is None and w._ego_pedals is not None:
        ego_step = lambda model, dt: _pedal_step(w, model, dt)  # noqa: E731
    scripted = ego_step is None
    fleet = w._fleet
    # every agent plans from one snapshot (taken before any moves or changes lane), their
    # gap searches in one batch; a driven ego with nobody around needs none
    obstacles = _obstacles(w) if scripted or len(fleet) else None
    front = w._driver.s_m + w.ego_geometry.front_offset_m
    for walker, s_cross, distance in w._triggers:
        if s_cross - front <= distance:
            walker.start(t)
    start_plan(fleet, t)
    search = w._gaps
    ego_query = None
    if scripted:
        g, driver = w.ego_geometry, w._driver
        steer = ref.steer(driver, w._ego)
        off, n = search.route_row(driver.route)
        s_front = driver.s_m + g.front_offset_m
        ego_query = (
            off,
            n,
            driver.ego_id,
            driver.s_m + g.center_offset_m,
            s_front,
            s_front + search.horizon_m,
            g.width_m,
        )
    else:
        _track_route(w)
    if obstacles is not None:
        q_int, q_float = fleet.queries(search.horizon_m, ego_query)
        gaps, speeds = search.gaps_of(q_int, q_float, *obstacles)
        # the followers plan (stop lines, IDM, braking) and move; the ego's plan does not
        # read them
        fleet.finish_and_advance(t, dt_s, gap_m=gaps, leader_speed_mps=speeds)
    if ego_step is None:
        accel = ref.accelerate(
            w._driver,
            w._ego,
            t,
            w.lights,
            gap_m=float(gaps[-1]),
            leader_speed_mps=float(speeds[-1]),
        )
        w._ego.step(dt_s, accel_mps2=accel, steer_rad=steer)
    else:
        ego_step(w._ego, dt_s)
    w._time_ns += dt_ns
    t_new = w.time_s
    for walker in w._walkers:
        walker.set_time(t_new)
    w._record_pose()


def _track_route(w: World) -> None:
    route = w._driver.route
    w._driver.s_m, _ = route.project_point(
        w._ego.x_m,
        w._ego.y_m,
        s_min_m=w._driver.s_m - 2.0,
        s_max_m=w._driver.s_m + 10.0,
    )


def _obstacles(w: World) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """The snapshot every agent plans from: ids (M,) and (6, M) centre x, y, length, width,
    velocity x, y (``GapSearch.gaps_of``'s obstacles) — the ego, the lane followers, the
    pedestrians, the parked vehicles."""
    g, ego = w.ego_geometry, w._ego
    c, s = math.cos(ego.yaw_rad), math.sin(ego.yaw_rad)
    ids = [EGO_ID]
    rows = [
        (
            ego.x_m + g.center_offset_m * c,
            ego.y_m + g.center_offset_m * s,
            g.length_m,
            g.width_m,
            ego.speed_mps * c,
            ego.speed_mps * s,
        )
    ]
    for walker in w._walkers:
        x, y, _ = walker.pose()
        ids.append(walker.agent_id)
        rows.append((x, y, walker.size_lwh_m[0], walker.size_lwh_m[1], *walker.velocity()))
    for parked in w._parked:
        ids.append(parked.agent_id)
        rows.append((*parked.center_xy, *parked.size_lwh_m[:2], 0.0, 0.0))
    return w._fleet.snapshot(np.array(ids, dtype=np.int64), np.array(rows, dtype=np.float64))
