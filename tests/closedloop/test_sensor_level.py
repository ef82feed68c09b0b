"""Sensor-level closed loop: the rig rendered from the driven ego.

Sensors follow the pose: driven the way the log was driven, the closed loop renders the clouds and
images ``redrive synth`` recorded; started 1 m to the left, it sees the scene 1 m to the right.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree

from redrive.algorithms import StageOutputs
from redrive.assembly.frames import FrameAssembler
from redrive.cli.main import main
from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.closedloop.synthetic import SyntheticSimulator
from redrive.closedloop.tracker import LqrTracker
from redrive.config import pipeline_from_plugins, reference_pipeline
from redrive.errors import ConfigError, SimulationError
from redrive.io import open_log
from redrive.io.mcap.writer import McapWriter
from redrive.io.ros.decoders import decode
from redrive.results import RunStatus, open_run
from redrive.sim.rig import rig_from_mapping
from redrive.sim.scenario import Scenario, load_scenario
from redrive.sim.synth import (
    EGO_STATE_TOPIC,
    GROUND_TRUTH_TOPIC,
    camera_info_topic,
    sensor_topic,
    synthesize,
)
from redrive.types import (
    ControlCommands,
    Frame,
    GnssFix,
    Image,
    Imu,
    PointCloud,
    Role,
    SensorData,
    SensorType,
)
from tests.closedloop import plugins

# Every sensor kind, a 16-beam LiDAR and a small camera keep it quick.
SMALL_RIG: dict[str, Any] = {
    "lidar_top": {"kind": "lidar", "preset": "VLP-16", "xyz": [1.2, 0.0, 1.9], "rate_hz": 10},
    "camera_front": {
        "kind": "camera",
        "xyz": [1.5, 0.0, 1.6],
        "rate_hz": 10,
        "width": 320,
        "height": 180,
        "fx": 250.0,
        "fy": 250.0,
    },
    "imu": {"kind": "imu", "xyz": [0.0, 0.0, 0.5], "rate_hz": 100},
    "gnss": {"kind": "gnss", "xyz": [0.0, 0.0, 1.8], "rate_hz": 10},
    "odom": {"kind": "odometry", "rate_hz": 50},
    "lidar_2d": {"kind": "lidar_2d", "preset": "UTM-30LX", "xyz": [3.7, 0.0, 0.5], "rate_hz": 20},
}
STRAIGHT_ON = StageOutputs(
    outputs={"hold": ControlCommands(throttle=0.0, brake=0.0, steering_angle_rad=0.0)},
    roles={"hold": Role.CONTROL},
)


def _small(name: str, duration_s: float) -> Scenario:
    return dataclasses.replace(load_scenario(name), rig=SMALL_RIG, duration_s=duration_s)


class ScriptedEgo(SyntheticSimulator):
    """The closed loop with its ego left to the scenario's own driver: commands that reproduce
    the logged motion exactly."""

    def _hand_over(self) -> None:
        pass


class StartsOneMetreLeft(SyntheticSimulator):
    """The closed loop with its ego placed 1 m to the left of the scenario's start."""

    def _hand_over(self) -> None:
        model = self._world.ego_model
        yaw = model.yaw_rad
        self._world.place_ego(x_m=model.x_m - np.sin(yaw), y_m=model.y_m + np.cos(yaw), yaw_rad=yaw)
        super()._hand_over()


def _drive(sim: SyntheticSimulator, outputs: StageOutputs) -> list[Frame]:
    """Observe, apply ``outputs``, until the simulator is done (as ClosedLoopMode does)."""
    frames = []
    while True:
        frames.append(sim.observe())
        sim.step(outputs, sim.dt_s)
        if sim.done:
            return frames


def _assert_same_data(a: SensorData, b: SensorData) -> None:
    assert (a.stamp_ns, a.frame_id, a.sensor_type) == (b.stamp_ns, b.frame_id, b.sensor_type)
    da, db = a.data, b.data
    assert type(da) is type(db)
    if isinstance(da, PointCloud):
        assert isinstance(db, PointCloud)
        assert len(da) > 100
        np.testing.assert_allclose(da.xyz, db.xyz, atol=1e-5)
        assert sorted(da.channels) == sorted(db.channels)
        for name, values in da.channels.items():
            assert values.dtype == db.channels[name].dtype
            np.testing.assert_allclose(values, db.channels[name], atol=1e-4)
    elif isinstance(da, Image):
        assert isinstance(db, Image)
        assert da.encoding == db.encoding
        np.testing.assert_array_equal(da.pixels, db.pixels)
    elif isinstance(da, Imu):
        assert isinstance(db, Imu)
        np.testing.assert_allclose(da.linear_acceleration, db.linear_acceleration, atol=1e-9)
        np.testing.assert_allclose(da.angular_velocity, db.angular_velocity, atol=1e-9)
        np.testing.assert_allclose(da.orientation, db.orientation, atol=1e-9)
    else:
        assert isinstance(da, GnssFix)
        assert isinstance(db, GnssFix)
        assert (da.latitude_deg, da.longitude_deg, da.altitude_m) == pytest.approx(
            (db.latitude_deg, db.longitude_deg, db.altitude_m), abs=1e-9
        )


