"""Stages a log cannot feed (issue 35 item 2): skipped with the reason unless refused."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.config import AlgorithmSpec, PipelineConfig, StageSpec
from redrive.engine import LogInputs, build_graph
from redrive.errors import MissingInputError
from redrive.results import open_run, read_manifest
from redrive.types import SensorType

_REFERENCE = (
    ("detection", "clusters", "cluster-detector"),
    ("planning", "planner", "idm-planner"),
    ("control", "controller", "pure-pursuit-pid"),
)
_LIDAR_ONLY = LogInputs(sensors={"velodyne": SensorType.LIDAR}, has_ground_truth=True)


def _pipeline(*stages: tuple[str, str, str]) -> PipelineConfig:
    return PipelineConfig(
        stages=tuple(
            StageSpec(name=stage, algorithms=(AlgorithmSpec(name=name, plugin=plugin),))
            for stage, name, plugin in stages
        )
    )


def test_the_stages_a_log_cannot_feed_are_refused_by_default() -> None:
    with pytest.raises(MissingInputError, match=r"stage 'planning'.*needs vehicle state"):
        build_graph(_pipeline(*_REFERENCE), _LIDAR_ONLY)


def test_skipping_keeps_what_the_log_feeds_and_says_why_for_the_rest() -> None:
    graph = build_graph(_pipeline(*_REFERENCE), _LIDAR_ONLY, skip_unfed=True)
    assert [name for name, _ in graph.stages] == ["detection"]
    assert list(graph.skipped) == ["planner", "controller"]
    assert "needs vehicle state, which this log does not have" in graph.skipped["planner"]
    assert "sensor map file" not in graph.skipped["planner"]  # advice for a refusal only
    assert "planning stage was skipped" in graph.skipped["controller"]
    # a log with the ego state feeds everything: nothing is skipped
    full = LogInputs(
        sensors={"velodyne": SensorType.LIDAR}, has_vehicle_state=True, has_ground_truth=True
    )
    graph = build_graph(_pipeline(*_REFERENCE), full, skip_unfed=True)
    assert [name for name, _ in graph.stages] == ["detection", "planning", "control"]
    assert graph.skipped == {}


def test_a_pipeline_the_log_feeds_nothing_of_is_refused_with_every_reason() -> None:
    with pytest.raises(MissingInputError, match=r"no stage of the pipeline can run.*planner"):
        build_graph(_pipeline(*_REFERENCE[1:]), _LIDAR_ONLY, skip_unfed=True)


def test_the_default_run_of_the_real_kitti_folder_runs_perception_and_stores_the_skips(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    kitti = shared_data / "kitti_object" / "training"
    out = tmp_path / "run"
    assert main(["run", str(kitti), "--out", str(out), "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "skipped planner" in said
    assert "needs vehicle state" in said
    manifest = read_manifest(out)
    assert manifest.pipeline.stages == ("detection", "tracking")
    assert set(manifest.pipeline.skipped) == {"planner", "controller"}
    assert len(open_run(out).detections("clusters")) == 3  # every frame's detections
    # --strict refuses it, as before
    assert main(["run", str(kitti), "--out", str(tmp_path / "strict"), "--strict"]) != 0
    assert "needs vehicle state" in capsys.readouterr().err


_WITH_TRACKER = (
    ("detection", "clusters", "cluster-detector"),
    ("tracking", "tracker", "kalman-tracker"),
    ("planning", "planner", "idm-planner"),
    ("control", "controller", "pure-pursuit-pid"),
)


def test_a_tracker_whose_detector_is_skipped_is_skipped_too() -> None:
    # issue 35 item 11: an IMU/odometry-only log feeds planning and control, not perception
    imu_only = LogInputs(sensors={"imu_data": SensorType.IMU}, has_vehicle_state=True)
    graph = build_graph(_pipeline(*_WITH_TRACKER), imu_only, skip_unfed=True)
    assert [name for name, _ in graph.stages] == ["planning", "control"]
    assert list(graph.skipped) == ["clusters", "tracker"]
    assert "needs a LIDAR sensor" in graph.skipped["clusters"]
    assert "no perception algorithm runs before it" in graph.skipped["tracker"]
    # with its detector fed, the tracker runs
    lidar = LogInputs(sensors={"velodyne": SensorType.LIDAR}, has_vehicle_state=True)
    graph = build_graph(_pipeline(*_WITH_TRACKER), lidar, skip_unfed=True)
    assert graph.skipped == {}
    # refused without skipping, as before: the detector's missing LiDAR is named
    with pytest.raises(MissingInputError, match=r"stage 'detection'.*LIDAR"):
        build_graph(_pipeline(*_WITH_TRACKER), imu_only)


def test_open_loop_on_a_real_imu_and_odometry_bag_plans_and_controls(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # the Jackal bag: /imu/data (3,061 Imu) and /jackal_velocity_controller/odom (3,060
    # Odometry), nothing else.  Its IMU now paces the frames (a closed loop over it did so
    # already), the ego state is the odometry, and the default pipeline runs what that feeds.
    bag = shared_data / "rosbag1_real" / "robot_localization_test2_jackal.bag"
    out = tmp_path / "run"
    assert main(["run", str(bag), "--out", str(out), "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "skipped clusters" in said
    assert "skipped tracker" in said
    manifest = read_manifest(out)
    assert manifest.pipeline.stages == ("planning", "control")
    assert set(manifest.pipeline.skipped) == {"clusters", "tracker"}
    assert manifest.sensors == {"imu_data": SensorType.IMU}
    run = open_run(out)
    assert run.table("frames").num_rows == 3061  # one frame per IMU message
    steps = run.table("steps").to_pylist()
    assert {s["algorithm"] for s in steps} == {"planner", "controller"}
    assert all(s["status"] == "ok" for s in steps)
    assert run.table("paths").num_rows > 0
    assert run.table("commands").num_rows == 3061
    # --strict refuses it
    assert main(["run", str(bag), "--out", str(tmp_path / "strict"), "--strict"]) != 0
    assert "LIDAR" in capsys.readouterr().err


def test_open_loop_on_the_real_husky_bag_plans_at_its_imu_rate(
    shared_data: Path, tmp_path: Path
) -> None:
    # the Husky bag (REAL, 2015): /imu/data 11,865 Imu at 30 Hz, odometry at 10 Hz, /fix 2.5 Hz
    bag = shared_data / "rosbag1_real" / "robot_localization_test1_husky.bag"
    out = tmp_path / "run"
    assert main(["run", str(bag), "--out", str(out), "--frames", "0:200", "--no-progress"]) == 0
    manifest = read_manifest(out)
    assert manifest.pipeline.stages == ("planning", "control")
    assert manifest.sensors == {"fix": SensorType.GNSS, "imu_data": SensorType.IMU}
    run = open_run(out)
    stamps = run.table("frames").column("stamp_ns").to_pylist()
    assert len(stamps) == 200
    period_s = (stamps[-1] - stamps[0]) / 199 / 1e9
    assert 1 / 35 < period_s < 1 / 25  # the IMU's ~30 Hz paces the frames
    steps = run.table("steps").to_pylist()
    assert all(s["status"] == "ok" for s in steps)
    assert len(steps) == 400  # planner and controller, every frame


def test_a_vehicle_state_on_another_clock_is_no_input_the_planner_is_skipped_with_why(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The Embark bag's odometry is stamped 1970 (simulated time), its clouds 2020: no frame gets
    a state, so the default run skips planner and controller (saying why) instead of failing
    them on every frame; the Husky bag's odometry and IMU share a clock and stay inputs."""
    from redrive.assembly.clocks import other_clock_inputs
    from redrive.assembly.frames import FrameAssembler
    from redrive.io import open_log

    bag = shared_data / "rosbag1_real" / "embag_luminar_test.bag"
    with open_log(bag) as log:
        unusable = other_clock_inputs(log, FrameAssembler(log).sensor_map)
    assert list(unusable) == ["vehicle_state"]
    assert "/base_pose_ground_truth" in unusable["vehicle_state"]
    assert "another clock" in unusable["vehicle_state"]
    husky = shared_data / "rosbag1_real" / "robot_localization_test1_husky.bag"
    with open_log(husky) as log:
        assert other_clock_inputs(log, FrameAssembler(log).sensor_map) == {}

    out = tmp_path / "run"
    assert main(["run", str(bag), "--out", str(out), "--no-progress"]) == 0
    said = " ".join(capsys.readouterr().out.split())  # the console wraps long lines
    assert "skipped planner" in said
    assert "another clock" in said
    manifest = read_manifest(out)
    assert manifest.pipeline.stages == ("detection", "tracking")
    assert set(manifest.pipeline.skipped) == {"planner", "controller"}
    assert "another clock" in manifest.pipeline.skipped["planner"]
    steps = open_run(out).table("steps").to_pylist()
    assert {row["algorithm"] for row in steps} == {"clusters", "tracker"}
    assert all(row["status"] == "ok" for row in steps)  # no failed planner steps
    # the manifest keeps why, and `evaluate` names the other clock, not just "no ego"
    assert "another clock" in manifest.pipeline.unusable_inputs["vehicle_state"]
    assert main(["evaluate", str(out), "--metric", "comfort"]) == 0
    said = " ".join(capsys.readouterr().out.split())
    assert "skipped comfort on the run: the run has no ego: the log's vehicle state" in said
    assert "another clock" in said
    # --strict refuses it, naming the clock
    assert main(["run", str(bag), "--out", str(tmp_path / "strict"), "--strict"]) != 0
    assert "another clock" in " ".join(capsys.readouterr().err.split())
