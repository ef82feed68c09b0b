"""Backend 2: a recorded log replayed around an ego under the algorithm's control (object level).

The driven ego starts at the log's first pose and speed (the ``VehicleState`` of the first frame
that has one, in the log's own frame — ``odom`` or ``map``) and is propagated by the actuated
kinematic bicycle (:class:`redrive.sim.ego.ActuatedEgo`) under the commands the outputs give.
Each frame the algorithms see is the log's next frame *re-expressed from the driven pose*:

- point clouds (``PointCloud`` payloads, in the sensor frame) are moved by the pose difference
  ``driven_base_from_logged_base`` (planar: x, y, yaw) so the world stays put: a point the logged
  car saw 10 m ahead is 9 m ahead of a driven car 1 m further on.  The sensor is taken to sit at
  its ``sensor_location`` with base_link's axes (the data model carries no mount rotation);
- ground-truth objects (base_link) are moved by the same difference;
- images and every other payload (IMU, GNSS, …) pass through unchanged: a camera cannot be
  re-rendered from a pose it never was at;
- ``vehicle_state`` is the driven ego; :attr:`LogSimulator.logged_state` the logged one.

This is right only for small deviations: nothing hidden from the logged viewpoint appears, the
ground and far objects shift with the car, and the log's own motion blur and timing stay.
:attr:`LogSimulator.deviation_threshold_m` / ``_rad`` (default 2 m / 10°) say when a frame is
flagged as too far from the log for its sensor data to be trusted (the ``deviated`` column).

Agents: ``replay`` — the logged objects as recorded (moved into the driven base frame).
``reactive`` on a log with a road map (Argoverse 2, Waymo Open Motion, CommonRoad, a ``redrive
synth`` log) — the logged vehicles drive along the lane graph under IDM whenever the driven ego
or a vehicle held up by it blocks them, stopping at red lights and stop signs, and hand back to
their logged track when nothing does (:mod:`redrive.closedloop.lane_agents`).  ``reactive``
without a map — the logged *vehicles that have the driven ego ahead of them in
their lane* (the ego's rear axle within ``lane_half_width_m`` of their heading line, ahead of
them, bumper-to-bumper gap below 150 m): each such vehicle moves along its own logged path at a
speed set by IDM with the driven ego as its leader and its logged speed (along its logged path)
as the desired one, never ahead of where the log has it.  A vehicle the ego never holds up is
exactly replayed; one it held up drives on at its logged speed, behind its logged position, until
it catches up with it (only where the log is faster).  In either, nothing else reacts
(pedestrians and cyclists are replayed, no objects the log does not have), and an object is
shown only while the log has it.

Mission: with a road map the logged ego path is mapped onto the lane graph
(:mod:`redrive.closedloop.mission`); the route and the logged trajectory are handed to every
algorithm before the first frame (``Algorithm.use_mission``): ``idm-planner`` follows the route,
``log-future-planner`` drives the logged trajectory (the expert).

Frames come from :class:`redrive.assembly.frames.FrameAssembler`, paced by one stream
(:func:`redrive.closedloop.log_checks.pace_frames`): the sensor map file's ``driver`` when it
names one; else, when no stage reads a sensor and the log has ground truth (an object-level
run), the ground-truth messages; else its highest-rate LiDAR/camera/radar, else its busiest
sensor (an IMU …), else the ground truth — at most ``rate_hz`` of them: the first frame at
or after each tick of a ``1 / rate_hz`` clock (less a quarter period, for jitter).  The time step between two frames is
the log's (:attr:`LogSimulator.dt_s` is the gap to the next frame).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from redrive.algorithms import StageOutputs
from redrive.assembly.frames import FrameAssembler
from redrive.assembly.sensor_map import (
    SensorMapOverrides,
    infer_sensor_map,
)
from redrive.closedloop.lane_agents import LaneAgents
from redrive.closedloop.log_checks import pace_frames, refuse_unfit_log, topics_text
from redrive.closedloop.mission import logged_mission
from redrive.closedloop.mode import DEFAULT_DEVIATION_M, DEFAULT_DEVIATION_RAD
from redrive.closedloop.path_agents import PathAgent
from redrive.closedloop.placed import at_poses
from redrive.closedloop.simulator import EgoCommand, PathFollower, check_options, choose_command
from redrive.closedloop.synthetic import AgentMode
from redrive.errors import ConfigError
from redrive.geometry import invert, transform_columns
from redrive.io import LogReader
from redrive.io.content import log_goal_lanes
from redrive.maps.index import DRIVABLE_LANE_KINDS, RoadMapIndex
from redrive.motion import IdmParams, idm_acceleration
from redrive.sim.ego import (
    ActuatedEgo,
    BicycleModel,
    EgoGeometry,
    PedalModel,
    TyreLimit,
    pose_matrix,
)
from redrive.types import (
    ControlCommands,
    DetectedObject,
    Frame,
    Mission,
    ObjectClass,
    ObjectColumns,
    PointCloud,
    RoadMap,
    SensorData,
    SensorType,
    VehicleState,
)
from redrive.types._drafts import draft_class

__all__ = [
    "LogSimulator",
    "driven_from_logged",
    "reexpress_cloud",
    "refuse_unfit_log",
]

#: the longest physics step of the driven ego (a longer gap between frames is split).
_MAX_PHYSICS_DT_S = 0.01
#: ``reactive``: beyond this bumper-to-bumper gap (m) the ego does not hold a vehicle up.
_INTERACTION_M = 150.0

#: VehicleState's draft (:mod:`redrive.types._drafts`): the driven ego's states, re-framed
_StateDraft = draft_class(VehicleState)


def _length_m(xy: npt.NDArray[np.float64]) -> float:
    return float(np.hypot(*np.diff(xy, axis=0).T).sum()) if xy.shape[0] > 1 else 0.0


def _pose(state: VehicleState) -> npt.NDArray[np.float64]:
    return pose_matrix(float(state.position[0]), float(state.position[1]), state.heading_rad)


def driven_from_logged(driven: VehicleState, logged: VehicleState) -> npt.NDArray[np.float64]:
    """4×4 ``driven_base_from_logged_base``: planar pose difference of two ego states in one
    frame (x, y, heading; height and tilt are not modelled)."""
    return invert(_pose(driven)) @ _pose(logged)


def reexpress_cloud(
    cloud: PointCloud,
    driven_base_from_logged_base: npt.NDArray[np.float64],
    *,
    sensor_location: tuple[float, float, float],
) -> PointCloud:
    """``cloud`` (sensor frame of the logged car) as the same sensor on the driven car sees the
    same points: into logged base_link (the sensor at ``sensor_location``, base_link's axes),
    through the pose difference, back into the sensor frame.  Channels are kept as they are."""
    mount = np.asarray(sensor_location, dtype=np.float64)
    mat = driven_base_from_logged_base
    xyz = cloud.xyz.astype(np.float64) + mount
    moved = xyz @ mat[:3, :3].T + mat[:3, 3] - mount
    return PointCloud(xyz=np.ascontiguousarray(moved, dtype=np.float32), channels=cloud.channels)


def _reexpress_sensor(data: SensorData, mat: npt.NDArray[np.float64]) -> SensorData:
    if not isinstance(data.data, PointCloud):
        return data  # images, IMU, GNSS …: cannot be re-rendered; passed through unchanged
    moved = reexpress_cloud(data.data, mat, sensor_location=data.sensor_location)
    return dataclasses.replace(data, data=moved)


class LogSimulator:
    """A recorded log as a closed-loop :class:`~redrive.closedloop.simulator.Simulator`.

    Args:
        log: an open log with the ego's pose (see :func:`refuse_unfit_log`).
        tracker: follows the planned path when the pipeline has no control stage.
        agents: ``replay`` or ``reactive`` (see the module text).
        rate_hz: at most this many frames per second.
        duration_s: how much of the log (None: all of it).
        overrides: a sensor map file's content (which topic is which sensor).
        geometry, pedal, tyres, delay_steps: the driven ego (``tyres``: its friction circle,
            ``TyreLimit()`` — μ = 0.9 — by default).
        deviation_threshold_m, deviation_threshold_rad: a frame farther than either from the
            logged ego is flagged ``deviated``.
        lane_half_width_m: ``reactive``: how far off a vehicle's heading line the ego still
            blocks it.
        reads_sensors: whether a stage of the pipeline reads a sensor; when none does (an
            object-level run) and the log has ground truth, the ground truth paces the frames
            (see :func:`~redrive.closedloop.log_checks.pace_frames`).
        road_map: the log's road map (None: it has none): the route of the :attr:`mission`
            (the logged ego path on its lane graph) and the lanes ``reactive`` agents drive.

    Raises:
        ConfigError: the log has no ego pose, no objects for ``reactive``, no sensor to pace
            frames, or fewer than two frames with the ego's pose.
    """

    has_vehicle_state = True

    def __init__(
        self,
        log: LogReader,
        *,
        tracker: PathFollower,
        agents: AgentMode = "replay",
        rate_hz: float = 10.0,
        duration_s: float | None = None,
        overrides: SensorMapOverrides | None = None,
        geometry: EgoGeometry | None = None,
        pedal: PedalModel | None = None,
        tyres: TyreLimit | None = None,
        delay_steps: int = 0,
        deviation_threshold_m: float = DEFAULT_DEVIATION_M,
        deviation_threshold_rad: float = DEFAULT_DEVIATION_RAD,
        lane_half_width_m: float = 1.75,
        reads_sensors: bool = True,
        road_map: RoadMap | None = None,
    ) -> None:
        check_options(agents=agents, rate_hz=rate_hz, delay_steps=delay_steps)
        refuse_unfit_log(log, agents=agents)
        smap = infer_sensor_map(
            log.topics, duration_ns=log.end_ns - log.start_ns, overrides=overrides
        )
        if smap.vehicle_state_topic is None:
            msg = (
                f"{log.path}: closed loop needs the ego's pose (odometry/poses), but no topic "
                f"decodes to one — its topics: {topics_text(log)}"
            )
            raise ConfigError(msg)
        if agents == "reactive" and smap.ground_truth_topic is None:
            msg = (
                f"{log.path}: --agents reactive needs the other road users (ground-truth objects "
                f"or tracks), but no topic decodes to them — its topics: {topics_text(log)}"
            )
            raise ConfigError(msg)
        smap, self.pace_reason = pace_frames(
            log, smap, overrides=overrides, reads_sensors=reads_sensors
        )
        self.log = log
        self.assembler = FrameAssembler(log, sensor_map=smap)
        self.sensors: Mapping[str, SensorType] = {s.sensor_id: s.sensor_type for s in smap.sensors}
        self.has_ground_truth = smap.ground_truth_topic is not None
        self.tracker = tracker
        self.agents: AgentMode = agents
        self.rate_hz = float(rate_hz)
        self.duration_s = duration_s
        self.geometry = geometry or EgoGeometry()
        self.pedal = pedal or PedalModel()
        self.tyres = tyres or TyreLimit()
        self.delay_steps = delay_steps
        self.deviation_threshold_m = float(deviation_threshold_m)
        self.deviation_threshold_rad = float(deviation_threshold_rad)
        self.lane_half_width_m = float(lane_half_width_m)
        self.road_map = road_map
        self.road_index = (
            RoadMapIndex(road_map, lane_kinds=DRIVABLE_LANE_KINDS) if road_map is not None else None
        )
        self._lane_agents: LaneAgents | None = None
        #: the log's ego pose topic has one message, the scenario's start (CommonRoad's planning
        #: problem): the frames after it carry that pose as the logged one (objects are in its
        #: base_link), and there is no logged ego to deviate from (``logged_state`` None)
        pose_topic = log.topics.get(smap.vehicle_state_topic or "")
        self.start_only = pose_topic is not None and pose_topic.count == 1
        self.reset(0)
        #: the route along the lane graph and the logged ego trajectory (``use_mission``)
        self.mission: Mission | None = logged_mission(
            self.assembler,
            index=self.road_index,
            start_ns=self._current.stamp_ns,
            duration_s=duration_s,
            goal_lane_ids=log_goal_lanes(log),
        )
        if (
            agents == "reactive"
            and self.road_index is not None
            and self.mission is not None
            and self.mission.frame_id == self.road_index.road_map.frame_id
        ):
            # the logged vehicles along the lane graph (lane_agents); without a map: along
            # their own logged paths (PathAgent)
            self._lane_agents = LaneAgents.from_log(
                self.assembler,
                mission=self.mission,
                index=self.road_index,
                lane_half_width_m=self.lane_half_width_m,
                stop_ns=None
                if duration_s is None
                else self._current.stamp_ns + round((duration_s + 1.0) * 1e9),
            )

    # -- the Simulator protocol ---------------------------------------------------------------

    def reset(self, seed: int) -> None:
        """Start over from the log's first frame with a pose (``seed`` is unused: the log and
        the bicycle are deterministic)."""
        self._frames = self._selected_frames()
        first = next(self._frames, None)
        second = next(self._frames, None)
        if first is None or second is None:
            msg = (
                f"{self.log.path}: closed loop needs at least two frames with the ego's pose; "
                f"this log has {0 if first is None else 1} (are its pose stamps near its frames'?)"
            )
            raise ConfigError(msg)
        self._current: Frame = first
        self._next: Frame | None = second
        logged = self._logged(first)
        speed = float(np.hypot(logged.velocity[0], logged.velocity[1]))
        steer = 0.0
        if speed > 0.1:
            steer = math.atan(logged.yaw_rate_rad_s * self.geometry.wheelbase_m / speed)
            steer = min(max(steer, -self.geometry.max_steer_rad), self.geometry.max_steer_rad)
        model = BicycleModel(
            self.geometry,
            x_m=float(logged.position[0]),
            y_m=float(logged.position[1]),
            yaw_rad=logged.heading_rad,
            speed_mps=speed,
            steer_rad=steer,
        )
        # the one-frame delay is applied per frame here (a frame spans several physics steps)
        self._ego = ActuatedEgo(model, pedals=self.pedal, delay_steps=0, tyres=self.tyres)
        neutral = ControlCommands(steering_angle_rad=steer)
        self._acting: ControlCommands = neutral  # the command the ego moves under now
        self._queued: ControlCommands = neutral  # with a one-frame delay: the next one
        self.tracker.reset()
        self._index = 0
        #: (frame index, the driven state observe gave there): step reuses it (the ego moves
        #: only in step)
        self._observed: tuple[int, VehicleState] | None = None
        self._agents: dict[int, PathAgent] = {}
        if self._lane_agents is not None:
            self._lane_agents.reset()
        self._update_agents(first, dt_s=0.0)

    def observe(self) -> Frame:
        frame = self._current
        logged = self._logged(frame)
        driven = self._driven_state(frame.stamp_ns, logged)
        self._observed = (self._index, driven)
        mat = driven_from_logged(driven, logged)
        sensors = {sid: _reexpress_sensor(data, mat) for sid, data in frame.sensors.items()}
        objects = frame.ground_truth
        if objects is not None:
            objects = self._objects(objects, driven=driven, moved=mat)
        return dataclasses.replace(
            frame,
            index=self._index,
            sensors=sensors,
            vehicle_state=driven,
            ground_truth=objects,
        )

    @property
    def dt_s(self) -> float:
        """Seconds to the next frame (the log's own gap)."""
        if self._next is None:
            return 1.0 / self.rate_hz
        return (self._next.stamp_ns - self._current.stamp_ns) / 1e9

    def step(self, outputs: StageOutputs, dt_s: float) -> EgoCommand:
        """Apply ``outputs`` and move on to the next frame, ``dt_s`` (= :attr:`dt_s`) later."""
        if self._next is None:
            msg = f"{self.log.path}: closed loop stepped past the last frame"
            raise RuntimeError(msg)
        if abs(dt_s - self.dt_s) > 1e-6:
            msg = (
                f"the log backend steps from frame to frame of the log ({self.dt_s:.6f} s), "
                f"not by {dt_s:.6f} s"
            )
            raise ValueError(msg)
        frame = self._current
        model = self._ego.model
        seen = self._observed
        if seen is not None and seen[0] == self._index:
            state = seen[1]  # observe's (the ego has not moved since)
        else:
            state = self._driven_state(frame.stamp_ns, self._logged(frame))
        chosen = choose_command(
            outputs,
            state=state,
            steer_rad=model.steer_rad,
            tracker=self.tracker,
            dt_s=dt_s,
            stamp_ns=frame.stamp_ns,
        )
        if self.delay_steps:
            self._acting, self._queued = self._queued, chosen.commands
        else:
            self._acting = chosen.commands
        if self._lane_agents is not None:  # the agents move from where everyone is now
            self._step_lane_agents(frame, state, dt_s=dt_s)
        substeps = max(1, math.ceil(dt_s / _MAX_PHYSICS_DT_S - 1e-9))
        self._ego.apply_steps(self._acting, dt_s / substeps, substeps)
        self._current, self._next = self._next, next(self._frames, None)
        self._index += 1
        self._update_agents(self._current, dt_s=dt_s)
        return chosen

    @property
    def done(self) -> bool:
        return self._next is None

    @property
    def logged_state(self) -> VehicleState | None:
        """The logged ego now; None when the log has only its start (:attr:`start_only`)."""
        return None if self.start_only else self._logged(self._current)

    @property
    def paced_by(self) -> str:
        """The stream whose messages make the frames: ``sensor ID (TOPIC)`` or ``ground truth
        (TOPIC)``."""
        smap = self.assembler.sensor_map
        if smap.driver is not None:
            return f"sensor {smap.driver} ({smap.sensor(smap.driver).topic})"
        return f"ground truth ({smap.ground_truth_topic})"

    def describe(self) -> dict[str, Any]:
        smap = self.assembler.sensor_map
        return {
            "backend": "log",
            "level": "object",
            "log": str(Path(self.log.path)),
            "agents": self.agents,
            "rate_hz": self.rate_hz,
            "duration_s": self.duration_s,
            "pace_sensor": smap.driver,
            "paced_by": self.paced_by,
            "pace_reason": self.pace_reason,
            "vehicle_state_topic": smap.vehicle_state_topic,
            "ground_truth_topic": smap.ground_truth_topic,
            "delay_steps": self.delay_steps,
            "deviation_threshold_m": self.deviation_threshold_m,
            "deviation_threshold_rad": self.deviation_threshold_rad,
            "lane_half_width_m": self.lane_half_width_m if self.agents == "reactive" else None,
            "sensors_reexpressed": "point clouds moved by the pose difference; images and "
            "other payloads passed through unchanged",
            "ego": {
                **self._ego.describe(),
                "delay_steps": self.delay_steps,  # applied per frame, not by the ActuatedEgo
                "max_physics_dt_s": _MAX_PHYSICS_DT_S,
            },
            "tracker": self.tracker.describe(),
            "route": None
            if self.mission is None
            else {
                "lanes": list(self.mission.route_lane_ids),
                "length_m": _length_m(self.mission.route_xy),
                "source": self.mission.source,
            },
        }

    # -- frames and the ego -------------------------------------------------------------------

    def _selected_frames(self) -> Iterator[Frame]:
        """The log's frames with a pose, within ``duration_s``, on a ``1 / rate_hz`` clock: the
        first frame at or after each tick (less a quarter period, for jitter), none between."""
        period_ns = round(1e9 / self.rate_hz)
        slack_ns = period_ns // 4
        first_ns: int | None = None
        due_ns = 0
        start: VehicleState | None = None
        for frame in self.assembler.frames():
            if frame.vehicle_state is None:
                if start is None or not self.start_only:
                    continue
                # a scenario's start is its only ego state (CommonRoad): the frames after it
                # keep it (their objects are in its base_link)
                frame = dataclasses.replace(  # noqa: PLW2901
                    frame, vehicle_state=dataclasses.replace(start, stamp_ns=frame.stamp_ns)
                )
            elif start is None:
                start = frame.vehicle_state
            if first_ns is None:
                first_ns = frame.stamp_ns
            elif frame.stamp_ns < due_ns:
                continue
            elif self.duration_s is not None and frame.stamp_ns - first_ns > round(
                self.duration_s * 1e9
            ):
                return
            tick = (frame.stamp_ns - first_ns + slack_ns) // period_ns + 1
            due_ns = first_ns + tick * period_ns - slack_ns
            yield frame

    def _logged(self, frame: Frame) -> VehicleState:
        assert frame.vehicle_state is not None  # _selected_frames keeps only frames with one
        return frame.vehicle_state

    def _driven_state(self, stamp_ns: int, logged: VehicleState) -> VehicleState:
        """The driven ego in the logged state's frame (its height taken from the log)."""
        state = self._ego.state(stamp_ns)
        position = state.position.copy()
        position[2] = logged.position[2]
        position.flags.writeable = False
        # dataclasses.replace(state, frame_id=..., position=position) without VehicleState's
        # second check (the ego's state is one it made; position a read-only float64 (3,))
        driven = _StateDraft()  # (redrive.types._drafts)
        driven.stamp_ns = state.stamp_ns
        driven.frame_id = logged.frame_id
        driven.position = position
        driven.velocity = state.velocity
        driven.acceleration = state.acceleration
        driven.heading_rad = state.heading_rad
        driven.yaw_rate_rad_s = state.yaw_rate_rad_s
        driven.__class__ = VehicleState
        return cast("VehicleState", driven)

    # -- agents -------------------------------------------------------------------------------

    def _step_lane_agents(self, frame: Frame, ego: VehicleState, *, dt_s: float) -> None:
        assert self._lane_agents is not None
        g = self.geometry
        ahead = g.length_m / 2.0 - g.rear_overhang_m  # rear axle → centre
        yaw = ego.heading_rad
        centre = (
            float(ego.position[0]) + ahead * math.cos(yaw),
            float(ego.position[1]) + ahead * math.sin(yaw),
        )
        lights = {light.id: light.state for light in frame.traffic.traffic_lights}
        self._lane_agents.step(
            frame.stamp_ns,
            dt_s=dt_s,
            ego=(centre[0], centre[1], yaw, ego.speed_mps, g.length_m),
            lights=lights,
        )

    def _objects(
        self,
        objects: tuple[DetectedObject, ...],
        *,
        driven: VehicleState,
        moved: npt.NDArray[np.float64],
    ) -> tuple[DetectedObject, ...]:
        """``objects`` (logged base_link) in the driven base frame (``moved``:
        ``driven_base_from_logged_base``, all rows at once), each reactive agent where it is."""
        columns = transform_columns(moved, ObjectColumns.from_objects(objects))
        if self._lane_agents is not None:
            columns = at_poses(columns, self._lane_agents.poses(), driven=driven)
        elif self.agents == "reactive":
            poses = {oid: (*a.pose(), a.speed_mps) for oid, a in self._agents.items()}
            columns = at_poses(columns, poses, driven=driven)
        return tuple(columns.objects())

    def _update_agents(self, frame: Frame, *, dt_s: float) -> None:
        """``reactive``: log the vehicles' new poses, then move each by IDM against the ego."""
        if self.agents != "reactive" or frame.ground_truth is None or self._lane_agents:
            return
        logged = self._logged(frame)
        map_from_base = _pose(logged)
        seen: set[int] = set()
        for obj in frame.ground_truth:
            if obj.object_class is not ObjectClass.VEHICLE or obj.object_id < 0:
                continue
            seen.add(obj.object_id)
            c = map_from_base @ np.array([obj.box.center[0], obj.box.center[1], 0.0, 1.0])
            xy = np.array([c[0], c[1]])
            yaw = math.remainder(obj.box.yaw_rad + logged.heading_rad, math.tau)
            agent = self._agents.get(obj.object_id)
            if agent is None:
                speed = float(np.hypot(obj.velocity[0], obj.velocity[1]))
                self._agents[obj.object_id] = PathAgent(xy, yaw, speed)
                continue
            on_log = agent.s_m >= agent.path_s[-1]
            agent.log(xy, yaw, dt_s)
            self._idm_step(agent, length_m=float(obj.box.size[0]), dt_s=dt_s, on_log=on_log)
        for gone in set(self._agents) - seen:
            del self._agents[gone]  # shown only while the log has it

    def _idm_step(self, agent: PathAgent, *, length_m: float, dt_s: float, on_log: bool) -> None:
        """Advance ``agent`` by ``dt_s``: IDM with the driven ego as leader when the ego is
        ahead of it in its lane (gap below ``_INTERACTION_M``), else on its logged motion (or,
        once held up, at its logged speed behind it) — never ahead of the log."""
        x, y, yaw = agent.pose()
        ego = self._ego.model
        dx, dy = ego.x_m - x, ego.y_m - y
        ahead = math.cos(yaw) * dx + math.sin(yaw) * dy
        side = -math.sin(yaw) * dx + math.cos(yaw) * dy
        # bumper to bumper: the agent's front (half its length ahead of its centre) to the ego's
        # rear bumper (rear_overhang_m behind the rear axle)
        gap = ahead - length_m / 2.0 - self.geometry.rear_overhang_m
        blocked = ahead > 0.0 and abs(side) <= self.lane_half_width_m and gap < _INTERACTION_M
        end = agent.path_s[-1]
        if not blocked and on_log:
            agent.s_m, agent.speed_mps = end, agent.logged_speed_mps  # exactly replayed
            return
        params = IdmParams(desired_speed_mps=max(agent.logged_speed_mps, 0.1))
        if blocked:
            lead = ego.speed_mps * math.cos(math.remainder(ego.yaw_rad - yaw, math.tau))
            accel = idm_acceleration(params, agent.speed_mps, gap_m=gap, leader_speed_mps=lead)
        else:
            accel = idm_acceleration(params, agent.speed_mps)
        accel = max(accel, -params.max_decel_mps2)
        agent.speed_mps = max(0.0, agent.speed_mps + accel * dt_s)
        agent.s_m = min(agent.s_m + agent.speed_mps * dt_s, end)
        if agent.s_m >= end:  # caught up with the log: back on its logged motion
            agent.speed_mps = agent.logged_speed_mps