def test_driven_as_logged_the_closed_loop_renders_the_logged_clouds_and_images(
    tmp_path: Path,
) -> None:
    scenario = _small("cut_in", duration_s=1.5)
    log = synthesize(scenario, tmp_path / "cut_in.mcap").path
    sim = ScriptedEgo(scenario, tracker=LqrTracker(), level="sensor")
    frames = _drive(sim, StageOutputs(outputs={}, roles={}))
    assert [f.index for f in frames] == list(range(14))  # 0.1 s … 1.4 s: after the first sweep
    assert frames[0].stamp_ns == scenario.start_stamp_ns + 100_000_000

    with open_log(log) as reader:
        logged = list(FrameAssembler(reader).frames())
        topics = {s.sensor_id: s.topic for s in FrameAssembler(reader).sensor_map.sensors}
        by_stamp: dict[tuple[str, int], Any] = {}
        for message in reader.messages(topics=list(topics.values())):
            decoded = decode(message, reader.deserialize)
            by_stamp[(message.topic, decoded.stamp_ns)] = decoded
    logged_at = {f.stamp_ns: f for f in logged}

    # the frames look like the log's: sensor ids, types, frames, mounts, image sizes
    assert dict(sim.sensors) == {k: s.sensor_type for k, s in logged[0].sensors.items()}
    for frame in frames:
        twin = logged_at[frame.stamp_ns]
        assert sorted(frame.sensors) == sorted(twin.sensors)
        for sid, data in frame.sensors.items():
            other = twin.sensors[sid]
            assert (data.sensor_type, data.frame_id, data.resolution) == (
                other.sensor_type,
                other.frame_id,
                other.resolution,
            )
            assert data.sensor_location == pytest.approx(other.sensor_location)
            assert data.frame_rate_hz == pytest.approx(other.frame_rate_hz, rel=0.15)
        # the ego and the ground truth of the same instant
        assert frame.vehicle_state is not None
        assert twin.vehicle_state is not None
        np.testing.assert_allclose(
            frame.vehicle_state.position, twin.vehicle_state.position, atol=1e-6
        )
        assert frame.ground_truth is not None
        assert twin.ground_truth is not None
        assert [o.object_id for o in frame.ground_truth] == [o.object_id for o in twin.ground_truth]
        for mine, theirs in zip(frame.ground_truth, twin.ground_truth, strict=True):
            np.testing.assert_allclose(mine.box.center, theirs.box.center, atol=1e-5)
            assert mine.box.yaw_rad == pytest.approx(theirs.box.yaw_rad, abs=1e-6)
            assert mine.num_lidar_points is not None
            assert mine.visible is not None

    # every sample equals the logged one of its sensor and stamp: a LiDAR's last finished
    # sweep (stamped at its start), the camera, IMU and GNSS of the frame's instant
    compared: dict[str, int] = {}
    for frame in frames:
        for sid, data in frame.sensors.items():
            logged_sample = by_stamp[(topics[sid], data.stamp_ns)]
            other = SensorData(
                sensor_id=sid,
                sensor_type=data.sensor_type,
                stamp_ns=logged_sample.stamp_ns,
                frame_id=logged_sample.frame_id,
                frame_rate_hz=data.frame_rate_hz,
                resolution=data.resolution,
                sensor_location=data.sensor_location,
                data=logged_sample.value,
            )
            _assert_same_data(data, other)
            compared[sid] = compared.get(sid, 0) + 1
        lidar = frame.sensors["lidar_top"]
        assert lidar.stamp_ns == frame.stamp_ns - 100_000_000
        assert frame.sensors["camera_front_image_raw"].stamp_ns == frame.stamp_ns
    assert compared == dict.fromkeys(sim.sensors, 14)


