"""The world's physics step, compiled: a frame's steps as one call, Python only at the ends.

A 100-Hz physics step is the obstacle snapshot, the pedestrians' triggers, the lane changes that
start, the lane followers' and the scripted ego's gap search, stop lines and IDM, the ego's pure
pursuit (or its pedals under a held command), the bicycle model and the walkers' clocks.
:class:`FrameStepper` is the world's only way to step: it copies the state that lives in Python
objects (the ego's :class:`~redrive.sim.ego.BicycleModel` and driver, the walkers) into arrays,
runs every physics step up to a stamp in :func:`_frame` and copies it back; the lane followers'
arrays (:class:`~redrive.sim.fleet.LaneFleet`) are stepped in place.

Every value is the one the world's Python step gives (the objects' methods: ``LaneFleet``'s,
the scripted driver's, ``Route.project``; that step stays in ``tests/sim/_reference_step.py`` as the
reference), bit for bit: the same float64 operations in the same order (no ``fastmath``; powers
through ``pow`` with a run-time exponent; ``math.hypot`` as CPython computes it,
:func:`redrive.sim.kernels.hypot`).  Python does two things between calls: it removes a follower
that left its route (:func:`_frame` stops after that step), and it moves an ego that
:meth:`World.drive_ego` hands to a Python step (one physics step a call).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numba
import numpy as np
import numpy.typing as npt

from redrive.errors import SimulationError
from redrive.motion.idm import GAP_MIN_M, V0_MIN_MPS, idm_kernel
from redrive.sim import fleet as fl
from redrive.sim import kernels
from redrive.sim.gaps import _gap_kernel  # compiled into _frame, with gaps.BLOCK (8 since h-obj7)

# numba keys _frame's cache by this file alone: an edit of gaps.py's kernel or BLOCK (or of
# fleet.py's, kernels.py's or motion/idm.py's kernels) must change this file too (or run
# `make clean-kernels`), else a cached _frame keeps the old code

if TYPE_CHECKING:
    from redrive.sim.ego import EgoGeometry, PedalModel
    from redrive.sim.world import World

__all__ = ["FrameStepper", "ego_parameters", "pedal_steps"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]

# the ego's state columns (FrameStepper._ego) and its parameters (FrameStepper._ego_p)
(EX, EY, EYAW, ESPEED, ESTEER, EACCEL, ES) = range(7)
(WB, CENTER, FRONT, ELEN, EWID, MAX_STEER, STEER_RATE, MAX_ACC, MAX_DEC, JERK) = range(10)
(LOOK_T, LOOK_MIN, LOOK_MAX, V0, HEADWAY, MIN_GAP, A_MAX, B_COMF, DELTA, IDM_DEC) = range(10, 20)
(THROTTLE, BRAKE, STEER_CMD, P_ACC, P_BRK, ROLL, DRAG, HORIZON, MARGIN) = range(20, 29)
FRICTION = 29  # the commanded ego's friction circle μ·g (m/s²; World.drive_ego_pedals)
_NP = 30
# a walker's columns: start x, y, end x, y, speed, start time (nan: not started), distance,
# yaw, clock, length, width
(WSX, WSY, WEX, WEY, WSPD, WSTART, WDIST, WYAW, WTIME, WLEN, WWID) = range(11)
_NW = 11


class FrameStepper:
    """The compiled physics steps of one world (built with it; see the module text)."""

    def __init__(self, world: World) -> None:
        w = world
        search, driver, g = w._gaps, w._driver, w.ego_geometry
        seg_len = search.net[5][_segment_starts(search.route_table)]
        if not np.all(seg_len * seg_len != 0.0):
            msg = (
                "World: a route of the scenario's road has two samples at one arclength (a "
                "segment of zero length); give every lane a positive length"
            )
            raise SimulationError(msg)
        self._route = search.routes.index(driver.route)
        idm = driver.idm
        p = ego_parameters(g, None, 0.0)  # the pedals' columns set by run when they drive
        p[LOOK_T:THROTTLE] = (
            driver.lookahead_time_s,
            driver.min_lookahead_m,
            driver.max_lookahead_m,
            idm.desired_speed_mps,
            idm.time_headway_s,
            idm.min_gap_m,
            idm.max_accel_mps2,
            idm.comfort_decel_mps2,
            idm.delta,
            idm.max_decel_mps2,
        )
        p[HORIZON], p[MARGIN] = search.horizon_m, search.margin_m
        self._p = p
        self._ego = np.zeros(7)
        self._clock = np.zeros(6, dtype=np.int64)
        self._hist_t = np.zeros(0, dtype=np.int64)
        self._hist = np.zeros((0, 3))
        self._n_ego_stops = len(driver.route.stop_lines)
        self._ego_committed = np.zeros(max(self._n_ego_stops, 1), dtype=bool)
        parked = w._parked
        self._parked_ids = np.array([a.agent_id for a in parked], dtype=np.int64)
        self._parked = np.array(
            [(*a.center_xy, *a.size_lwh_m[:2], 0.0, 0.0) for a in parked], dtype=np.float64
        ).reshape(-1, 6)
        # the walkers and triggers are fixed for the stepper's life (drop_agents builds a new
        # one): their constant columns once, their clocks copied in and out each call
        walkers = w._walkers
        self._walk = np.zeros((len(walkers), _NW))
        for k, a in enumerate(walkers):
            self._walk[k] = (
                *a.start_xy,
                *a.end_xy,
                a.speed_mps,
                math.nan,
                a.distance_m,
                a.yaw_rad,
                0.0,
                *a.size_lwh_m[:2],
            )
        self._walk_ids = np.array([a.agent_id for a in walkers], dtype=np.int64)
        self._trig = np.array([(s, d) for _, s, d in w._triggers], dtype=np.float64).reshape(-1, 2)
        self._trig_walker = np.array(
            [walkers.index(a) for a, _, _ in w._triggers], dtype=np.int64
        ).reshape(-1)

    def run(self, world: World, stamp_ns: int) -> None:
        """Step ``world`` towards ``stamp_ns`` in one compiled call — the scripted driver, the
        held command of :meth:`World.drive_ego_pedals`, or (one step a call) the ego moved by
        the step :meth:`World.drive_ego` gave; it stops early after a step in which a follower
        left its route (removed here)."""
        w, fleet, model, driver = world, world._fleet, world._ego, world._driver
        e, p = self._ego, self._p
        e[:] = (
            model.x_m,
            model.y_m,
            model.yaw_rad,
            model.speed_mps,
            model.steer_rad,
            model.accel_mps2,
            driver.s_m,
        )
        ego_step = w._ego_step
        mode = 0  # the scripted driver
        if ego_step is not None:
            mode = 2
        elif w._ego_pedals is not None:
            mode = 1
            cmd, pm = w._ego_pedals
            p[THROTTLE:HORIZON] = (
                cmd.throttle,
                cmd.brake,
                cmd.steering_angle_rad,
                pm.max_accel_mps2,
                pm.max_brake_mps2,
                pm.rolling_resistance_mps2,
                pm.drag_coefficient_1pm,
            )
            p[FRICTION] = w._ego_friction_mps2
        committed = self._ego_committed
        if self._n_ego_stops:
            committed[:] = False
            for index in driver._committed:
                committed[index] = True
        walkers, walk = w._walkers, self._walk
        for k, a in enumerate(walkers):
            walk[k, WSTART] = math.nan if a.start_time_s is None else a.start_time_s
            walk[k, WTIME] = a._time_s
        dt_ns = w._dt_ns
        max_steps = -(-(stamp_ns - w._time_ns) // dt_ns)
        if len(self._hist_t) < max_steps:
            self._hist_t = np.zeros(max_steps, dtype=np.int64)
            self._hist = np.zeros((max_steps, 3))
        clock = self._clock
        clock[:] = (w._time_ns, w._start_ns, dt_ns, stamp_ns, mode, 0)
        search = w._gaps
        done, fleet_t, next_lc, left = _frame(
            clock,
            fleet._time_s,
            fleet._next_lc,
            fleet._f,
            fleet._i,
            fleet._committed,
            fleet._has_brake,
            fleet._stop_s,
            fleet._stop_light,
            fleet._n_stops,
            fleet._light_group,
            fleet._timing,
            fleet._route_len,
            1.0 if w.lights.signals else 0.0,
            fl._POWERS,
            search.net,
            search.blocks,
            search.route_table,
            e,
            p,
            self._route,
            self._n_ego_stops,
            committed,
            walk,
            self._walk_ids,
            self._trig,
            self._trig_walker,
            self._parked_ids,
            self._parked,
            self._hist_t,
            self._hist,
        )
        # copy back: the ego, its driver, the walkers, the fleet's clock, the pose history
        model.x_m, model.y_m, model.yaw_rad = float(e[EX]), float(e[EY]), float(e[EYAW])
        model.speed_mps, model.steer_rad = float(e[ESPEED]), float(e[ESTEER])
        model.accel_mps2, driver.s_m = float(e[EACCEL]), float(e[ES])
        if self._n_ego_stops:
            for index, flag in enumerate(committed[: self._n_ego_stops].tolist()):
                if flag:
                    driver._committed.add(index)
        fleet._time_s, fleet._next_lc = fleet_t, next_lc
        if ego_step is not None:  # the step's ego motion, after the others planned and moved
            ego_step(model, (int(clock[0]) - w._time_ns) / 1e9)
            self._hist[0] = (model.x_m, model.y_m, model.yaw_rad)
        for k, a in enumerate(walkers):
            if a.start_time_s is None and not math.isnan(walk[k, WSTART]):
                a.start_time_s = float(walk[k, WSTART])
            a._time_s = float(walk[k, WTIME])
        w._time_ns = int(clock[0])
        # (t_ns, x, y, yaw) a step, as World._record_pose appends them
        xs, ys, yaws = self._hist[:done].T.tolist()
        w._history.extend(zip(self._hist_t[:done].tolist(), xs, ys, yaws, strict=True))
        w._trim_history()
        if left:
            fleet._keep(fleet._i[:, fl.ACTIVE] == 1)


def _segment_starts(table: I64) -> B:
    """Every sample of ``GapSearch.net`` that starts a segment (not a route's last sample)."""
    n = int(table[0, -1] + table[1, -1]) if table.shape[1] else 0
    mask = np.ones(n, dtype=bool)
    mask[(table[0] + table[1] - 1).tolist()] = False
    return mask


@numba.njit(cache=True, nogil=True)
def _frame(  # noqa: PLR0917 (the world's columns; numba has no keyword-only parameters)
    clock: I64,
    fleet_t: float,
    next_lc: float,
    f: F64,
    i: I64,
    committed: B,
    has_brake: B,
    stop_s: F64,
    stop_light: I64,
    n_stops: I64,
    light_group: I64,
    timing: F64,
    route_len: F64,
    any_lights: float,
    powers: F64,
    net: F64,
    blocks: F64,
    table: I64,
    e: F64,
    p: F64,
    ego_route: int,
    n_ego_stops: int,
    ego_committed: B,
    walk: F64,
    walk_ids: I64,
    trig: F64,
    trig_walker: I64,
    parked_ids: I64,
    parked: F64,
    hist_t: I64,
    hist: F64,
) -> tuple[int, float, float, bool]:  # pragma: no cover - compiled
    """The world's physics steps until ``clock[3]`` (one step when ``clock[4]`` is 2: the ego is
    moved by Python); returns the steps taken, the fleet's plan time, the time of the next lane
    change to start and whether a follower left its route (it stops after that step)."""
    time_ns, start_ns, dt_full, stamp_ns, pedals = clock[0], clock[1], clock[2], clock[3], clock[4]
    two = powers[0]
    off, n_route = table[0, ego_route], table[1, ego_route]
    net_s, net_x, net_y = net[0], net[1], net[2]
    nf, nw, npk = len(f), len(walk), len(parked)
    steps = 0
    left = False
    while time_ns < stamp_ns:
        dt_ns = min(dt_full, stamp_ns - time_ns)
        t = (time_ns - start_ns) / 1e9
        dt_s = dt_ns / 1e9
        scripted = pedals == 0
        plan = scripted or nf > 0
        nm = 1 + nf + nw + npk
        ids = np.empty(nm, dtype=np.int64)
        obst = np.empty((6, nm))
        if plan:  # the obstacle snapshot: the ego, the followers, the walkers, the parked
            c, s = math.cos(e[EYAW]), math.sin(e[EYAW])
            ids[0] = 0
            obst[0, 0], obst[1, 0] = e[EX] + p[CENTER] * c, e[EY] + p[CENTER] * s
            obst[2, 0], obst[3, 0] = p[ELEN], p[EWID]
            obst[4, 0], obst[5, 0] = e[ESPEED] * c, e[ESPEED] * s
            for a in range(nf):
                x, y, yaw = fl._pose(f, i, a, fleet_t, net, table, powers)
                v = f[a, fl.SPEED]
                ids[1 + a] = i[a, fl.ID]
                obst[0, 1 + a], obst[1, 1 + a] = x, y
                obst[2, 1 + a], obst[3, 1 + a] = f[a, fl.LENGTH], f[a, fl.WIDTH]
                obst[4, 1 + a], obst[5, 1 + a] = v * math.cos(yaw), v * math.sin(yaw)
            for k in range(nw):
                at = 1 + nf + k
                x, y, vx, vy = _walker(walk, k)
                ids[at] = walk_ids[k]
                obst[0, at], obst[1, at] = x, y
                obst[2, at], obst[3, at] = walk[k, WLEN], walk[k, WWID]
                obst[4, at], obst[5, at] = vx, vy
            for k in range(npk):
                at = 1 + nf + nw + k
                ids[at] = parked_ids[k]
                for col in range(6):
                    obst[col, at] = parked[k, col]
        front = e[ES] + p[FRONT]
        for r in range(len(trig)):  # the pedestrians the ego's progress starts
            k = trig_walker[r]
            if trig[r, 0] - front <= trig[r, 1] and math.isnan(walk[k, WSTART]):
                walk[k, WSTART] = t
        if t >= next_lc:  # lane changes that start now (after the snapshot: it has the old lanes)
            next_lc = _start_lane_changes(f, i, t, fleet_t, net, table, route_len, powers)
        fleet_t = t
        # the ego on its route again (the reference's steer; Route.project_point)
        s0 = e[ES]
        lo = min(max(kernels.bisect_right(net_s, off, off + n_route, s0 - 2.0) - 1, 0), n_route - 2)
        hi = min(kernels.bisect_left(net_s, off, off + n_route, s0 + 10.0) + 1, n_route - 1)
        hi = max(hi, lo + 1)
        s_new, _, _ = kernels.project_point(net_s, net_x, net_y, off + lo, off + hi, e[EX], e[EY])
        e[ES] = s_new
        steer = 0.0
        if scripted:  # pure pursuit
            v = e[ESPEED]
            look = min(max(p[LOOK_T] * v, p[LOOK_MIN]), p[LOOK_MAX])
            tx, ty, _ = kernels.route_pose(net, off, n_route, e[ES] + look, 0.0)
            dx, dy = tx - e[EX], ty - e[EY]
            c, sn = math.cos(e[EYAW]), math.sin(e[EYAW])
            lx, ly = c * dx + sn * dy, -sn * dx + c * dy
            dist = max(kernels.hypot(lx, ly), 1e-6)
            steer = math.atan2(2.0 * p[WB] * ly, dist * dist)
        gap_e, lead_e = np.inf, 0.0
        if plan:
            nq = nf + 1 if scripted else nf
            q_int, q_float = fl._queries(f, i, table, p[HORIZON], scripted)
            if scripted:
                s_front = e[ES] + p[FRONT]
                q_int[0, nf], q_int[1, nf], q_int[2, nf] = off, n_route, 0
                q_float[0, nf], q_float[1, nf] = e[ES] + p[CENTER], s_front
                q_float[2, nf], q_float[3, nf] = s_front + p[HORIZON], p[EWID]
            if nq > 0:
                gaps, speeds = _gap_kernel(q_int, q_float, p[MARGIN], ids, obst, net, blocks)
            else:
                gaps, speeds = np.full(0, np.inf), np.zeros(0)
            fclock = np.empty(3)
            fclock[0], fclock[1], fclock[2] = t, dt_s, any_lights
            fl._plan_advance(
                f,
                i,
                committed,
                fclock,
                gaps,
                speeds,
                has_brake,
                stop_s,
                stop_light,
                n_stops,
                light_group,
                timing,
                route_len,
                powers,
            )
            if scripted:
                gap_e, lead_e = gaps[nf], speeds[nf]
        if scripted:  # the reference's accelerate: the stop lines, the route's end, IDM
            v = e[ESPEED]
            s_front = e[ES] + p[FRONT]
            stop = fl.light_gap_kernel(
                stop_s,
                stop_light,
                ego_route,
                n_ego_stops,
                ego_committed,
                light_group,
                timing,
                s_front,
                v,
                t,
                p[B_COMF],
                two,
            )
            end = route_len[ego_route] - 1.0 - s_front
            if min(stop, end) < gap_e:
                gap_e, lead_e = min(stop, end), 0.0
            accel_cmd = idm_kernel(
                v,
                gap_e,
                lead_e,
                p[V0],
                p[DELTA],
                p[HEADWAY],
                p[MIN_GAP],
                p[A_MAX],
                p[B_COMF],
                p[IDM_DEC],
                V0_MIN_MPS,
                GAP_MIN_M,
                two,
            )
            _bicycle(e, p, dt_s, accel_cmd, steer, math.nan)  # the script: no tyre bound
        elif pedals == 1:  # ActuatedEgo.apply: the pedals under the held command
            pedal_steps(e, p, dt_s, 1)
        # (pedals == 2: Python moves the ego after this step, World.drive_ego)
        time_ns += dt_ns
        t_new = (time_ns - start_ns) / 1e9
        for k in range(nw):
            walk[k, WTIME] = t_new
        hist_t[steps] = time_ns
        hist[steps, 0], hist[steps, 1], hist[steps, 2] = e[EX], e[EY], e[EYAW]
        steps += 1
        for k in range(nf):
            if i[k, fl.ACTIVE] == 0:
                left = True
        if left or pedals == 2:
            break
    clock[0] = time_ns
    return steps, fleet_t, next_lc, left


@numba.njit(cache=True, nogil=True)
def _start_lane_changes(  # noqa: PLR0917 (numba has no keyword-only parameters)
    f: F64, i: I64, t: float, fleet_t: float, net: F64, table: I64, route_len: F64, powers: F64
) -> float:  # pragma: no cover - compiled
    """``ReferenceFollower.start_plan``'s lane changes at ``t``: each follower whose change is due
    moves onto its target route where ``Route.project`` of its pose (over the whole target)
    puts it; returns the start time of the next change (inf: none left)."""
    net_s, net_x, net_y = net[0], net[1], net[2]
    next_lc = np.inf
    for k in range(len(f)):
        if i[k, fl.LC_TARGET] < 0 or i[k, fl.LC_STARTED] == 1:
            continue
        if not t >= f[k, fl.LC_START]:
            next_lc = min(next_lc, f[k, fl.LC_START])
            continue
        x, y, _ = fl._pose(f, i, k, fleet_t, net, table, powers)
        target = i[k, fl.LC_TARGET]
        off, n = table[0, target], table[1, target]
        # Route._piece(0, length): every segment of the target
        lo = min(max(kernels.bisect_right(net_s, off, off + n, 0.0) - 1, 0), n - 2)
        hi = min(kernels.bisect_left(net_s, off, off + n, route_len[target]) + 1, n - 1)
        hi = max(hi, lo + 1)
        s_new, lat, _ = kernels.project_point(net_s, net_x, net_y, off + lo, off + hi, x, y)
        i[k, fl.ROUTE], f[k, fl.S] = target, s_new
        f[k, fl.LC_OFF0] = lat - f[k, fl.LAT]
        i[k, fl.LC_STARTED] = 1
    return next_lc


@numba.njit(cache=True, nogil=True)
def _walker(walk: F64, k: int) -> tuple[float, float, float, float]:  # pragma: no cover
    """Walker.pose's x, y and Walker.velocity of walker ``k``."""
    start, dist = walk[k, WSTART], walk[k, WDIST]
    walked = 0.0
    if not math.isnan(start):
        walked = min(max(walk[k, WSPD] * (walk[k, WTIME] - start), 0.0), dist)
    fr = walked / dist if dist > 0 else 0.0
    x = walk[k, WSX] + fr * (walk[k, WEX] - walk[k, WSX])
    y = walk[k, WSY] + fr * (walk[k, WEY] - walk[k, WSY])
    vx = vy = 0.0
    if not math.isnan(start) and 0.0 < walked < dist:
        vx = walk[k, WSPD] * math.cos(walk[k, WYAW])
        vy = walk[k, WSPD] * math.sin(walk[k, WYAW])
    return x, y, vx, vy


def ego_parameters(geometry: EgoGeometry, pedals: PedalModel | None, friction_mps2: float) -> F64:
    """The ego's parameter columns: ``geometry``'s limits, ``pedals``' model (None: zeros) and
    the friction circle — what :func:`pedal_steps` reads (the command's three columns are set
    per call)."""
    g = geometry
    p = np.zeros(_NP)
    p[WB:JERK] = (
        g.wheelbase_m,
        g.center_offset_m,
        g.front_offset_m,
        g.length_m,
        g.width_m,
        g.max_steer_rad,
        g.max_steer_rate_rad_s,
        g.max_accel_mps2,
        g.max_decel_mps2,
    )
    p[JERK] = math.nan if g.max_jerk_mps3 is None else g.max_jerk_mps3
    if pedals is not None:
        p[P_ACC:HORIZON] = (
            pedals.max_accel_mps2,
            pedals.max_brake_mps2,
            pedals.rolling_resistance_mps2,
            pedals.drag_coefficient_1pm,
        )
    p[FRICTION] = friction_mps2
    return p


@numba.njit(cache=True, nogil=True)
def pedal_steps(e: F64, p: F64, dt_s: float, steps: int) -> None:
    """``steps`` × ``ActuatedEgo.apply(command, dt_s)`` (no delay) on the ego's columns ``e``
    (x, y, yaw, speed, steer, accel), in place: each step the pedal model's acceleration at the
    speed then, and ``BicycleModel.step`` within the friction circle — also the commanded ego's
    step of the world's frame (``pedals == 1`` in ``_frame``); ``p`` is :func:`ego_parameters` with
    the command in its ``THROTTLE``, ``BRAKE``, ``STEER_CMD`` columns."""  # pragma: no cover
    for _ in range(steps):
        v = e[ESPEED]
        accel_cmd = p[THROTTLE] * p[P_ACC] - p[BRAKE] * p[P_BRK] - (p[ROLL] + p[DRAG] * v * v)
        _bicycle(e, p, dt_s, accel_cmd, p[STEER_CMD], p[FRICTION])


@numba.njit(cache=True, nogil=True)
def _bicycle(  # noqa: PLR0917 (numba has no keyword-only parameters)
    e: F64, p: F64, dt_s: float, accel_cmd: float, steer_cmd: float, friction: float
) -> None:
    """``BicycleModel.step`` of the ego's columns, in place (``friction``: its
    ``friction_circle_mps2``, NaN for None)."""  # pragma: no cover - compiled
    max_delta = p[STEER_RATE] * dt_s
    cmd = min(max(steer_cmd, -p[MAX_STEER]), p[MAX_STEER])
    e[ESTEER] += min(max(cmd - e[ESTEER], -max_delta), max_delta)
    accel = min(max(accel_cmd, -p[MAX_DEC]), p[MAX_ACC])
    if not math.isnan(p[JERK]):
        max_change = p[JERK] * dt_s
        accel = min(max(accel, e[EACCEL] - max_change), e[EACCEL] + max_change)
    if not math.isnan(friction):  # friction_scale
        v0 = e[ESPEED]
        v_top = max(v0, v0 + accel * dt_s)
        lateral = v_top * v_top * (math.tan(e[ESTEER]) / p[WB])  # v² · curvature_1pm
        demand = kernels.hypot(accel, lateral)  # CPython's hypot, as friction_scale's
        if demand > friction:
            scale = friction / demand
            accel *= scale
            e[ESTEER] = math.atan(math.tan(e[ESTEER]) * scale)
    e[EACCEL] = accel
    v = e[ESPEED]
    v1 = v + accel * dt_s
    if v1 >= 0.0:
        dist = 0.0 + v * dt_s + 0.5 * accel * dt_s * dt_s
        e[ESPEED] = v1
    else:
        dist = 0.0 + v * v / (-2.0 * accel)
        e[ESPEED] = 0.0
    if e[ESPEED] == 0.0 and e[EACCEL] < 0.0:
        e[EACCEL] = 0.0
    kappa = math.tan(e[ESTEER]) / p[WB]
    dyaw = kappa * dist
    yaw0 = e[EYAW]
    if kappa == 0.0:
        e[EX] += dist * math.cos(yaw0)
        e[EY] += dist * math.sin(yaw0)
    else:
        e[EX] += (math.sin(yaw0 + dyaw) - math.sin(yaw0)) / kappa
        e[EY] += (math.cos(yaw0) - math.cos(yaw0 + dyaw)) / kappa
    e[EYAW] = yaw0 + dyaw
