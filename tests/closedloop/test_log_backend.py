"""Closed loop on recorded logs (object level): the ego starts at the log's pose and is driven by
the outputs, the log's frames are re-expressed from the driven pose, and the run stores the driven
and the logged ego and how far apart they were."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from redrive.algorithms import StageOutputs
from redrive.assembly.frames import FrameAssembler
from redrive.cli.main import main
from redrive.closedloop.logreplay import LogSimulator, driven_from_logged, reexpress_cloud
from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.closedloop.tracker import LqrTracker
from redrive.config import PipelineConfig, load_pipeline, pipeline_from_plugins
from redrive.errors import ConfigError
from redrive.evaluation.closedloop import AtFaultCollisions
from redrive.evaluation.evaluator import evaluate_run
from redrive.io import open_log
from redrive.results import Run, RunStatus, open_run
from redrive.types import ControlCommands, Imu, PointCloud, Role, VehicleState

PLUGINS = "tests.closedloop.plugins"
FOLLOWER = Path(__file__).parent / "data" / "follower.toml"
#: the real ROS 1 bags of ../shared/data with odometry (README §6)
ODOMETRY_BAGS = (
    "rosbag1_real/robot_localization_test1_husky.bag",
    "rosbag1_real/robot_localization_test2_jackal.bag",
)


def _state(x: float, y: float, yaw: float) -> VehicleState:
    return VehicleState(
        stamp_ns=0, frame_id="odom", position=np.array([x, y, 0.0]), heading_rad=yaw
    )


def _follower_pipeline(tmp_path: Path, log: Path) -> PipelineConfig:
    toml = tmp_path / "follow.toml"
    toml.write_text(
        '[[stage]]\nname = "planning"\n[[stage.algorithm]]\nname = "follow"\n'
        f'plugin = "{PLUGINS}:LoggedPathFollower"\nconfig = {{ log = "{log}" }}\n'
    )
    return load_pipeline(toml)


def _run(out: Path, log: Path, pipeline: PipelineConfig, **kw: object) -> Run:
    report = run_closed_loop(ClosedLoopRequest(scenario=str(log), pipeline=pipeline, out=out, **kw))  # type: ignore[arg-type]
    assert report.status is RunStatus.COMPLETE
    return open_run(out)


def _without_timing(table: pa.Table) -> pa.Table:
    timing = {"wall_ns", "latency_ns", "cpu_ns"}
    return table.drop_columns([c for c in table.column_names if c in timing])


# -- the re-expression, by hand ------------------------------------------------------------------


def test_a_driven_ego_1_m_to_the_left_sees_the_points_1_m_to_the_right() -> None:
    logged, driven = _state(10.0, 5.0, 0.3), _state(10.0, 5.0, 0.3)
    left = np.array([-math.sin(0.3), math.cos(0.3), 0.0])  # +y of the logged base, in odom
    driven = _state(10.0 + left[0], 5.0 + left[1], 0.3)
    mat = driven_from_logged(driven, logged)
    xyz = np.array([[5.0, 0.0, 0.0], [-3.0, 2.0, 1.0], [0.0, -7.5, -1.5]], dtype=np.float32)
    cloud = PointCloud(xyz=xyz, channels={"intensity": np.array([1.0, 2.0, 3.0], np.float32)})
    moved = reexpress_cloud(cloud, mat, sensor_location=(1.2, 0.0, 1.8))
    np.testing.assert_allclose(moved.xyz, xyz - np.array([0.0, 1.0, 0.0]), atol=1e-5)
    assert moved.xyz.dtype == np.float32
    np.testing.assert_array_equal(moved.channels["intensity"], [1.0, 2.0, 3.0])


def test_a_turned_ego_sees_the_world_turned_back_about_its_own_axle() -> None:
    logged, driven = _state(0.0, 0.0, 0.0), _state(0.0, 0.0, math.pi / 2)
    xyz = np.array([[10.0, 0.0, 0.0]], dtype=np.float32)  # 10 m ahead of a sensor at 2 m
    moved = reexpress_cloud(PointCloud(xyz=xyz), driven_from_logged(driven, logged),
                            sensor_location=(2.0, 0.0, 0.0))  # fmt: skip
    # the point is 12 m ahead of the rear axle; turned left by 90°, the car has it 12 m to its
    # right, which is (-2, -12) from the sensor 2 m ahead of the axle
    np.testing.assert_allclose(moved.xyz, [[-2.0, -12.0, 0.0]], atol=1e-5)


# -- real bags with odometry ---------------------------------------------------------------------


@pytest.mark.parametrize("name", ODOMETRY_BAGS)
def test_closed_loop_on_a_real_bag_follows_the_logged_path(
    shared_data: Path, tmp_path: Path, name: str
) -> None:
    bag = shared_data / name
    run = _run(tmp_path / "run", bag, _follower_pipeline(tmp_path, bag), duration_s=15.0)
    manifest = run.manifest
    assert manifest.pipeline.mode_manager == "closed_loop"
    assert manifest.closed_loop["backend"] == "log"
    assert manifest.closed_loop["deviation_threshold_m"] == 2.0
    assert manifest.closed_loop["deviation_threshold_rad"] == pytest.approx(math.radians(10))
    assert manifest.log.sha256 is not None
    assert len(manifest.log.sha256) == 64
    assert manifest.log.format == "ros1"
    driven, logged = run.ego(), run.logged_ego()
    assert sorted(driven) == sorted(logged)
    assert 140 <= len(driven) <= 151  # 15 s at (at most) 10 Hz
    first = min(driven)
    np.testing.assert_allclose(driven[first].position, logged[first].position)
    rows = run.table("closed_loop").to_pylist()
    assert {r["source"] for r in rows} == {"tracker"}
    dev = np.array([r["deviation_m"] for r in rows])
    assert dev[0] == 0.0
    # the driven ego moved on its own (not copied from the log) …
    assert dev.max() > 1e-3
    moved = np.linalg.norm(driven[max(driven)].position[:2] - driven[first].position[:2])
    logged_moved = np.linalg.norm(logged[max(logged)].position[:2] - logged[first].position[:2])
    assert moved > 0.5 * logged_moved
    flagged = [r["frame_index"] for r in rows if r["deviated"]]
    assert manifest_summary(run)["deviated_frames"] == len(flagged)
    if "husky" in name:
        # the Husky drives gentle curves: the car-sized bicycle stays on its path, within 1 m
        assert dev.max() < 1.0
        assert not flagged
    else:
        # the Jackal turns on the spot (radius < 1 m); a car's bicycle (2.8 m wheelbase, 0.6 rad
        # of steering: 4.1 m radius at best) cannot, and the frames are flagged from the first
        # tight turn on
        kappa = [
            abs(s.yaw_rate_rad_s) / s.speed_mps
            for _, s in sorted(logged.items())
            if s.speed_mps > 0.3
        ]
        assert max(kappa) > 1.0 / 4.1
        assert flagged
        assert dev.max() > 2.0


def manifest_summary(run: Run) -> dict[str, object]:
    return dict(run.manifest.summary.closed_loop)  # type: ignore[union-attr]


def test_a_blind_planner_on_the_husky_bag_deviates_and_the_frames_are_flagged(
    shared_data: Path, tmp_path: Path
) -> None:
    bag = shared_data / ODOMETRY_BAGS[0]
    pipeline = pipeline_from_plugins(planning=[f"{PLUGINS}:StandStill"])
    run = _run(tmp_path / "still", bag, pipeline, duration_s=15.0)
    rows = run.table("closed_loop").to_pylist()
    flagged = [r["frame_index"] for r in rows if r["deviated"]]
    assert flagged
    assert flagged == list(range(flagged[0], len(rows)))
    assert rows[flagged[0]]["deviation_m"] > 2.0 >= rows[flagged[0] - 1]["deviation_m"]
    summary = manifest_summary(run)
    assert summary["deviated_frames"] == len(flagged)
    assert summary["first_deviated_frame"] == flagged[0]
    assert summary["max_deviation_m"] == pytest.approx(max(r["deviation_m"] for r in rows))


def test_same_log_same_run(shared_data: Path, tmp_path: Path) -> None:
    bag = shared_data / ODOMETRY_BAGS[1]
    pipeline = _follower_pipeline(tmp_path, bag)
    a = _run(tmp_path / "a", bag, pipeline, duration_s=5.0)
    b = _run(tmp_path / "b", bag, pipeline, duration_s=5.0)
    for name in ("frames", "ego", "ego_logged", "paths", "closed_loop"):
        assert _without_timing(a.table(name)).equals(_without_timing(b.table(name))), name


@pytest.mark.parametrize("agents", ["replay", "reactive"])
def test_same_synthetic_log_same_run(follower_log: Path, tmp_path: Path, agents: str) -> None:
    """Both agent modes on a log with objects: the reactive agents' IDM is deterministic too."""
    pipeline = pipeline_from_plugins(planning=[f"{PLUGINS}:StandStill"])
    a = _run(tmp_path / "a", follower_log, pipeline, agents=agents, duration_s=3.0)
    b = _run(tmp_path / "b", follower_log, pipeline, agents=agents, duration_s=3.0)
    for name in ("frames", "ego", "ego_logged", "ground_truth", "closed_loop"):
        assert _without_timing(a.table(name)).equals(_without_timing(b.table(name))), name
    assert a.table("ground_truth").num_rows > 0


