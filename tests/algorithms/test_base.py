"""The Algorithm contract: config, input binding, timing, output checks, upstream lookups."""

from __future__ import annotations

import dataclasses
import pickle
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import pytest

from redrive.algorithms import (
    GROUND_TRUTH,
    VEHICLE_STATE,
    Algorithm,
    Role,
    StageOutputs,
    StepStatus,
    check_output,
)
from redrive.errors import AlgorithmError, ConfigError
from redrive.types import (
    Box3D,
    ControlCommands,
    DetectedObject,
    Frame,
    PlannedPath,
    PointCloud,
    SensorData,
    SensorType,
)

SENSORS = {"lidar_top": SensorType.LIDAR, "lidar_rear": SensorType.LIDAR, "cam": SensorType.CAMERA}


class Det(Algorithm):
    """Returns one object per LiDAR point above 1 m."""

    role = Role.PERCEPTION
    inputs = (SensorType.LIDAR, VEHICLE_STATE)
    defaults: Mapping[str, Any] = {"height_m": 1.0, "sleep_s": 0.0}

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        time.sleep(self.config["sleep_s"])
        cloud = self.sensor(frame, SensorType.LIDAR).data
        assert isinstance(cloud, PointCloud)
        tall = cloud.xyz[cloud.xyz[:, 2] > self.config["height_m"]]
        return [DetectedObject(box=Box3D(center=p, size=np.ones(3))) for p in tall]


def frame_with(sensor_id: str) -> Frame:
    xyz = np.array([[1, 0, 0.5], [2, 0, 1.5], [3, 0, 2.5]], dtype=np.float32)
    data = SensorData(
        sensor_id=sensor_id, sensor_type=SensorType.LIDAR, stamp_ns=1, data=PointCloud(xyz=xyz)
    )
    return Frame(stamp_ns=1, index=4, sensors={sensor_id: data})


def test_configure_lays_the_config_over_the_defaults_and_refuses_unknown_keys() -> None:
    det = Det(name="d")
    det.configure({"height_m": 2.0})
    assert dict(det.config) == {"height_m": 2.0, "sleep_s": 0.0}
    with pytest.raises(ConfigError, match=r"unknown config key.*colour"):
        det.configure({"colour": "red"})


def test_a_sensor_type_binds_the_first_sensor_or_the_one_configured() -> None:
    det = Det()
    det.configure({})
    det.bind(SENSORS, extras=[VEHICLE_STATE])
    assert det.bound_inputs[SensorType.LIDAR] == "lidar_rear"  # first by name
    det.configure({"lidar_sensor": "lidar_top"})
    det.bind(SENSORS, extras=[VEHICLE_STATE])
    assert det.bound_inputs[SensorType.LIDAR] == "lidar_top"
    det.configure({"lidar_sensor": "nope"})
    with pytest.raises(ConfigError, match="LIDAR sensor 'nope'"):
        det.bind(SENSORS, extras=[VEHICLE_STATE])


def test_missing_inputs_are_refused_with_what_the_log_has() -> None:
    det = Det()
    det.configure({})
    with pytest.raises(ConfigError, match=r"needs vehicle state.*lidar_top \(LIDAR\)"):
        det.bind(SENSORS)

    class NeedsTruth(Det):
        inputs = (GROUND_TRUTH, "radar_front")

    with pytest.raises(ConfigError, match="needs ground truth"):
        NeedsTruth().bind(SENSORS)
    with pytest.raises(ConfigError, match="sensor 'radar_front'"):
        NeedsTruth().bind(SENSORS, extras=[GROUND_TRUTH])


def test_run_step_times_checks_and_records() -> None:
    det = Det(name="det")
    det.configure({"sleep_s": 0.02})
    det.bind({"lidar_top": SensorType.LIDAR}, extras=[VEHICLE_STATE])
    result = det.run_step(frame_with("lidar_top"), StageOutputs())
    assert result.status is StepStatus.OK
    assert isinstance(result.output, tuple)
    assert len(result.output) == 2
    assert result.latency_ns >= 20_000_000
    assert 0 <= result.cpu_ns < result.latency_ns  # sleeping costs no CPU

    # the sensor dropped out on this frame: an error for this frame, with where
    missing = det.run_step(frame_with("other"), StageOutputs())
    assert missing.status is StepStatus.ERROR
    assert missing.error is not None
    assert missing.error.type == "AlgorithmError"
    assert "frame 4" in missing.error.message
    assert "Traceback" in missing.error.traceback


def test_wrong_output_types_say_what_came_back() -> None:
    with pytest.raises(AlgorithmError, match="must return a list of DetectedObject, got list"):
        check_output(Role.PERCEPTION, [1, "x"], where="w")
    with pytest.raises(AlgorithmError, match="a PlannedPath, got ControlCommands"):
        check_output(Role.PLANNING, ControlCommands(), where="w")
    assert check_output(Role.PERCEPTION, [], where="w") == ()


def test_upstream_gives_the_latest_output_of_a_role_or_a_named_one() -> None:
    obj = DetectedObject(box=Box3D(center=np.zeros(3), size=np.ones(3)))
    path = PlannedPath(stamp_ns=0, waypoints=np.array([[0.0, 0, 0, 0], [1, 0, 0, 1]]))
    up = StageOutputs().merged({"det": (obj,)}, {"det": Role.PERCEPTION})
    up = up.merged({"trk": ()}, {"trk": Role.PERCEPTION})
    up = up.merged({}, {"failed_planner": Role.PLANNING})
    assert up.objects() == ()  # the tracker's, the latest
    assert up.objects("det") == (obj,)
    assert up.path() is None
    assert Role.PLANNING in up.roles.values()  # a planner ran, and failed
    up = up.merged({"p": path}, {"p": Role.PLANNING})
    assert up.path() is path
    # merged() builds a real, frozen StageOutputs (another class's instance given its class)
    assert type(up) is StageOutputs
    with pytest.raises(dataclasses.FrozenInstanceError):
        up.roles = {}  # type: ignore[misc]
    assert pickle.loads(pickle.dumps(up)).roles == up.roles
    with pytest.raises(AlgorithmError, match="is a PERCEPTION algorithm, not PLANNING"):
        up.path("det")
    assert up.commands() is None
