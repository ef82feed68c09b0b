"""A Waymo Open Motion Dataset ``Scenario`` TFRecord read as a log (format ``womd``), without
TensorFlow.

The file's records are checked (:mod:`redrive.io.datasets.tfrecord`) and the first is decoded as
``waymo.open_dataset.Scenario`` (:mod:`redrive.io.datasets.womd_proto`; a file of several
scenarios — WOMD's training shards — reads its first, and ``redrive info`` says how many it
holds).  What the scenario holds, as its ``scenario.proto`` documents it:

- ``timestamps_seconds`` (91 steps at 10 Hz: 11 past, the current one at
  ``current_time_index``, 80 future) — step ``k`` has log time ``round(t_k · 1e9)`` ns;
- ``tracks``: every agent's ``ObjectState`` per step (box centre, length/width/height, heading,
  velocity, ``valid``); ``sdc_track_index`` is the autonomous vehicle (the ego);
  ``objects_of_interest`` and ``tracks_to_predict`` (:class:`WomdScenarioInfo`);
- ``dynamic_map_states``: per step the traffic signal state of each lane it controls;
- ``map_features``: the roadgraph (:mod:`redrive.io.datasets.womd_map`).

Every step where the SDC is valid yields, at its stamp:

====================  ==========================  =============================================
topic                 msgtype                     payload (:class:`Decoded` value)
====================  ==========================  =============================================
``/ego_pose``         ``redrive/VehicleState``    the SDC's state, frame ``map`` (velocity
                                                  given; yaw rate from neighbouring headings)
``/objects``          ``redrive/GroundTruth…``    every other agent valid at the step, in
                                                  ``base_link`` (the SDC's box centre and
                                                  heading: WOMD does not say where its rear
                                                  axle is); ``object_id`` is the track ``id``
``/traffic_lights``   ``redrive/TrafficData``     one ``TrafficLight`` per lane state: ``id``
                                                  is the lane's feature id, the state
                                                  STOP→RED, CAUTION→YELLOW, GO→GREEN (arrows
                                                  and flashing alike), UNKNOWN
====================  ==========================  =============================================

There are no sensors: frames are made from the ground truth (one per step).  Classes: vehicle →
VEHICLE, pedestrian → PEDESTRIAN, cyclist → BICYCLE, other → OTHER, unset → UNKNOWN.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple, cast

import numpy as np
import numpy.typing as npt

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
from redrive.io.datasets.tfrecord import looks_like_tfrecord, read_tfrecords
from redrive.io.datasets.womd_proto import LANE_STATE_NAMES, scenario_class
from redrive.io.datasets.womd_wire import map_polylines, track_states
from redrive.io.datasets.womd_wire_map import LaneStates, lane_states, map_lanes
from redrive.types import (
    DetectedObject,
    LightState,
    ObjectClass,
    ObjectColumns,
    RoadMap,
    TrafficData,
    TrafficLight,
    VehicleState,
)
from redrive.types._drafts import draft_class

__all__ = [
    "TOPIC_EGO_POSE",
    "TOPIC_OBJECTS",
    "TOPIC_TRAFFIC_LIGHTS",
    "WomdReader",
    "WomdScenarioInfo",
    "WomdTracks",
    "light_state_of",
]

logger = logging.getLogger(__name__)

_CLASSES = (
    ObjectClass.UNKNOWN,
    ObjectClass.VEHICLE,
    ObjectClass.PEDESTRIAN,
    ObjectClass.BICYCLE,
    ObjectClass.OTHER,
)


def light_state_of(state: int) -> LightState:
    """A ``TrafficSignalLaneState.State`` number as a :class:`LightState`."""
    name = LANE_STATE_NAMES[state] if 0 <= state < len(LANE_STATE_NAMES) else ""
    for word, light in (("STOP", LightState.RED), ("CAUTION", LightState.YELLOW)):
        if name.endswith(word):
            return light
    return LightState.GREEN if name.endswith("_GO") else LightState.UNKNOWN


@dataclass(frozen=True, slots=True, kw_only=True)
class WomdTracks:
    """Every agent's states, ``(num_objects, num_steps)`` as in Waymax.

    Attributes:
        ids: (N,) int64 track ids.
        object_types: (N,) int64 ``Track.ObjectType`` numbers.
        xyz: (N, T, 3) float64 box centres, metres, map frame.
        lwh: (N, T, 3) float64 length, width, height, metres.
        heading_rad: (N, T) float64.
        velocity_mps: (N, T, 2) float64, map frame.
        valid: (N, T) bool.
    """

    ids: npt.NDArray[np.int64]
    object_types: npt.NDArray[np.int64]
    xyz: npt.NDArray[np.float64]
    lwh: npt.NDArray[np.float64]
    heading_rad: npt.NDArray[np.float64]
    velocity_mps: npt.NDArray[np.float64]
    valid: npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True, kw_only=True)
class WomdScenarioInfo:
    """What the scenario says of its agents.

    Attributes:
        scenario_id: the scenario's id.
        sdc_track_id: the track id of the autonomous vehicle (the ego).
        current_time_index: the step that is "now" (10: 1.1 s of history).
        objects_of_interest: track ids the scenario marks as interesting.
        tracks_to_predict: (track id, difficulty 0/1/2) of the tracks the benchmark scores.
        scenarios_in_file: how many scenarios the file holds (the first is read).
    """

    scenario_id: str
    sdc_track_id: int
    current_time_index: int
    objects_of_interest: tuple[int, ...]
    tracks_to_predict: tuple[tuple[int, int], ...]
    scenarios_in_file: int


def _tracks_of(scenario: Any, *, where: str, data: bytes) -> WomdTracks:
    """The tracks of ``scenario``, decoded from the record ``data``; their states read from the
    bytes in one pass (:func:`~redrive.io.datasets.womd_wire.track_states`), else (a record
    that walk does not take) one attribute at a time."""
    steps = len(scenario.timestamps_seconds)
    n = len(scenario.tracks)
    walked = track_states(data)
    counts = walked[1].tolist() if walked is not None else [len(t.states) for t in scenario.tracks]
    for i, track in enumerate(scenario.tracks):
        if counts[i] != steps:
            msg = (
                f"{where}: track {i} (id {track.id}) has {counts[i]} states for "
                f"{steps} timestamps; the scenario is damaged"
            )
            raise LogError(msg)
    if walked is not None:
        rows = walked[0].reshape(n, steps, 10)
    else:
        # one flat list (numpy converts it far faster than a list of rows)
        rows = np.array(
            [
                v
                for track in scenario.tracks
                for s in track.states
                for v in (
                    s.center_x,
                    s.center_y,
                    s.center_z,
                    s.length,
                    s.width,
                    s.height,
                    s.heading,
                    s.velocity_x,
                    s.velocity_y,
                    s.valid,
                )
            ],
            dtype=np.float64,
        ).reshape(n, steps, 10)
    xyz = np.ascontiguousarray(rows[:, :, 0:3])
    lwh = np.ascontiguousarray(rows[:, :, 3:6])
    heading = np.ascontiguousarray(rows[:, :, 6])
    vel = np.ascontiguousarray(rows[:, :, 7:9])
    valid = rows[:, :, 9] > 0
    bad = valid & ~np.all(np.isfinite(rows[:, :, 0:9]), axis=2)
    if bad.any():
        i, k = (int(v) for v in np.argwhere(bad)[0])
        msg = f"{where}: track {i} step {k} is valid but holds a value that is not finite"
        raise LogError(msg)
    return WomdTracks(
        ids=np.array([t.id for t in scenario.tracks], dtype=np.int64),
        object_types=np.array([t.object_type for t in scenario.tracks], dtype=np.int64),
        xyz=xyz,
        lwh=np.maximum(lwh, 0.0),
        heading_rad=heading,
        velocity_mps=vel,
        valid=valid,
    )


class WomdReader(NativeLogBase):
    """A Waymo Open Motion ``Scenario`` TFRecord as a :class:`~redrive.io.base.LogReader`.

    Raises (at open):
        LogError: a record is cut off or its CRC does not match (record index and byte offset
            named); the record is not a Scenario; a track is inconsistent.
    """

    format = "womd"
    description = "a Waymo Open Motion Dataset Scenario TFRecord (scenario/*.tfrecord*)"

    @classmethod
    def recognises(cls, path: Path) -> bool:
        return cls.recognised(path) is not None

    @classmethod
    def recognised(cls, path: Path) -> FirstRecord | None:
        """What recognising ``path`` found (its first record, decoded), or None when it is no
        WOMD scenario file: :func:`~redrive.io.readers.open_log` hands it to the constructor, so
        the record is not decoded twice."""
        if not path.is_file() or not looks_like_tfrecord(path):
            return None
        try:
            first = next(read_tfrecords(path, limit=1))
        except (LogError, StopIteration):
            return FirstRecord(
                None, None
            )  # a TFRecord whose first record is damaged: opening says where
        scenario = _parse(first.data)
        return None if scenario is None else FirstRecord(first.data, scenario)

    def __init__(
        self, path: str | Path, *, strict: bool = True, recognised: object | None = None
    ) -> None:
        """``strict``: see :mod:`redrive.io.datasets.native`; the file is checked whole at open.
        ``recognised``: what :meth:`recognised` returned for ``path`` (used when the file's first
        record is still the bytes it decoded)."""
        self.path = Path(path)
        self.strict = strict
        first = None
        count = 0
        for record in read_tfrecords(self.path):  # every record checked, the first kept
            first = first or record
            count += 1
        if first is None:
            msg = f"{self.path}: holds no TFRecord record; restore it"
            raise LogError(msg)
        kept = recognised if isinstance(recognised, FirstRecord) else None
        if kept is not None and kept.data == first.data:
            scenario = kept.scenario
        else:
            scenario = _parse(first.data)
        where = f"{self.path}: record 0 at byte {first.offset}"
        if scenario is None:
            msg = f"{where}: not a waymo.open_dataset.Scenario protobuf (or a damaged one)"
            raise LogError(msg)
        if count > 1:
            logger.warning(
                "%s holds %d scenarios; the first (%s) is read",
                self.path,
                count,
                scenario.scenario_id,
            )
        self._scenario = scenario
        self._record = first.data  # the map's points are read from it when asked
        self.tracks = _tracks_of(scenario, where=where, data=first.data)
        steps = len(scenario.timestamps_seconds)
        sdc = int(scenario.sdc_track_index)
        if not 0 <= sdc < len(scenario.tracks):
            msg = f"{where}: sdc_track_index {sdc} names no track (it has {len(scenario.tracks)})"
            raise LogError(msg)
        ids = self.tracks.ids
        self.info = WomdScenarioInfo(
            scenario_id=str(scenario.scenario_id),
            sdc_track_id=int(ids[sdc]),
            current_time_index=int(scenario.current_time_index),
            objects_of_interest=tuple(int(i) for i in scenario.objects_of_interest),
            tracks_to_predict=tuple(
                (int(ids[p.track_index]), int(p.difficulty))
                for p in scenario.tracks_to_predict
                if 0 <= p.track_index < len(ids)
            ),
            scenarios_in_file=count,
        )
        self._sdc = sdc
        #: each track's ObjectClass (its Track.ObjectType number's)
        self._classes = tuple(
            _CLASSES[k] if 0 <= k < len(_CLASSES) else ObjectClass.UNKNOWN
            for k in self.tracks.object_types.tolist()
        )
        self._stamps = [round(float(t) * 1e9) for t in scenario.timestamps_seconds]
        if any(b <= a for a, b in zip(self._stamps, self._stamps[1:], strict=False)):
            msg = f"{where}: timestamps_seconds do not increase"
            raise LogError(msg)
        #: the lane states of dynamic_map_states read from the record (None: the walk gave up)
        self._lane_states = lane_states(first.data)
        self._lights = _lights_of(scenario, self._lane_states)
        self._road_map: RoadMap | None = None
        #: each step's objects once decoded (immutable): a closed loop reads the tracks whole
        #: before its first frame, then frame by frame
        self._objects: dict[int, tuple[DetectedObject, ...]] = {}
        self._steps = self._schedule(steps)
        self._topics = native_topics(self._steps, TRAFFIC_TOPIC_KINDS)
        self.capabilities = ReaderCapabilities(
            message_typed=False,
            has_tf=False,
            has_ground_truth=True,
            has_ego_pose=True,
            road_map=True,
            traffic_lights=bool(self._lights),
            contents=True,
        )

    def _schedule(self, steps: int) -> list[NativeStep]:
        tr, sdc = self.tracks, self._sdc
        heading = tr.heading_rad[sdc]
        out = []
        for k in range(steps):
            t = self._stamps[k]
            messages: list[tuple[str, Loader]] = []
            if tr.valid[sdc, k]:
                lo, hi = max(k - 1, 0), min(k + 1, steps - 1)
                while lo < k and not tr.valid[sdc, lo]:
                    lo += 1
                while hi > k and not tr.valid[sdc, hi]:
                    hi -= 1
                dt_s = (self._stamps[hi] - self._stamps[lo]) * 1e-9
                rate = math.remainder(heading[hi] - heading[lo], math.tau) / dt_s if dt_s else 0.0
                state = _ego_state(
                    t,
                    position=tr.xyz[sdc, k].copy(),
                    velocity=np.array([*tr.velocity_mps[sdc, k], 0.0]),
                    heading_rad=float(heading[k]),
                    yaw_rate_rad_s=float(rate),
                )
                messages.append((TOPIC_EGO_POSE, _const(t, "map", state)))
                messages.append((TOPIC_OBJECTS, self._objects_loader(k)))
            if k < len(self._lights):
                messages.append(
                    (
                        TOPIC_TRAFFIC_LIGHTS,
                        _const(t, "map", TrafficData(traffic_lights=self._lights[k])),
                    )
                )
            out.append(NativeStep(stamp_ns=t, messages=tuple(messages)))
        return out

    def _objects_loader(self, k: int) -> Loader:
        def load() -> Any:
            objects = self._objects.get(k)
            if objects is None:
                objects = self._objects[k] = self.objects_at(k)
            return decoded(self._stamps[k], "base_link", objects)

        return load

    def objects_at(self, step: int) -> tuple[DetectedObject, ...]:
        """The agents (all but the SDC) valid at ``step``, in the SDC's base_link."""
        tr, sdc = self.tracks, self._sdc
        others = np.flatnonzero(tr.valid[:, step])
        others = others[others != sdc]
        yaw0 = float(tr.heading_rad[sdc, step])
        c, s = math.cos(yaw0), math.sin(yaw0)
        rot_t = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # base_from_map rotation
        rel = (tr.xyz[others, step] - tr.xyz[sdc, step]) @ rot_t.T
        vel3 = np.concatenate([tr.velocity_mps[others, step], np.zeros((len(others), 1))], axis=1)
        vel = vel3 @ rot_t.T
        yaw = np.array(
            [math.remainder(h - yaw0, math.tau) for h in tr.heading_rad[others, step].tolist()]
        )
        classes = tuple(map(self._classes.__getitem__, others.tolist()))
        orientation = np.zeros((len(others), 3))
        orientation[:, 0] = yaw
        # fresh float64 / int64 arrays of the columns' shapes; the valid states' numbers were
        # checked finite at open and the sizes are ≥ 0 (what DetectedObject.many would check)
        return tuple(
            ObjectColumns.trusted(
                object_id=tr.ids[others],
                object_class=classes,
                center_m=rel,
                size_m=tr.lwh[others, step],
                yaw_rad=yaw,
                velocity_mps=vel,
                orientation_rad=orientation,
            ).objects()
        )

    def contents(self) -> dict[str, int | str]:
        info = self.info
        features: dict[str, int] = {}
        for feature in self._scenario.map_features:
            kind = feature.WhichOneof("feature_data") or "unset"
            features[kind] = features.get(kind, 0) + 1
        out: dict[str, int | str] = {
            "scenario": info.scenario_id,
            "agents": len(self.tracks.ids),
            "steps": len(self._stamps),
            "SDC": f"track {info.sdc_track_id} (index {self._sdc})",
            "current step": f"{info.current_time_index} (0-based)",
            "tracks to predict": len(info.tracks_to_predict),
            "objects of interest": len(info.objects_of_interest),
            "steps with traffic signal states": len(self._lights),
        }
        for kind, label in (
            ("lane", "lanes"),
            ("road_line", "road lines"),
            ("road_edge", "road edges"),
            ("stop_sign", "stop signs"),
            ("crosswalk", "crosswalks"),
            ("speed_bump", "speed bumps"),
            ("driveway", "driveways"),
        ):
            if features.get(kind):
                out[label] = features[kind]
        if info.scenarios_in_file > 1:
            out["scenarios in the file (the first is read)"] = info.scenarios_in_file
        return out

    def road_map(self) -> RoadMap | None:
        """The scenario's roadgraph in the road-map model."""
        if self._road_map is None:
            from redrive.io.datasets.womd_map import road_map_from_scenario

            self._road_map = road_map_from_scenario(
                self._scenario,
                source=str(self.path),
                points=map_polylines(self._record),
                lane_states=self._lane_states,
                lanes_walked=map_lanes(self._record),
            )
        return self._road_map


