"""A CommonRoad scenario (``*.xml``, formats 2018b and 2020a) read as a log (format
``commonroad``) through ``commonroad-io``.

What is read (``commonroad.common.reader.file_reader_xml.XMLFileReader``; the protobuf reader is
never imported — see the Makefile on commonroad-io's protobuf pin):

- the time steps of ``scenario.dt``: step ``k`` has log time ``round(k · dt · 1e9)`` ns, from the
  first to the last step any obstacle or the planning problem has;
- dynamic obstacles: their ``initial_state`` and ``prediction.trajectory`` states (position,
  orientation, velocity along the heading or ``velocity_y`` when given) as ground truth with
  ``object_id`` = the obstacle id, size from the shape (rectangle length × width, circle
  diameter, polygon extent along its heading); static obstacles at every step;
- the planning problem (the first of the set): its ``initial_state`` is the ego's start (the
  ego's only logged state: CommonRoad records the traffic around a vehicle a planner is to
  drive), its goal (:class:`CommonRoadGoal`);
- traffic lights (2020a): their cycle's state per step (``get_state_at_time_step``); the
  lanelet network as a road map (:mod:`redrive.io.datasets.commonroad_map`).

==================  ==========================  ===============================================
topic               msgtype                     payload (:class:`Decoded` value)
==================  ==========================  ===============================================
``/ego_pose``       ``redrive/VehicleState``    the planning problem's start, frame ``map``, at
                                                its time step only
``/objects``        ``redrive/GroundTruth…``    the obstacles of the step in ``base_link`` **of
                                                the ego's start** (the only ego pose there is)
``/traffic_lights`` ``redrive/TrafficData``     one ``TrafficLight`` per light (``id`` its
                                                traffic light id): red, yellow, green (red-
                                                yellow is RED; inactive is UNKNOWN)
==================  ==========================  ===============================================

CommonRoad is 2-D: boxes have height 0 and z 0.  Frames are made from the ground truth.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from redrive.errors import LogError
from redrive.io.base import ReaderCapabilities
from redrive.io.datasets.native import (
    TOPIC_EGO_POSE,
    TOPIC_OBJECTS,
    TOPIC_TRAFFIC_LIGHTS,
    TRAFFIC_TOPIC_KINDS,
    Loader,
    NativeLogBase,
    NativeStep,
    decoded,
    native_topics,
)
from redrive.types import (
    Box3D,
    DetectedObject,
    LightState,
    ObjectClass,
    RoadMap,
    TrafficData,
    TrafficLight,
    VehicleState,
)

__all__ = ["CLASS_OF_OBSTACLE_TYPE", "CommonRoadGoal", "CommonRoadReader"]

logger = logging.getLogger(__name__)

_HEAD_BYTES = 4096

#: commonroad-io ``ObstacleType`` value → ObjectClass
CLASS_OF_OBSTACLE_TYPE = {
    "car": ObjectClass.VEHICLE,
    "taxi": ObjectClass.VEHICLE,
    "priorityVehicle": ObjectClass.VEHICLE,
    "parkedVehicle": ObjectClass.VEHICLE,
    "truck": ObjectClass.TRUCK,
    "bus": ObjectClass.TRUCK,
    "bicycle": ObjectClass.BICYCLE,
    "motorcycle": ObjectClass.MOTORCYCLE,
    "pedestrian": ObjectClass.PEDESTRIAN,
    "constructionZone": ObjectClass.STATIC,
    "roadBoundary": ObjectClass.STATIC,
    "building": ObjectClass.STATIC,
    "pillar": ObjectClass.STATIC,
    "median_strip": ObjectClass.STATIC,
    "train": ObjectClass.OTHER,
    "unknown": ObjectClass.UNKNOWN,
}
_LIGHT = {
    "red": LightState.RED,
    "redYellow": LightState.RED,
    "yellow": LightState.YELLOW,
    "green": LightState.GREEN,
}


@dataclass(frozen=True, slots=True, kw_only=True)
class CommonRoadGoal:
    """The planning problem's goal.

    Attributes:
        planning_problem_id: its id.
        time_steps: (first, last) time step of the goal's interval, None when it sets none.
        lanelet_ids: the lanelets of the goal position (``lanelets_of_goal_position``).
        positions: each goal state's position shape (commonroad-io objects: ``Rectangle``,
            ``Circle``, ``Polygon``, ``ShapeGroup``), empty when the goal sets none.
    """

    planning_problem_id: int
    time_steps: tuple[int, int] | None
    lanelet_ids: tuple[int, ...]
    positions: tuple[Any, ...]


def _looks_like_commonroad(path: Path) -> bool:
    try:
        with path.open("rb") as fh:
            head = fh.read(_HEAD_BYTES)
    except OSError:
        return False
    head = head.removeprefix(b"\xef\xbb\xbf").lstrip()
    return head.startswith((b"<?xml", b"<commonRoad")) and b"<commonRoad" in head


def _xml_error(path: Path, err: Exception) -> LogError:
    position: tuple[int, int] | None = getattr(err, "position", None)
    where = ""
    if position is not None:
        line, column = position
        offset = None
        try:
            lines = path.read_bytes().split(b"\n")
            offset = sum(len(x) + 1 for x in lines[: line - 1]) + max(column - 1, 0)
        except OSError:
            pass
        where = f" at line {line}, column {column}" + (
            f" (byte {offset})" if offset is not None else ""
        )
    return LogError(f"{path}: not well-formed CommonRoad XML{where} ({err}); restore the file")


def _check_elements(path: Path) -> None:
    """Check what commonroad-io would trip over with an unhelpful error: the XML itself, and
    every lanelet's bounds.

    Raises:
        LogError: naming the line (and byte) of bad XML, or the lanelet id that lacks a bound.
    """
    from lxml import etree

    try:
        root = etree.parse(str(path)).getroot()
    except etree.XMLSyntaxError as err:
        raise _xml_error(path, err) from err
    for lanelet in root.findall("lanelet"):  # the network's (others are references)
        lid = lanelet.get("id")
        for bound in ("leftBound", "rightBound"):
            element = lanelet.find(bound)
            points = [] if element is None else element.findall("point")
            if len(points) < 2:
                msg = (
                    f"{path}: lanelet {lid} (line {lanelet.sourceline}): its {bound} has "
                    f"{len(points)} point(s), a lanelet needs both bounds with >= 2 points"
                )
                raise LogError(msg)


def _size_of(shape: Any) -> tuple[float, float]:
    """(length, width) of a commonroad-io shape, metres."""
    if hasattr(shape, "length") and hasattr(shape, "width"):
        return float(shape.length), float(shape.width)
    if hasattr(shape, "radius"):
        return 2.0 * float(shape.radius), 2.0 * float(shape.radius)
    vertices = getattr(shape, "vertices", None)
    if vertices is not None and len(vertices):
        span = np.ptp(np.asarray(vertices, dtype=np.float64), axis=0)
        return float(span[0]), float(span[1])
    shapes = getattr(shape, "shapes", None)
    if shapes:
        sizes = [_size_of(s) for s in shapes]
        return max(s[0] for s in sizes), max(s[1] for s in sizes)
    return 0.0, 0.0


def _value(value: Any) -> float:
    """A state's value as a number: the midpoint of an uncertain ``Interval`` /
    ``AngleInterval`` (the 2018b files of measured traffic give some as intervals); 0 for None."""
    if value is None:
        return 0.0
    if hasattr(value, "start") and hasattr(value, "end"):
        return 0.5 * (float(value.start) + float(value.end))
    return float(value)


def _position(value: Any) -> tuple[float, float] | None:
    """A state's position: a point, or the centre of an uncertain position region (a shape or
    occupancy: ``center``); None when it has none."""
    if value is None:
        return None
    centre = getattr(value, "center", None)
    if centre is not None:
        value = centre
    if hasattr(value, "x") and hasattr(value, "y"):  # a shapely Point
        return float(value.x), float(value.y)
    xy = np.asarray(value, dtype=np.float64).reshape(-1)
    return (float(xy[0]), float(xy[1])) if xy.size >= 2 else None


def _velocity(state: Any) -> tuple[float, float]:
    """(vx, vy) in the map frame of a CommonRoad state: ``velocity`` along the orientation,
    or ``velocity`` and ``velocity_y`` of a point-mass state."""
    v = _value(getattr(state, "velocity", None))
    vy = getattr(state, "velocity_y", None)
    if vy is not None:
        return v, _value(vy)
    theta = _value(getattr(state, "orientation", None))
    return v * math.cos(theta), v * math.sin(theta)


class CommonRoadReader(NativeLogBase):
    """A CommonRoad scenario file as a :class:`~redrive.io.base.LogReader`.

    Raises (at open):
        LogError: not well-formed XML (line, column and byte named); a lanelet without two
            bounds (its id named); commonroad-io refuses the file; no time step.
    """

    format = "commonroad"
    description = "a CommonRoad scenario (.xml: lanelet network, obstacles, planning problem)"

    @classmethod
    def recognises(cls, path: Path) -> bool:
        return path.is_file() and _looks_like_commonroad(path)

    def __init__(self, path: str | Path, *, strict: bool = True) -> None:
        """``strict``: see :mod:`redrive.io.datasets.native`; the file is checked whole at open."""
        self.path = Path(path)
        self.strict = strict
        _check_elements(self.path)
        try:
            from commonroad.common.reader.file_reader_xml import XMLFileReader
        except ImportError as err:
            msg = (
                f"{self.path}: reading CommonRoad scenarios needs commonroad-io "
                f"({err}); install it: pip install --no-deps commonroad-io plus redrive's "
                "[commonroad] extra (see the Makefile)"
            )
            raise LogError(msg) from err
        # commonroad-io warns of every 2020a intersection element it maps to the new names
        cr_logger = logging.getLogger("commonroad")
        level = cr_logger.level
        cr_logger.setLevel(logging.ERROR)
        try:
            scenario, problems = XMLFileReader(str(self.path)).open()
        except Exception as err:  # commonroad-io raises bare exceptions of every kind
            msg = f"{self.path}: commonroad-io cannot read it ({type(err).__name__}: {err})"
            raise LogError(msg) from err
        finally:
            cr_logger.setLevel(level)
        self.scenario = scenario
        self.planning_problems = problems
        self._dt_s = float(scenario.dt)
        if not self._dt_s > 0:
            msg = f"{self.path}: the scenario's dt is {scenario.dt!r}, must be > 0"
            raise LogError(msg)
        problem = next(iter(problems.planning_problem_dict.values()), None)
        self._problem = problem
        self.goal = None if problem is None else _goal_of(problem)
        last = 0
        for obstacle in scenario.dynamic_obstacles:
            last = max(last, int(obstacle.initial_state.time_step))
            prediction = obstacle.prediction
            if prediction is not None:
                last = max(last, int(prediction.final_time_step))
        first = 0 if problem is None else min(0, int(problem.initial_state.time_step))
        self._time_steps = range(first, last + 1)
        self._start = None if problem is None else self._start_state(problem)
        self._road_map: RoadMap | None = None
        self._steps = self._schedule()
        self._topics = native_topics(self._steps, TRAFFIC_TOPIC_KINDS)
        self.capabilities = ReaderCapabilities(
            message_typed=False,
            has_tf=False,
            has_ground_truth=True,
            has_ego_pose=self._start is not None,
            road_map=True,
            traffic_lights=bool(scenario.lanelet_network.traffic_lights),
            contents=True,
            goal=self.goal is not None,
        )

    def _stamp(self, step: int) -> int:
        return round(step * self._dt_s * 1e9)

    def _start_state(self, problem: Any) -> VehicleState:
        state = problem.initial_state
        xy = _position(state.position)
        if xy is None:
            msg = (
                f"{self.path}: planning problem {problem.planning_problem_id} has no start position"
            )
            raise LogError(msg)
        x, y = xy
        vx, vy = _velocity(state)
        return VehicleState(
            stamp_ns=self._stamp(int(state.time_step)),
            frame_id="map",
            position=np.array([x, y, 0.0]),
            velocity=np.array([vx, vy, 0.0]),
            heading_rad=_value(state.orientation),
            yaw_rate_rad_s=_value(getattr(state, "yaw_rate", None)),
        )

    def _schedule(self) -> list[NativeStep]:
        lights = self.scenario.lanelet_network.traffic_lights
        out = []
        for k in self._time_steps:
            t = self._stamp(k)
            messages: list[tuple[str, Loader]] = []
            if self._start is not None and self._start.stamp_ns == t:
                messages.append((TOPIC_EGO_POSE, _const(t, "map", self._start)))
            messages.append((TOPIC_OBJECTS, self._objects_loader(k)))
            if lights:
                states = tuple(
                    TrafficLight(
                        id=str(light.traffic_light_id),
                        state=_LIGHT.get(light.get_state_at_time_step(k).value, LightState.UNKNOWN),
                    )
                    for light in lights
                )
                messages.append(
                    (TOPIC_TRAFFIC_LIGHTS, _const(t, "map", TrafficData(traffic_lights=states)))
                )
            out.append(NativeStep(stamp_ns=t, messages=tuple(messages)))
        return out

    def _objects_loader(self, step: int) -> Loader:
        def load() -> Any:
            return decoded(self._stamp(step), "base_link", self.objects_at(step))

        return load

    def objects_at(self, step: int) -> tuple[DetectedObject, ...]:
        """The obstacles at ``step`` in the base_link of the ego's start (the map frame's axes
        at the origin when the file has no planning problem)."""
        origin = np.zeros(2) if self._start is None else self._start.position[:2]
        yaw0 = 0.0 if self._start is None else self._start.heading_rad
        c, s = math.cos(yaw0), math.sin(yaw0)
        out = []
        obstacles = [(o, o.state_at_time(step)) for o in self.scenario.dynamic_obstacles]
        obstacles += [(o, o.initial_state) for o in self.scenario.static_obstacles]
        for obstacle, state in obstacles:
            xy = None if state is None else _position(getattr(state, "position", None))
            if xy is None:
                continue
            dx, dy = xy[0] - float(origin[0]), xy[1] - float(origin[1])
            vx, vy = _velocity(state)
            yaw = math.remainder(_value(getattr(state, "orientation", None)) - yaw0, math.tau)
            length, width = _size_of(obstacle.obstacle_shape)
            out.append(
                DetectedObject(
                    object_id=int(obstacle.obstacle_id),
                    object_class=CLASS_OF_OBSTACLE_TYPE.get(
                        obstacle.obstacle_type.value, ObjectClass.OTHER
                    ),
                    confidence=1.0,
                    box=Box3D(
                        center=np.array([c * dx + s * dy, -s * dx + c * dy, 0.0]),
                        size=np.array([length, width, 0.0]),
                        yaw_rad=yaw,
                    ),
                    velocity=np.array([c * vx + s * vy, -s * vx + c * vy, 0.0]),
                    orientation=np.array([yaw, 0.0, 0.0]),
                )
            )
        return tuple(out)

    def contents(self) -> dict[str, int | str]:
        sc = self.scenario
        network = sc.lanelet_network
        out: dict[str, int | str] = {
            "scenario": str(sc.scenario_id),
            "dynamic obstacles": len(sc.dynamic_obstacles),
            "static obstacles": len(sc.static_obstacles),
            "time steps": len(self._time_steps),
            "dt": f"{self._dt_s} s",
            "lanelets": len(network.lanelets),
            "traffic signs": len(network.traffic_signs),
            "traffic lights": len(network.traffic_lights),
            "intersections": len(network.intersections),
            "planning problems": len(self.planning_problems.planning_problem_dict),
        }
        if self.goal is not None:
            goal = self.goal
            out["goal"] = (
                f"planning problem {goal.planning_problem_id}: "
                + (
                    f"time steps {goal.time_steps[0]}-{goal.time_steps[1]}"
                    if goal.time_steps
                    else "any time"
                )
                + (
                    f", lanelets {', '.join(map(str, goal.lanelet_ids))}"
                    if goal.lanelet_ids
                    else ""
                )
            )
        return out

    def goal_lane_ids(self) -> tuple[str, ...]:
        """The goal's lanelets (``lanelets_of_goal_position``), else those holding the centre
        of a goal position's shape (``LaneletNetwork.find_lanelet_by_position``)."""
        if self.goal is None:
            return ()
        ids = list(self.goal.lanelet_ids)
        if not ids:
            network = self.scenario.lanelet_network
            for shape in self.goal.positions:
                centre = getattr(shape, "center", None)
                if centre is not None:
                    found = network.find_lanelet_by_position([np.asarray(centre, dtype=float)])
                    ids.extend(int(i) for i in (found[0] if found else []))
        return tuple(str(i) for i in dict.fromkeys(ids))

    def road_map(self) -> RoadMap | None:
        """The lanelet network in the road-map model."""
        if self._road_map is None:
            from redrive.io.datasets.commonroad_map import road_map_from_lanelets

            self._road_map = road_map_from_lanelets(self.scenario, source=str(self.path))
        return self._road_map


def _goal_of(problem: Any) -> CommonRoadGoal:
    goal = problem.goal
    first = last = None
    positions = []
    for state in goal.state_list:
        interval = getattr(state, "time_step", None)
        if interval is not None and hasattr(interval, "start"):
            first = int(interval.start) if first is None else min(first, int(interval.start))
            last = int(interval.end) if last is None else max(last, int(interval.end))
        position = getattr(state, "position", None)
        if position is not None:
            positions.append(position)
    lanelets = sorted(
        {int(i) for ids in (goal.lanelets_of_goal_position or {}).values() for i in ids}
    )
    return CommonRoadGoal(
        planning_problem_id=int(problem.planning_problem_id),
        time_steps=None if first is None or last is None else (first, last),
        lanelet_ids=tuple(lanelets),
        positions=tuple(positions),
    )


def _const(stamp_ns: int, frame_id: str, value: Any) -> Loader:
    return lambda: decoded(stamp_ns, frame_id, value)
