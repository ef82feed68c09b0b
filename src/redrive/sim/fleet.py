"""The world's lane followers as arrays, planned and moved by compiled kernels.

``ReferenceFollower`` (``tests/sim/_reference_agents.py``, a
:class:`~redrive.sim.agents.LaneFollower` that moves itself) is the reference: one object per vehicle, its pose,
stop lines, IDM and motion in Python, a few dozen calls per agent per physics step.  The world
keeps the same state for all of them in arrays (:class:`LaneFleet`): every physics step is then
one kernel call for their poses (the obstacle snapshot), one for the gap search
(:class:`~redrive.sim.gaps.GapSearch`) and one for the stop lines, IDM, scripted braking and
the motion of all of them.

Every value is the one ``ReferenceFollower`` computes, bit for bit: the same float64 operations
in the same order (compiled without ``fastmath``; powers go through ``pow`` with a run-time
exponent, as Python's ``**`` does; ``math.hypot`` of each route segment is taken from Python);
a lane change starts in the world's frame kernel (:mod:`redrive.sim.stepper`) where
:meth:`Route.project` puts the follower on its target (the Python version of that step is in
``tests/sim/_reference_step.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numba
import numpy as np
import numpy.typing as npt

from redrive.motion.idm import GAP_MIN_M, V0_MIN_MPS, idm_kernel
from redrive.sim import kernels
from redrive.sim.agents import LaneFollower
from redrive.sim.gaps import GapSearch
from redrive.sim.lights import TrafficLights
from redrive.sim.roads import Route
from redrive.types import ObjectClass

__all__ = ["LaneFleet"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]

#: exponents handed to the kernels at run time: a literal would let the compiler turn
#: ``pow(x, 2.0)`` into ``x * x``, which libm's ``pow`` (Python's ``**``) need not equal
_POWERS = np.array([2.0, 3.0, 4.0, 5.0])

# columns of LaneFleet._f (float state and parameters, one row per follower)
(S, SPEED, ACCEL, LAT, LENGTH, WIDTH, V0, HEADWAY, MIN_GAP, A_MAX, B_COMF, DELTA, MAX_DECEL) = (
    range(13)
)
(BRAKE_T, BRAKE_DECEL, LC_START, LC_DUR, LC_OFF0) = range(13, 18)
_NF = 18
# columns of LaneFleet._i
(ID, ROUTE, LC_TARGET, LC_STARTED, OBEYS, ACTIVE) = range(6)
_NI = 6


class LaneFleet:
    """The lane followers of one world (in the world's order), stepped together.

    Args:
        followers: the followers as the world built them (their state is copied).
        search: the world's gap search (its routes hold every route a follower may drive).
        lights: the world's traffic lights.
    """

    def __init__(
        self, followers: Sequence[LaneFollower], search: GapSearch, lights: TrafficLights
    ) -> None:
        self._search = search
        self._lights = lights
        self._routes: list[Route] = list(search.routes)
        index = {id(r): k for k, r in enumerate(self._routes)}
        n = len(followers)
        f = np.zeros((n, _NF))
        i = np.zeros((n, _NI), dtype=np.int64)
        for k, a in enumerate(followers):
            p, lc = a.idm, a.lane_change
            f[k, :LC_OFF0] = (
                a.s_m,
                a.speed_mps,
                a.accel_mps2,
                a.lateral_offset_m,
                a.size_lwh_m[0],
                a.size_lwh_m[1],
                p.desired_speed_mps,
                p.time_headway_s,
                p.min_gap_m,
                p.max_accel_mps2,
                p.comfort_decel_mps2,
                p.delta,
                p.max_decel_mps2,
                math.inf if a.brake_time_s is None else a.brake_time_s,
                a.brake_decel_mps2,
                math.inf if lc is None else lc.start_time_s,
                1.0 if lc is None else lc.duration_s,
            )
            i[k] = (
                a.agent_id,
                index[id(a.route)],
                -1 if lc is None else index[id(lc.target)],
                0,
                int(a.obeys_lights),
                1,
            )
        self._f, self._i = f, i
        self._has_brake = np.array([a.brake_time_s is not None for a in followers], dtype=bool)
        self.classes: list[ObjectClass] = [a.object_class for a in followers]
        self.heights: F64 = np.array([a.size_lwh_m[2] for a in followers], dtype=np.float64)
        self.colors: list[tuple[int, int, int]] = [a.color_rgb for a in followers]
        self.reflectivity: list[float] = [a.reflectivity for a in followers]
        self.sizes: list[tuple[float, float, float]] = [a.size_lwh_m for a in followers]
        self._next_lc = float(f[:, LC_START].min()) if n else math.inf
        self._time_s = 0.0  # the last plan's time: a lane change's offset fades with it
        # the stop lines of every route, (routes, most stop lines) padded
        k_max = max((len(r.stop_lines) for r in self._routes), default=0)
        self._stop_s = np.zeros((len(self._routes), max(k_max, 1)))
        self._stop_light = np.zeros((len(self._routes), max(k_max, 1)), dtype=np.int64)
        self._n_stops = np.array([len(r.stop_lines) for r in self._routes], dtype=np.int64)
        for r, route in enumerate(self._routes):
            for k, stop in enumerate(route.stop_lines):
                self._stop_s[r, k], self._stop_light[r, k] = stop.s_m, stop.light_id
        self._committed = np.zeros((n, max(k_max, 1)), dtype=bool)
        # the signals' phase groups by light id (-1: no such signal, its state UNKNOWN) and the
        # timing, for TrafficLights.state in the kernel
        n_lights = max([s.light_id for s in lights.signals] + [int(self._stop_light.max())]) + 1
        self._light_group = np.full(n_lights, -1, dtype=np.int64)
        for sig in lights.signals:
            self._light_group[sig.light_id] = sig.phase_group
        tm = lights.timing
        self._timing = np.array([tm.green_s, tm.yellow_s, tm.offset_s, tm.cycle_s])
        self._route_len = np.array([r.length_m for r in self._routes], dtype=np.float64)
        self._clock = np.zeros(3)

    def __len__(self) -> int:
        return len(self._f)

    @property
    def ids(self) -> I64:
        """(N,) agent ids."""
        return self._i[:, ID]

    @property
    def lengths(self) -> F64:
        """(N,) box lengths, metres."""
        return self._f[:, LENGTH]

    @property
    def widths(self) -> F64:
        """(N,) box widths, metres."""
        return self._f[:, WIDTH]

    def drop(self) -> None:
        """Remove every follower."""
        self._keep(np.zeros(len(self._f), dtype=bool))

    def _keep(self, mask: B) -> None:
        self._f, self._i = self._f[mask], self._i[mask]
        self._committed, self._has_brake = self._committed[mask], self._has_brake[mask]
        self.heights = self.heights[mask]
        keep = mask.tolist()
        for name in ("classes", "colors", "reflectivity", "sizes"):
            setattr(self, name, [v for v, k in zip(getattr(self, name), keep, strict=True) if k])

    def poses(self) -> F64:
        """(5, N): box centre x, y (metres), yaw (rad) and map velocity x, y (m/s) — what each
        ``ReferenceFollower.pose`` and ``velocity`` give."""
        search = self._search
        return _poses(self._f, self._i, self._time_s, search.net, search.route_table, _POWERS)

    def snapshot(self, ids: I64, rows: F64) -> tuple[I64, F64]:
        """The obstacles of a physics step with the followers after the first of ``rows``
        ((K, 6): centre x, y, length, width, velocity x, y; ``ids`` (K,)): ids (M,) and the
        rows transposed, (6, M), as :meth:`GapSearch.gaps_of` takes them."""
        search = self._search
        return _snapshot(
            self._f, self._i, self._time_s, search.net, search.route_table, _POWERS, ids, rows
        )

    def queries(
        self, horizon_m: float, extra: tuple[int, int, int, float, float, float, float] | None
    ) -> tuple[I64, F64]:
        """The gap-search queries of all followers (``GapSearch.gaps_of``'s arrays), then
        ``extra`` (route's first sample, sample count, id, centre, front, front + horizon,
        width: the scripted ego's) when given."""
        search = self._search
        q_int, q_float = _queries(
            self._f, self._i, search.route_table, horizon_m, extra is not None
        )
        if extra is not None:
            q_int[0, -1], q_int[1, -1], q_int[2, -1] = extra[0], extra[1], extra[2]
            q_float[0, -1], q_float[1, -1], q_float[2, -1], q_float[3, -1] = extra[3:]
        return q_int, q_float

    def finish_and_advance(
        self, time_s: float, dt_s: float, *, gap_m: F64, leader_speed_mps: F64
    ) -> None:
        """``ReferenceFollower.finish_plan`` then ``advance`` of all; those
        who left the end of their route are removed."""
        clock = self._clock
        clock[0], clock[1], clock[2] = time_s, dt_s, 1.0 if self._lights.signals else 0.0
        _plan_advance(
            self._f,
            self._i,
            self._committed,
            clock,
            gap_m,
            leader_speed_mps,
            self._has_brake,
            self._stop_s,
            self._stop_light,
            self._n_stops,
            self._light_group,
            self._timing,
            self._route_len,
            _POWERS,
        )
        active = self._i[:, ACTIVE] == 1
        if not active.all():
            self._keep(active)


@numba.njit(cache=True, nogil=True)
def _pose(  # noqa: PLR0917 (numba has no keyword-only parameters)  # pragma: no cover
    f: F64, i: I64, k: int, time_s: float, net: F64, table: I64, powers: F64
) -> tuple[float, float, float]:
    """``ReferenceFollower.pose`` of follower ``k``."""
    off = rate = 0.0
    if i[k, LC_TARGET] >= 0 and i[k, LC_STARTED] == 1:
        dur = f[k, LC_DUR]
        u = min(max((time_s - f[k, LC_START]) / dur, 0.0), 1.0)
        p2, p3, p4, p5 = u ** powers[0], u ** powers[1], u ** powers[2], u ** powers[3]
        fade = 1.0 - (10.0 * p3 - 15.0 * p4 + 6.0 * p5)
        r = -(30.0 * p2 - 60.0 * p3 + 30.0 * p4) / dur
        off, rate = f[k, LC_OFF0] * fade, f[k, LC_OFF0] * r
    route = i[k, ROUTE]
    x, y, heading = kernels.route_pose(
        net, table[0, route], table[1, route], f[k, S], f[k, LAT] + off
    )
    return x, y, heading + math.atan2(rate, max(f[k, SPEED], 0.5))


@numba.njit(cache=True, nogil=True)
def _poses(  # noqa: PLR0917 (numba has no keyword-only parameters)
    f: F64, i: I64, time_s: float, net: F64, table: I64, powers: F64
) -> F64:  # pragma: no cover - compiled
    out = np.empty((5, len(f)))
    for k in range(len(f)):
        x, y, yaw = _pose(f, i, k, time_s, net, table, powers)
        v = f[k, SPEED]
        out[0, k], out[1, k], out[2, k] = x, y, yaw
        out[3, k], out[4, k] = v * math.cos(yaw), v * math.sin(yaw)
    return out


@numba.njit(cache=True, nogil=True)
def _snapshot(  # noqa: PLR0917 (numba has no keyword-only parameters)
    f: F64, i: I64, time_s: float, net: F64, table: I64, powers: F64, ids: I64, rows: F64
) -> tuple[I64, F64]:  # pragma: no cover - compiled
    n, k = len(f), len(ids)
    out_ids = np.empty(n + k, dtype=np.int64)
    out = np.empty((6, n + k))
    for r in range(k):
        at = r if r == 0 else r + n
        out_ids[at] = ids[r]
        for c in range(6):
            out[c, at] = rows[r, c]
    for a in range(n):
        x, y, yaw = _pose(f, i, a, time_s, net, table, powers)
        v = f[a, SPEED]
        out_ids[1 + a] = i[a, ID]
        out[0, 1 + a], out[1, 1 + a] = x, y
        out[2, 1 + a], out[3, 1 + a] = f[a, LENGTH], f[a, WIDTH]
        out[4, 1 + a], out[5, 1 + a] = v * math.cos(yaw), v * math.sin(yaw)
    return out_ids, out


@numba.njit(cache=True, nogil=True)
def _queries(
    f: F64, i: I64, table: I64, horizon_m: float, extra: bool
) -> tuple[I64, F64]:  # pragma: no cover - compiled
    n = len(f)
    q_int = np.empty((3, n + 1 if extra else n), dtype=np.int64)
    q_float = np.empty((4, n + 1 if extra else n))
    for k in range(n):
        route = i[k, ROUTE]
        s_front = f[k, S] + f[k, LENGTH] / 2.0
        q_int[0, k], q_int[1, k], q_int[2, k] = table[0, route], table[1, route], i[k, ID]
        q_float[0, k], q_float[1, k] = f[k, S], s_front
        q_float[2, k], q_float[3, k] = s_front + horizon_m, f[k, WIDTH]
    return q_int, q_float


@numba.njit(cache=True, nogil=True)
def _light_state(group: I64, timing: F64, light: int, time_s: float) -> int:  # pragma: no cover
    """TrafficLights.state as a code: 0 green, 1 yellow, 2 red, 3 unknown."""
    if light >= len(group) or group[light] < 0:
        return 3
    green, yellow, offset, cycle = timing[0], timing[1], timing[2], timing[3]
    half = cycle / 2.0
    tau = np.fmod(time_s + offset - group[light] * half, cycle)  # exact, as math.fmod
    if tau < 0.0:
        tau += cycle
    if tau < green:
        return 0
    if tau < green + yellow:
        return 1
    return 2


@numba.njit(cache=True, nogil=True)
def light_gap_kernel(  # noqa: PLR0917 (numba has no keyword-only parameters)
    stop_s: F64,
    stop_light: I64,
    route: int,
    n_stops: int,
    committed: B,
    light_group: I64,
    timing: F64,
    s_front: float,
    v: float,
    time_s: float,
    comfort: float,
    two: float,
) -> float:  # pragma: no cover - compiled
    """``light_gap`` (tests/sim/_reference_agents.py): the gap (m) to the first stop line of
    ``route`` ahead of ``s_front`` that must be respected, inf if none; a yellow line that cannot
    be stopped at comfortably is marked in ``committed`` (that vehicle's row) and passed."""
    for j in range(n_stops):
        g = stop_s[route, j] - s_front
        if g < -0.5 or committed[j]:
            continue
        state = _light_state(light_group, timing, stop_light[route, j], time_s)
        if state == 0:
            return np.inf
        if state == 1 and v**two / (2.0 * comfort) > g:
            committed[j] = True
            continue
        return float(max(g, 0.0))
    return np.inf


@numba.njit(cache=True, nogil=True)
def _plan_advance(  # noqa: PLR0917 (the fleet's arrays; numba has no keyword-only parameters)
    f: F64,
    i: I64,
    committed: B,
    clock: F64,
    gaps: F64,
    leader_speeds: F64,
    has_brake: B,
    stop_s: F64,
    stop_light: I64,
    n_stops: I64,
    light_group: I64,
    timing: F64,
    route_len: F64,
    powers: F64,
) -> None:  # pragma: no cover - compiled
    """finish_plan (``light_gap``, IDM: :func:`~redrive.motion.idm.idm_kernel`, the scripted
    braking) and advance (``advance_1d``, leaving at the route's end) of every follower, in
    place."""
    time_s, dt_s, any_lights = clock[0], clock[1], clock[2] != 0.0
    two = powers[0]
    for k in range(len(f)):
        gap, v_lead = gaps[k], leader_speeds[k]
        v = f[k, SPEED]
        if i[k, OBEYS] == 1 and any_lights:
            route = i[k, ROUTE]
            s_front = f[k, S] + f[k, LENGTH] / 2.0
            stop = light_gap_kernel(
                stop_s,
                stop_light,
                route,
                n_stops[route],
                committed[k],
                light_group,
                timing,
                s_front,
                v,
                time_s,
                f[k, B_COMF],
                two,
            )
            if stop < gap:
                gap, v_lead = stop, 0.0
        accel = idm_kernel(
            v,
            gap,
            v_lead,
            f[k, V0],
            f[k, DELTA],
            f[k, HEADWAY],
            f[k, MIN_GAP],
            f[k, A_MAX],
            f[k, B_COMF],
            f[k, MAX_DECEL],
            V0_MIN_MPS,
            GAP_MIN_M,
            two,
        )
        if has_brake[k] and time_s >= f[k, BRAKE_T]:
            accel = min(accel, -f[k, BRAKE_DECEL])
        # advance_1d
        s = f[k, S]
        v1 = v + accel * dt_s
        if v1 >= 0.0:
            s, v = s + v * dt_s + 0.5 * accel * dt_s * dt_s, v1
        else:
            s, v = s + v * v / (-2.0 * accel), 0.0
        if v == 0.0 and accel < 0.0:
            accel = 0.0
        f[k, S], f[k, SPEED], f[k, ACCEL] = s, v, accel
        if s - f[k, LENGTH] / 2.0 > route_len[i[k, ROUTE]]:
            i[k, ACTIVE] = 0