def _non_ground(frame: Frame) -> np.ndarray:
    cloud = frame.sensors["lidar_top"].data
    assert isinstance(cloud, PointCloud)
    xyz = cloud.xyz.astype(np.float64)
    return xyz[xyz[:, 2] > -1.6]  # the sensor is 1.9 m above the ground


def test_one_metre_to_the_left_the_scene_is_one_metre_to_the_right() -> None:
    scenario = _small("highway", duration_s=1.0)
    ref = _drive(SyntheticSimulator(scenario, tracker=LqrTracker(), level="sensor"), STRAIGHT_ON)
    left = _drive(StartsOneMetreLeft(scenario, tracker=LqrTracker(), level="sensor"), STRAIGHT_ON)
    assert len(ref) == len(left) == 9
    for a, b in zip(ref, left, strict=True):
        assert a.vehicle_state is not None
        assert b.vehicle_state is not None
        # same heading, 1 m to the left, the same distance along the (straight) road
        offset = b.vehicle_state.position[:2] - a.vehicle_state.position[:2]
        yaw = a.vehicle_state.heading_rad
        assert b.vehicle_state.heading_rad == pytest.approx(yaw, abs=1e-9)
        left_m = -np.sin(yaw) * offset[0] + np.cos(yaw) * offset[1]
        ahead_m = np.cos(yaw) * offset[0] + np.sin(yaw) * offset[1]
        assert (left_m, ahead_m) == pytest.approx((1.0, 0.0), abs=1e-6)
        # the ground truth moved 1 m to the right in base_link
        assert a.ground_truth
        assert b.ground_truth
        for oa, ob in zip(a.ground_truth, b.ground_truth, strict=True):
            assert oa.object_id == ob.object_id
            np.testing.assert_allclose(ob.box.center - oa.box.center, [0.0, -1.0, 0.0], atol=1e-6)
        # the point cloud: what stands on the ground (walls, poles, cars) lies 1 m further right:
        # of the lateral shifts 0 … 2 m (5 cm apart), 1 m brings it back onto the reference cloud
        tree = cKDTree(_non_ground(a))
        moved = _non_ground(b)
        assert len(moved) > 500
        shifts = np.round(np.arange(0.0, 2.001, 0.05), 2)
        misfit = [
            float(np.median(tree.query(moved + np.array([0.0, dy, 0.0]))[0])) for dy in shifts
        ]
        assert shifts[int(np.argmin(misfit))] == 1.0
        assert misfit[20] < 0.1  # 1 m: back on the scan lines
        assert misfit[0] > 0.9  # unshifted: 1 m off them


def test_the_reference_pipeline_drives_cut_in_on_its_sensors(tmp_path: Path) -> None:
    out = tmp_path / "run"
    report = run_closed_loop(
        ClosedLoopRequest(
            scenario="cut_in",
            pipeline=reference_pipeline(),
            out=out,
            duration_s=3.0,
            level="sensor",
        )
    )
    assert report.status is RunStatus.COMPLETE
    run = open_run(out)
    described = run.manifest.closed_loop
    assert described["level"] == "sensor"
    assert described["sensors"]["lidar_top"] == "lidar"
    assert described["first_frame_s"] == pytest.approx(0.1)
    driven = run.ego()
    assert sorted(driven) == list(range(29))  # 0.1 s … 2.9 s
    stats = {a.name: a for a in report.algorithms}
    assert all(a.ok == 29 and a.error == 0 for a in report.algorithms)
    assert stats["clusters"].outputs >= 29  # the detector finds the cars in the rendered sweeps
    assert stats["tracker"].outputs >= 20
    commands = run.table("closed_loop").to_pylist()
    assert {r["source"] for r in commands} == {"control"}
    # the pipeline drives: down to its planner's speed, in its lane
    logged = run.logged_ego()
    for k, state in driven.items():
        yaw = logged[k].heading_rad
        dx, dy = state.position[:2] - logged[k].position[:2]
        assert abs(-np.sin(yaw) * dx + np.cos(yaw) * dy) < 0.3
    assert driven[28].speed_mps < driven[0].speed_mps - 5.0


def test_cli_sensor_level_and_sensors_without_closed_loop(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "cut_in", "--sensors", "--out", str(tmp_path / "x")]) == 2
    assert "add --closed-loop" in capsys.readouterr().out
    out = tmp_path / "cli"
    code = main(
        [
            "run",
            "cut_in",
            "--closed-loop",
            "--sensors",
            "--perception",
            "cluster-detector",
            "--planning",
            "idm-planner",
            "--duration",
            "1.0",
            "--out",
            str(out),
            "--no-progress",
        ]
    )
    assert code == 0
    assert open_run(out).manifest.closed_loop["level"] == "sensor"