class FirstRecord(NamedTuple):
    """What :meth:`WomdReader.recognised` found: the file's first record and its Scenario (both
    None when that record is damaged)."""

    data: bytes | None
    scenario: Any | None


#: each ``TrafficSignalLaneState.State`` number's :class:`LightState` (light_state_of, once)
_LIGHT_STATES = tuple(light_state_of(k) for k in range(len(LANE_STATE_NAMES)))


def _lights_of(scenario: Any, walked: LaneStates | None) -> list[tuple[TrafficLight, ...]]:
    """Each step's lights (``dynamic_map_states``; ``walked``: their lane states read from the
    record, None: from ``scenario``): one :class:`TrafficLight` per lane state; a lane showing
    the same state at several steps shares one (frozen) instance."""
    rows: Iterable[tuple[int, int, int]]
    if walked is None:
        steps = len(scenario.dynamic_map_states)
        rows = [
            (k, int(lane_state.lane), int(lane_state.state))
            for k, state in enumerate(scenario.dynamic_map_states)
            for lane_state in state.lane_states
        ]
    else:
        step, lane, number, _, _, steps = walked
        rows = zip(step.tolist(), lane.tolist(), number.tolist(), strict=True)
    made: dict[tuple[int, int], TrafficLight] = {}
    out: list[list[TrafficLight]] = [[] for _ in range(steps)]
    for k, lane_id, state_number in rows:
        light = made.get((lane_id, state_number))
        if light is None:
            kind = (
                _LIGHT_STATES[state_number]
                if 0 <= state_number < len(_LIGHT_STATES)
                else LightState.UNKNOWN
            )
            light = made[lane_id, state_number] = TrafficLight(id=str(lane_id), state=kind)
        out[k].append(light)
    return [tuple(lights) for lights in out]