def test_a_bag_without_a_pose_is_refused_naming_what_is_missing(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = shared_data / "rosbag1_recorded_here" / "kitti_3frames_rosbag_record_lz4.bag"
    pipeline = pipeline_from_plugins(planning=[f"{PLUGINS}:StandStill"])
    request = ClosedLoopRequest(scenario=str(bag), pipeline=pipeline, out=tmp_path / "x")
    with pytest.raises(
        ConfigError,
        match=r"kitti_3frames_rosbag_record_lz4\.bag: closed loop needs the ego's pose "
        r"\(odometry/poses\); this log has none — its topics: /kitti/camera_color_left/image_raw",
    ):
        run_closed_loop(request)
    assert not (tmp_path / "x").exists()
    assert main(["run", str(bag), "--closed-loop", "--out", str(tmp_path / "y")]) == 1
    assert "closed loop needs the ego's pose (odometry/poses)" in capsys.readouterr().err


def test_reactive_agents_need_objects(shared_data: Path, tmp_path: Path) -> None:
    bag = shared_data / ODOMETRY_BAGS[0]
    pipeline = pipeline_from_plugins(planning=[f"{PLUGINS}:StandStill"])
    request = ClosedLoopRequest(
        scenario=str(bag), pipeline=pipeline, out=tmp_path / "x", agents="reactive"
    )
    with pytest.raises(ConfigError, match=r"--agents reactive needs the other road users"):
        run_closed_loop(request)


def test_a_bag_whose_poses_miss_its_frames_is_refused(shared_data: Path) -> None:
    """The Luminar bag's odometry (a Stage simulation) is stamped far from its LiDAR clouds."""
    bag = shared_data / "rosbag1_real" / "embag_luminar_test.bag"
    with (
        open_log(bag) as log,
        pytest.raises(ConfigError, match=r"at least two frames with the ego's pose.*has 0"),
    ):
        LogSimulator(log, tracker=LqrTracker())


def test_the_lidar_points_stay_put_in_the_world(follower_log: Path) -> None:
    """The driven ego brakes hard while the logged one drove on at 20 m/s: the clouds it sees
    are the logged clouds moved by exactly the pose difference."""
    with open_log(follower_log) as log:
        raw = list(FrameAssembler(log).frames())[:12]
        sim = LogSimulator(log, tracker=LqrTracker(), duration_s=1.0)
        throttle = StageOutputs(
            outputs={"stop": ControlCommands(brake=1.0)}, roles={"stop": Role.CONTROL}
        )
        seen = [sim.observe()]
        while True:  # as the closed-loop mode does: observe, step, until done
            assert sim.step(throttle, sim.dt_s).source == "control"
            if sim.done:
                break
            seen.append(sim.observe())
    assert [f.stamp_ns for f in seen] == [f.stamp_ns for f in raw[: len(seen)]]
    assert len(seen) == 10  # 1 s at 10 Hz; the 11th frame is where the last step lands
    for frame, logged_frame in zip(seen, raw, strict=False):
        assert frame.vehicle_state is not None
        assert logged_frame.vehicle_state is not None
        mat = driven_from_logged(frame.vehicle_state, logged_frame.vehicle_state)
        lidar = next(k for k, v in logged_frame.sensors.items() if isinstance(v.data, PointCloud))
        data = logged_frame.sensors[lidar]
        assert isinstance(data.data, PointCloud)
        expected = reexpress_cloud(data.data, mat, sensor_location=data.sensor_location)
        got = frame.sensors[lidar].data
        assert isinstance(got, PointCloud)
        np.testing.assert_allclose(got.xyz, expected.xyz, atol=1e-3)
        assert got.channels.keys() == data.data.channels.keys()
        imu = logged_frame.sensors["imu"].data  # IMU, camera …: passed through unchanged
        assert isinstance(imu, Imu)
        np.testing.assert_array_equal(frame.sensors["imu"].data.linear_acceleration,  # type: ignore[union-attr]
                                      imu.linear_acceleration)  # fmt: skip
    # the driven ego is behind the logged one on a straight road: the points are farther ahead
    last, logged_last = seen[-1].vehicle_state, raw[len(seen) - 1].vehicle_state
    assert last is not None
    assert logged_last is not None
    behind = float(np.linalg.norm(logged_last.position[:2] - last.position[:2]))
    assert behind > 1.0
    got = seen[-1].sensors[lidar].data
    was = raw[len(seen) - 1].sensors[lidar].data
    assert isinstance(got, PointCloud)
    assert isinstance(was, PointCloud)
    np.testing.assert_allclose(got.xyz[:, 0], was.xyz[:, 0] + behind, atol=0.05)


# -- reactive agents on a synthetic log ----------------------------------------------------------


@pytest.fixture(scope="module")
def follower_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize

    folder = tmp_path_factory.mktemp("follower")
    scenario = folder / "follower.toml"
    scenario.write_text(
        FOLLOWER.read_text()
        + '\n[rig.lidar_top]\nkind = "lidar"\npreset = "HDL-32E"\nxyz = [1.2, 0.0, 1.9]\n'
        'rate_hz = 10\n\n[rig.imu]\nkind = "imu"\nxyz = [0.0, 0.0, 0.5]\nrate_hz = 100\n'
    )
    out = folder / "follower.mcap"
    synthesize(load_scenario(str(scenario)), out, duration_s=8.0, seed=5)
    return out


def test_a_follower_runs_into_a_braking_ego_when_replayed_and_stops_when_reactive(
    follower_log: Path, tmp_path: Path
) -> None:
    pipeline = pipeline_from_plugins(planning=[f"{PLUGINS}:StandStill"])
    found = {}
    for agents in ("replay", "reactive"):
        out = tmp_path / agents
        run = _run(out, follower_log, pipeline, agents=agents)
        assert run.manifest.closed_loop["agents"] == agents
        summary = evaluate_run(out, metrics=[AtFaultCollisions()])
        assert not summary.failed, summary.failed
        values = dict(summary.scored[0].result.values)
        behind = [
            -float(o.box.center[0])
            for objs in run.ground_truth().values()
            for o in objs
            if o.box.center[0] < 0 and abs(o.box.center[1]) < 1.75
        ]
        found[agents] = (values["collisions"], min(behind))
    # replayed, the follower keeps its logged motion and drives into the stopped ego
    assert found["replay"][0] >= 1
    # reactive, its IDM sees the ego brake: it stops behind (ego rear bumper at -0.95 m, the
    # follower's half length ~2.3 m behind its centre)
    assert found["reactive"][0] == 0
    assert found["reactive"][1] > 0.95 + 2.3