def test_object_level_still_refuses_a_sensor_reader(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"cluster-detector.*reads lidar.*--sensors"):
        run_closed_loop(
            ClosedLoopRequest(scenario="cut_in", pipeline=reference_pipeline(), out=tmp_path / "r")
        )


def test_level_is_checked() -> None:
    with pytest.raises(ConfigError, match="level"):
        SyntheticSimulator(
            load_scenario("cut_in"),
            tracker=LqrTracker(),
            level="pixels",  # type: ignore[arg-type]
        )
    sim = SyntheticSimulator(_small("cut_in", 1.0), tracker=LqrTracker(), level="sensor")
    assert dict(sim.sensors) == {
        "camera_front_image_raw": SensorType.CAMERA,
        "gnss": SensorType.GNSS,
        "imu": SensorType.IMU,
        "lidar_2d": SensorType.LIDAR_2D,
        "lidar_top": SensorType.LIDAR,
    }


def test_a_sensor_level_run_records_what_its_algorithms_saw(tmp_path: Path) -> None:
    out = tmp_path / "run"
    plugins.SEEN_CLOUDS.clear()
    pipeline = pipeline_from_plugins(
        perception=["tests.closedloop.plugins:LidarWitness"], planning=["idm-planner"]
    )
    report = run_closed_loop(
        ClosedLoopRequest(
            scenario="cut_in", pipeline=pipeline, out=out, duration_s=2.0, level="sensor"
        )
    )
    assert report.status is RunStatus.COMPLETE
    run = open_run(out)
    assert run.manifest.closed_loop["sensor_log"] == "sensors.mcap"
    frames = sorted(run.ego())
    assert frames == list(range(19))  # 0.1 s … 1.9 s
    scenario = load_scenario("cut_in")
    rig = rig_from_mapping(scenario.rig, source=scenario.source)
    with open_log(out / "sensors.mcap") as log:
        topics = set(log.topics)
        expected = {sensor_topic(s) for s in rig} | {"/tf", "/tf_static"}
        expected |= {camera_info_topic(s) for s in rig.of_kind(SensorType.CAMERA)}
        assert expected | {EGO_STATE_TOPIC, GROUND_TRUTH_TOPIC} <= topics
        lidar = sensor_topic(rig.of_kind(SensorType.LIDAR)[0])
        assert abs(log.topics[lidar].count - len(frames)) <= 1
        first = next(iter(log.messages(topics=[lidar])))
        cloud = decode(first, log.deserialize).value
    assert isinstance(cloud, PointCloud)
    seen = plugins.SEEN_CLOUDS[0]
    assert len(seen) > 1000
    np.testing.assert_array_equal(cloud.xyz, seen.xyz)
    for name, values in seen.channels.items():
        np.testing.assert_array_equal(cloud.channels[name], values)


def test_a_failed_run_leaves_a_recording_that_opens(tmp_path: Path) -> None:
    out = tmp_path / "run"

    def interrupt(done: int) -> None:
        if done == 3:
            msg = "the progress display broke"
            raise RuntimeError(msg)

    with pytest.raises(RuntimeError, match="display broke"):
        run_closed_loop(
            ClosedLoopRequest(
                scenario="cut_in",
                pipeline=pipeline_from_plugins(planning=["idm-planner"]),
                out=out,
                duration_s=2.0,
                level="sensor",
            ),
            progress=interrupt,
        )
    run = open_run(out)
    assert run.manifest.status is RunStatus.FAILED
    with open_log(out / "sensors.mcap") as log:
        assert 3 <= log.topics["/lidar_top"].count <= 5  # rendered up to the interruption
        assert next(iter(log.messages(topics=["/tf_static"]))).log_time_ns == log.start_ns


def test_recording_is_for_a_sensor_level_run_from_its_start(tmp_path: Path) -> None:
    objects = SyntheticSimulator(_small("cut_in", 1.0), tracker=LqrTracker())
    with pytest.raises(ConfigError, match="object-level"):
        objects.record_sensors(McapWriter(tmp_path / "a.mcap"))
    sim = SyntheticSimulator(_small("cut_in", 1.0), tracker=LqrTracker(), level="sensor")
    sim.observe()
    with pytest.raises(SimulationError, match="before the first frame"):
        sim.record_sensors(McapWriter(tmp_path / "b.mcap"))
