"""The deterministic driving world: roads, lights, agents, scenery and the ego, stepped in time.

``World(scenario)`` builds everything from the scenario and one ``numpy.random.Generator`` seeded
with ``scenario.seed`` (scenery first, then agents in file order), so the same seed gives the same
states bit for bit.  Time is int nanoseconds since the epoch; physics runs at the scenario's
``physics_dt_s``; :meth:`World.scene` is the :class:`~redrive.sim.scene.Scene` the sensors render.

The lane followers are built as :class:`~redrive.sim.agents.LaneFollower` objects and then kept
as arrays (:class:`~redrive.sim.fleet.LaneFleet`); the world steps only in compiled calls
(:class:`~redrive.sim.stepper.FrameStepper`: a frame's physics steps — the obstacle snapshot,
lane changes, every agent's gap search, the followers' and the ego's plan and motion — in one
call), with the results the objects would give, bit for bit.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from redrive.errors import SimulationError
from redrive.motion import IdmParams
from redrive.sim.agents import LaneChange, LaneFollower, ParkedObject, Walker
from redrive.sim.ego import (
    BicycleModel,
    EgoDriver,
    EgoGeometry,
    PedalModel,
    TyreLimit,
    pose_matrix,
)
from redrive.sim.fleet import LaneFleet
from redrive.sim.gaps import GapSearch
from redrive.sim.ground import rasterize
from redrive.sim.ground_truth import boxes_in_base
from redrive.sim.lights import TrafficLights
from redrive.sim.roads import RoadNetwork, build_network
from redrive.sim.scenario import AgentSpec, Scenario
from redrive.sim.scene import GroundMap, ObjectLooks, Scene
from redrive.sim.scenery import build_scenery
from redrive.sim.stepper import FrameStepper
from redrive.sim.truth import _Constant, truth_columns, truth_moving
from redrive.types import (
    ControlCommands,
    DetectedObject,
    ObjectClass,
    ObjectColumns,
    TrafficData,
    VehicleState,
)

__all__ = ["World"]

EGO_ID = 0
_HISTORY_S = 0.3
_SIZES = {
    "vehicle": (4.5, 1.85, 1.5),
    "truck": (8.0, 2.5, 3.2),
    "cyclist": (1.8, 0.6, 1.7),
    "pedestrian": (0.5, 0.6, 1.75),
    "parked": (4.5, 1.85, 1.5),
    "parked_van": (5.5, 2.1, 2.5),
}
_CLASSES = {
    "vehicle": ObjectClass.VEHICLE,
    "truck": ObjectClass.TRUCK,
    "cyclist": ObjectClass.BICYCLE,
    "parked": ObjectClass.VEHICLE,
    "parked_van": ObjectClass.VEHICLE,
}
_PALETTE = np.array(
    [
        [200, 30, 30],
        [30, 60, 170],
        [235, 235, 235],
        [25, 25, 25],
        [120, 120, 125],
        [30, 120, 60],
        [220, 180, 40],
        [150, 90, 40],
    ],
    dtype=np.uint8,
)


_kernels_loaded = False


def _load_kernels(scenario: Scenario) -> None:
    """Once per process, when the first world is built: step a throwaway world of the same
    scenario once, so that loading the physics step's compiled kernels (numba's cache; compiling
    them on a cold cache) is part of building a world, not of its first step — a closed loop's
    first frame or a live run's."""
    global _kernels_loaded  # noqa: PLW0603 (one flag per process)
    if _kernels_loaded:
        return
    _kernels_loaded = True
    probe = World(scenario)
    probe.objects()
    probe.step_to(probe.time_ns + probe._dt_ns)
    probe.drive_ego_pedals(ControlCommands(), PedalModel())
    probe.step_to(probe.time_ns + probe._dt_ns)