def _parse(data: bytes) -> Any | None:
    from google.protobuf.message import DecodeError

    scenario = scenario_class()()
    try:
        scenario.ParseFromString(data)
    except DecodeError:
        return None
    if not scenario.timestamps_seconds or not scenario.tracks:
        return None
    return scenario


def _ego_state(
    stamp_ns: int,
    *,
    position: npt.NDArray[np.float64],
    velocity: npt.NDArray[np.float64],
    heading_rad: float,
    yaw_rate_rad_s: float,
) -> VehicleState:
    """``VehicleState(stamp_ns=…, frame_id="map", …)`` of the SDC's numbers (fresh float64 (3,)
    arrays, checked finite at open), built through its draft (:mod:`redrive.types._drafts`):
    what its checks would make — read-only views, zero acceleration — without them."""
    state = _StateDraft()
    state.stamp_ns = int(stamp_ns)
    state.frame_id = "map"
    for name, vector in (
        ("position", position),
        ("velocity", velocity),
        ("acceleration", np.zeros(3, dtype=np.float64)),
    ):
        view = vector.view()
        view.flags.writeable = False
        setattr(state, name, view)
    state.heading_rad = heading_rad
    state.yaw_rate_rad_s = yaw_rate_rad_s
    state.__class__ = VehicleState
    return cast("VehicleState", state)


#: VehicleState's draft (:mod:`redrive.types._drafts`): the SDC's logged states
_StateDraft = draft_class(VehicleState)


def _const(stamp_ns: int, frame_id: str, value: Any) -> Loader:
    return lambda: decoded(stamp_ns, frame_id, value)