class World:
    """The synthetic world of one :class:`Scenario`; call :meth:`step` to advance it."""

    def __init__(self, scenario: Scenario, *, ego_geometry: EgoGeometry | None = None) -> None:
        self.scenario = scenario
        self.network: RoadNetwork = build_network(scenario.road)
        self.lights = TrafficLights(self.network.signals, scenario.lights)
        self.ego_geometry = ego_geometry or EgoGeometry()
        self._rng = np.random.default_rng(scenario.seed)
        self._start_ns = int(scenario.start_stamp_ns)
        self._time_ns = self._start_ns
        self._dt_ns = round(scenario.physics_dt_s * 1e9)
        self._ground: GroundMap | None = None
        self._static = build_scenery(self.network, scenario, self._rng)
        #: the scenery's ground-truth part (usually none), for :meth:`ground_truth_objects`
        self._static_truth = _subset(self._static, self._static[1].is_ground_truth)
        self._followers: list[LaneFollower] = []
        self._walkers: list[Walker] = []
        self._triggers: list[tuple[Walker, float, float]] = []  # walker, s on ego route, distance
        self._parked: list[ParkedObject] = []
        spec = scenario.ego
        route = self.network.routes[spec.route]
        x, y, yaw = route.pose_at(spec.start_s_m)
        speed = spec.set_speed_mps if spec.initial_speed_mps is None else spec.initial_speed_mps
        self._ego = BicycleModel(self.ego_geometry, x_m=x, y_m=y, yaw_rad=yaw, speed_mps=speed)
        idm = IdmParams(
            desired_speed_mps=spec.set_speed_mps,
            time_headway_s=spec.time_headway_s,
            min_gap_m=spec.min_gap_m,
            max_accel_mps2=spec.max_accel_mps2,
            comfort_decel_mps2=spec.comfort_decel_mps2,
        )
        self._driver = EgoDriver(route, spec.start_s_m, idm=idm, ego_id=EGO_ID)
        next_id = 1
        for agent in scenario.agents:
            next_id = self._add_agent(agent, next_id)
        self._history: deque[tuple[int, float, float, float]] = deque()
        #: steps the ego instead of the scripted driver: ``step(model, dt_s)`` (drive_ego)
        self._ego_step: Callable[[BicycleModel, float], None] | None = None
        #: the command and pedals the ego moves under (:meth:`drive_ego_pedals`), or None
        self._ego_pedals: tuple[ControlCommands, PedalModel] | None = None
        #: the friction circle (m/s²) the pedal-driven ego moves within
        self._ego_friction_mps2 = TyreLimit().max_accel_mps2
        #: every lane follower's and the scripted ego's gap search, batched per physics step
        self._gaps = GapSearch(self.network.routes.values())
        #: the lane followers' state as arrays, stepped by compiled kernels
        self._fleet = LaneFleet(self._followers, self._gaps, self.lights)
        self._followers = []  # their state lives in the fleet from here on
        #: a frame's physics steps in one compiled call (the scripted or the pedal-driven ego)
        self._stepper = FrameStepper(self)
        self._truth_cache: _Constant | None = None
        self._ego_state: tuple[tuple[float, ...], VehicleState] | None = None
        _load_kernels(scenario)
        self._record_pose()

    # -- construction -------------------------------------------------------------------------
    def _add_agent(self, spec: AgentSpec, next_id: int) -> int:
        route = self.network.routes[spec.route]
        size = spec.size_m or _SIZES[spec.kind]
        shoulder = self.scenario.road.shoulder_m
        for k in range(spec.count):
            s = spec.start_s_m - k * spec.spacing_m
            color = spec.color or self._pick_color()
            if spec.kind == "pedestrian":
                walk = self.scenario.road.sidewalk_width_m
                d0 = spec.lateral_offset_m
                if d0 is None:
                    d0 = -(route.width_m / 2 + shoulder + walk / 2)
                x0, y0, _ = route.pose_at(s, d0)
                x1, y1, _ = route.pose_at(s, spec.to_offset_m or 0.0)
                walker = Walker(
                    next_id,
                    start_xy=(x0, y0),
                    end_xy=(x1, y1),
                    speed_mps=spec.speed_mps,
                    start_time_s=spec.start_time_s,
                    size_lwh_m=size,
                )
                self._walkers.append(walker)
                if spec.trigger_ego_distance_m is not None:
                    s_ego, _ = self._driver.route.project(
                        [[x0, y0]], s_min_m=0.0, s_max_m=self._driver.route.length_m
                    )
                    self._triggers.append((walker, float(s_ego[0]), spec.trigger_ego_distance_m))
            elif spec.kind in ("parked", "parked_van"):
                d = spec.lateral_offset_m
                if d is None:
                    d = -(route.width_m / 2 + shoulder / 2)
                x, y, yaw = route.pose_at(s, d)
                self._parked.append(
                    ParkedObject(
                        agent_id=next_id,
                        object_class=_CLASSES[spec.kind],
                        center_xy=(x, y),
                        yaw_rad=yaw,
                        size_lwh_m=size,
                        color_rgb=color,
                    )
                )
            else:
                v0 = spec.desired_speed_mps
                if v0 is None:
                    v0 = spec.speed_mps
                    if self.scenario.speed_jitter_mps > 0:
                        v0 += float(self._rng.normal(0.0, self.scenario.speed_jitter_mps))
                cyclist = spec.kind == "cyclist"
                idm = IdmParams(
                    desired_speed_mps=max(v0, 0.5), max_accel_mps2=1.0 if cyclist else 1.5
                )
                lane_change = None
                if spec.lane_change_route is not None and spec.lane_change_time_s is not None:
                    lane_change = LaneChange(
                        target=self.network.routes[spec.lane_change_route],
                        start_time_s=spec.lane_change_time_s,
                        duration_s=spec.lane_change_duration_s,
                    )
                offset = spec.lateral_offset_m
                if offset is None:
                    offset = -0.9 if cyclist else 0.0
                self._followers.append(
                    LaneFollower(
                        next_id,
                        _CLASSES[spec.kind],
                        route=route,
                        s_m=s,
                        speed_mps=spec.speed_mps,
                        idm=idm,
                        size_lwh_m=size,
                        color_rgb=color,
                        lateral_offset_m=offset,
                        brake_time_s=spec.brake_time_s,
                        brake_decel_mps2=spec.brake_decel_mps2,
                        lane_change=lane_change,
                    )
                )
            next_id += 1
        return next_id

    def _pick_color(self) -> tuple[int, int, int]:
        r, g, b = (int(c) for c in _PALETTE[self._rng.integers(len(_PALETTE))])
        return r, g, b

    # -- time ---------------------------------------------------------------------------------
    @property
    def time_ns(self) -> int:
        """Current time, int ns since the epoch."""
        return self._time_ns

    @property
    def time_s(self) -> float:
        """Seconds since the start of the scenario."""
        return (self._time_ns - self._start_ns) / 1e9

    def step(self, dt_s: float) -> None:
        """Advance by ``dt_s`` seconds (in physics steps; the last one may be shorter)."""
        if not dt_s >= 0:
            msg = f"World.step: dt_s must be ≥ 0, got {dt_s}"
            raise SimulationError(msg)
        self.step_to(self._time_ns + round(dt_s * 1e9))

    def step_to(self, stamp_ns: int) -> None:
        """Advance until ``time_ns == stamp_ns`` (which must not lie in the past)."""
        if stamp_ns < self._time_ns:
            msg = f"World.step_to: {stamp_ns} ns is before the current time {self._time_ns} ns; the world only moves forward"
            raise SimulationError(msg)
        stepper = self._stepper
        while self._time_ns < stamp_ns:
            stepper.run(self, stamp_ns)

    def drive_ego(self, step: Callable[[BicycleModel, float], None] | None) -> None:
        """Hand the ego to ``step(model, dt_s)``, called every physics step in place of the
        scripted driver (closed loop: the algorithm's commands move the car); None gives it back.
        Each call comes after the other agents planned and moved in that physics step (the
        world then steps one physics step per compiled call: :meth:`drive_ego_pedals` is the
        fast way to drive it).

        The ego's progress along its route is still tracked (it starts the scenario's
        pedestrian triggers), and the other agents see the ego wherever it is.
        """
        self._ego_step = step
        self._ego_pedals = None

    def drive_ego_pedals(
        self, commands: ControlCommands, pedals: PedalModel, *, tyres: TyreLimit | None = None
    ) -> None:
        """Move the ego, every physics step from now on, under ``commands`` through ``pedals``
        within the friction circle of ``tyres`` (None: ``TyreLimit()``) — what :meth:`drive_ego`
        with ``ActuatedEgo(model, pedals=pedals, tyres=tyres).apply(commands, dt_s)`` does, in
        the compiled physics step (call it again for each new command)."""
        self._ego_step = None
        self._ego_pedals = (commands, pedals)
        self._ego_friction_mps2 = (tyres if tyres is not None else TyreLimit()).max_accel_mps2

    def drop_agents(self) -> None:
        """Remove every agent — lane followers, pedestrians, parked vehicles — for good: the world
        keeps its roads, lights, scenery and ego, and :meth:`objects` lists the scenery only.

        For a closed loop whose agents come from another world of the same scenario (replayed
        agents do what the scripted world's do, whatever the driven ego does): stepping this
        world then moves only its ego.
        """
        self._fleet.drop()
        self._walkers, self._triggers, self._parked = [], [], []
        self._stepper = FrameStepper(self)

    def place_ego(self, *, x_m: float, y_m: float, yaw_rad: float) -> None:
        """Start the ego at another pose (map frame, rear-axle centre) — before the first step
        only, so the pose history the LiDARs' skew reads starts there too.  Its speed and
        steering stay; its progress along the route is found again from the new position.

        Raises:
            SimulationError: the world has already moved.
        """
        if self._time_ns != self._start_ns:
            msg = "World.place_ego: the world has already moved; place the ego before stepping"
            raise SimulationError(msg)
        self._ego.x_m, self._ego.y_m, self._ego.yaw_rad = float(x_m), float(y_m), float(yaw_rad)
        s, _ = self._driver.route.project(
            [[self._ego.x_m, self._ego.y_m]], s_min_m=0.0, s_max_m=self._driver.route.length_m
        )
        self._driver.s_m = float(s[0])
        self._history.clear()
        self._record_pose()

    @property
    def ego_model(self) -> BicycleModel:
        """The ego's bicycle model (its state; step it only through :meth:`drive_ego`)."""
        return self._ego

    def _record_pose(self) -> None:
        self._history.append((self._time_ns, self._ego.x_m, self._ego.y_m, self._ego.yaw_rad))
        self._trim_history()

    def _trim_history(self) -> None:
        oldest_ns = self._time_ns - round(_HISTORY_S * 1e9)
        while len(self._history) > 2 and self._history[1][0] <= oldest_ns:
            self._history.popleft()

    # -- state --------------------------------------------------------------------------------
    def _others(self) -> list[Walker | ParkedObject]:
        """The agents that are not lane followers (those are :attr:`_fleet`), in the world's
        order after them."""
        return [*self._walkers, *self._parked]

    def ego_state(self) -> VehicleState:
        """The ego's true state (rear-axle centre, map frame) at :attr:`time_ns` (the same
        immutable object again while neither the time nor the ego's state changed)."""
        m = self._ego
        key = (self._time_ns, m.x_m, m.y_m, m.yaw_rad, m.speed_mps, m.steer_rad, m.accel_mps2)
        if self._ego_state is None or key != self._ego_state[0]:
            self._ego_state = (key, m.state(self._time_ns))
        return self._ego_state[1]

    def map_from_base(self) -> npt.NDArray[np.float64]:
        """The ego pose at :attr:`time_ns`, 4×4 float64."""
        return self._ego.map_from_base()

    def map_from_base_at(self, stamp_ns: int) -> npt.NDArray[np.float64]:
        """The ego pose at ``stamp_ns`` within the last ~0.3 s (linear in x, y and yaw between
        physics steps), for the ego-motion skew inside a LiDAR sweep."""
        stamps = [h[0] for h in self._history]
        if not stamps[0] <= stamp_ns <= stamps[-1]:
            msg = (
                f"World.map_from_base_at: {stamp_ns} ns is outside the pose history "
                f"[{stamps[0]}, {stamps[-1]}] ns; ask for times within the last {_HISTORY_S} s"
            )
            raise SimulationError(msg)
        i = min(bisect.bisect_left(stamps, stamp_ns), len(stamps) - 1)
        t1, x1, y1, yaw1 = self._history[i]
        if t1 == stamp_ns or i == 0:
            return pose_matrix(x1, y1, yaw1)
        t0, x0, y0, yaw0 = self._history[i - 1]
        f = (stamp_ns - t0) / (t1 - t0)
        dyaw = math.remainder(yaw1 - yaw0, 2.0 * math.pi)
        return pose_matrix(x0 + f * (x1 - x0), y0 + f * (y1 - y0), yaw0 + f * dyaw)

    @property
    def ground(self) -> GroundMap:
        """The ground raster (computed once, on first use)."""
        if self._ground is None:
            self._ground = rasterize(self.network)
        return self._ground

    def objects(self) -> tuple[ObjectColumns, ObjectLooks]:
        """Agents and parked vehicles (ground truth) followed by the scenery, map frame, and
        their looks."""
        return self._objects(self._static)

    def ground_truth_objects(self) -> ObjectColumns:
        """The ground-truth ones of :meth:`objects` (agents, parked vehicles and any scenery
        marked as ground truth), in the same order, without the rest of the scenery — what an
        object-level observation needs, at a fraction of the cost."""
        return self._objects(self._static_truth)[0]

    def ground_truth_columns(self) -> ObjectColumns:
        """:meth:`ground_truth_objects`'s rows and values (boxes only, not validated again; the
        constant columns built once) — an object-level observation's input."""
        columns, self._truth_cache = truth_columns(self, self._truth_cache)
        return columns

    def ground_truth_in_base(
        self,
        map_from_base: npt.NDArray[np.float64],
        *,
        lidar_hits: dict[int, int] | None = None,
        camera_pixels: dict[int, int] | None = None,
    ) -> tuple[DetectedObject, ...]:
        """``objects_in_base(self.ground_truth_columns(), map_from_base, …)``: the rows within
        range of an ego at ``map_from_base``, in its base_link, without the map-frame columns."""
        centers, yaws, vels, cache = truth_moving(self, self._truth_cache)
        self._truth_cache = cache
        yaws.flags.writeable = False  # (as a scene's column: the kernel's one signature)
        return boxes_in_base(
            cache.object_ids, cache.classes, centers, cache.sizes, yaws, vels, map_from_base,
            lidar_hits=lidar_hits, camera_pixels=camera_pixels,
        )  # fmt: skip

    def _objects(
        self, static: tuple[ObjectColumns, ObjectLooks]
    ) -> tuple[ObjectColumns, ObjectLooks]:
        """The agents' boxes, map frame, followed by ``static``'s."""
        boxes, looks = static
        fleet = self._fleet
        nf = len(fleet)
        others = self._others()
        n = nf + len(others)
        centers, sizes, yaws, vels = (
            np.zeros((n, 3)),
            np.zeros((n, 3)),
            np.zeros(n),
            np.zeros((n, 3)),
        )
        if nf:
            poses = fleet.poses()
            sizes[:nf] = fleet.sizes
            centers[:nf, 0], centers[:nf, 1] = poses[0], poses[1]
            centers[:nf, 2] = fleet.heights / 2
            yaws[:nf] = poses[2]
            vels[:nf, 0], vels[:nf, 1] = poses[3], poses[4]
        for k, agent in enumerate(others, start=nf):
            sizes[k] = agent.size_lwh_m
            if isinstance(agent, ParkedObject):
                x, y, yaw = agent.center_xy[0], agent.center_xy[1], agent.yaw_rad
            else:
                x, y, yaw = agent.pose()
                vels[k, :2] = agent.velocity()
            centers[k] = (x, y, agent.size_lwh_m[2] / 2)
            yaws[k] = yaw
        columns = ObjectColumns.of(
            object_id=np.concatenate(
                [
                    fleet.ids,
                    np.array([a.agent_id for a in others], dtype=np.int64),
                    boxes.object_id,
                ]
            ),
            object_class=(*fleet.classes, *(a.object_class for a in others), *boxes.object_class),
            center_m=np.concatenate([centers, boxes.center_m]),
            size_m=np.concatenate([sizes, boxes.size_m]),
            yaw_rad=np.concatenate([yaws, boxes.yaw_rad]),
            velocity_mps=np.concatenate([vels, boxes.velocity_mps]),
        )
        appearance = ObjectLooks(
            colors_rgb=np.concatenate(
                [
                    np.array(
                        [*fleet.colors, *(a.color_rgb for a in others)], dtype=np.uint8
                    ).reshape(-1, 3),
                    looks.colors_rgb,
                ]
            ),
            reflectivity=np.concatenate(
                [
                    np.array(
                        [*fleet.reflectivity, *(a.reflectivity for a in others)], dtype=np.float32
                    ),
                    looks.reflectivity,
                ]
            ),
            is_ground_truth=np.concatenate([np.ones(n, dtype=bool), looks.is_ground_truth]),
        )
        return columns, appearance

    def traffic_data(self) -> TrafficData:
        """The signals' ground truth at :attr:`time_ns` (ids: the road map's ``light_id``)."""
        return self.lights.traffic_data(self.time_s)

    def scene(self) -> Scene:
        """The world at :attr:`time_ns`, as the sensors see it (the ego's own box excluded)."""
        objects, looks = self.objects()
        return Scene(
            stamp_ns=self._time_ns,
            ground=self.ground,
            objects=objects,
            looks=looks,
            traffic_lights=self.lights.states(self.time_s),
            map_from_base=self.map_from_base(),
        )


def _subset(
    static: tuple[ObjectColumns, ObjectLooks], keep: npt.NDArray[np.bool_]
) -> tuple[ObjectColumns, ObjectLooks]:
    """The rows of ``static`` where ``keep`` is true, in order."""
    idx = np.flatnonzero(keep)
    return static[0].take(idx), static[1].take(idx)
