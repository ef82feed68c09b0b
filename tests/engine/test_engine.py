"""The engine on a real (rosbags-written) ROS 1 bag: outputs, modes, faults, resume."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.config import AlgorithmSpec, PipelineConfig, StageSpec
from redrive.engine import RunReport, RunRequest, run_log
from redrive.errors import ConfigError
from redrive.results import RunStatus, open_run
from tests.engine._runs import OUTPUT_TABLES, outputs

P = "tests.engine.plugins:"


def pipeline(*stages: tuple[tuple[str, str], ...], **options: object) -> PipelineConfig:
    return PipelineConfig(
        stages=tuple(
            StageSpec(
                name=f"stage{i}",
                algorithms=tuple(AlgorithmSpec(name=n, plugin=P + cls) for n, cls in stage),
            )
            for i, stage in enumerate(stages)
        ),
        **options,  # type: ignore[arg-type]
    )


STANDARD = (
    (("centroid", "Centroid"),),
    (("straight", "Straight"),),
    (("follow", "FollowSpeed"),),
)


def run(log: Path, out: Path, pipe: PipelineConfig, **kw: object) -> RunReport:
    return run_log(RunRequest(log=log, pipeline=pipe, out=out, **kw))  # type: ignore[arg-type]


def test_every_frame_goes_through_every_stage(demo_bag: Path, tmp_path: Path) -> None:
    report = run(demo_bag, tmp_path / "run", pipeline(*STANDARD))

    assert report.status == "complete"
    assert report.frames == 50
    assert [a.ok for a in report.algorithms] == [50, 50, 50]
    r = open_run(tmp_path / "run")
    assert r.manifest.status is RunStatus.COMPLETE
    steps = r.table("steps")
    assert steps.num_rows == 150
    det = r.table("detections")
    # the stateful counter saw the frames in order, once each
    ids = det.column("object_id").to_pylist()
    assert ids == [i + 1 for i in det.column("frame_index").to_pylist()]
    assert len(ids) > 30
    assert r.table("commands").num_rows == 50
    assert r.table("paths").num_rows == 50 * 7
    names = [a.name for a in r.manifest.algorithms]
    assert names == ["centroid", "straight", "follow"]
    assert all(len(a.config_hash) == 64 for a in r.manifest.algorithms)
    assert len(r.manifest.log.sha256 or "") == 64


def test_same_log_and_config_give_identical_outputs(demo_bag: Path, tmp_path: Path) -> None:
    run(demo_bag, tmp_path / "a", pipeline(*STANDARD))
    run(demo_bag, tmp_path / "b", pipeline(*STANDARD))
    a, b = outputs(tmp_path / "a"), outputs(tmp_path / "b")
    for name in OUTPUT_TABLES:
        assert a[name].equals(b[name]), name


@pytest.mark.parametrize(
    ("mode", "executor"),
    [("pipelined", "threads"), ("sequential", "processes"), ("pipelined", "processes")],
)
def test_modes_and_executors_give_the_sequential_outputs(
    demo_bag: Path, tmp_path: Path, mode: str, executor: str
) -> None:
    run(demo_bag, tmp_path / "seq", pipeline(*STANDARD), stop_frame=20)
    report = run(
        demo_bag,
        tmp_path / "other",
        pipeline(*STANDARD, mode=mode, executor=executor),
        stop_frame=20,
    )
    assert report.frames == 20
    a, b = outputs(tmp_path / "seq"), outputs(tmp_path / "other")
    for name in OUTPUT_TABLES:
        assert a[name].equals(b[name]), name


def test_two_algorithms_side_by_side_in_one_stage(demo_bag: Path, tmp_path: Path) -> None:
    stages = (
        (("c1", "Centroid"), ("c2", "Centroid")),
        (("straight", "Straight"),),
    )
    report = run(demo_bag, tmp_path / "run", pipeline(*stages), stop_frame=10)
    assert [a.ok for a in report.algorithms] == [10, 10, 10]
    det = open_run(tmp_path / "run").table("detections")
    by_algo = det.group_by("algorithm").aggregate([("object_id", "count")])
    assert sorted(by_algo.column("algorithm").to_pylist()) == ["c1", "c2"]


def test_an_exception_every_10th_frame_is_recorded_and_the_run_goes_on(
    demo_bag: Path, tmp_path: Path
) -> None:
    stages = ((("flaky", "FailEvery10th"),), (("straight", "Straight"),))
    report = run(demo_bag, tmp_path / "run", pipeline(*stages))

    assert report.status == "complete"
    flaky = report.algorithms[0]
    assert (flaky.ok, flaky.error) == (45, 5)
    steps = open_run(tmp_path / "run").table("steps").to_pylist()
    errors = [s for s in steps if s["status"] == "error"]
    assert [s["frame_index"] for s in errors] == [0, 10, 20, 30, 40]
    assert errors[0]["error_type"] == "ValueError"
    assert errors[0]["error_message"] == "planned failure on frame 0"
    assert "plugins.py" in errors[0]["traceback"]
    assert "raise ValueError" in errors[0]["traceback"]


def test_a_hanging_step_times_out_and_the_worker_is_replaced(
    demo_bag: Path, tmp_path: Path
) -> None:
    stages = (
        (("centroid", "Centroid"),),
        (("hang", "HangOnce"),),
    )
    report = run(demo_bag, tmp_path / "run", pipeline(*stages, step_timeout_s=1.0), stop_frame=8)

    assert report.status == "complete"
    hang = report.algorithms[1]
    assert (hang.ok, hang.timeout) == (7, 1)
    steps = open_run(tmp_path / "run").table("steps").to_pylist()
    timed_out = [s for s in steps if s["status"] == "timeout"]
    assert [(s["algorithm"], s["frame_index"]) for s in timed_out] == [("hang", 3)]
    assert timed_out[0]["latency_ns"] >= 1_000_000_000
    assert open_run(tmp_path / "run").manifest.status is RunStatus.COMPLETE


def test_a_wrong_output_type_is_recorded_as_an_error(demo_bag: Path, tmp_path: Path) -> None:
    stages = ((("straight", "Straight"),), (("wrong", "WrongType"),))
    report = run(demo_bag, tmp_path / "run", pipeline(*stages), stop_frame=5)
    assert report.algorithms[1].error == 5
    steps = open_run(tmp_path / "run").table("steps").to_pylist()
    wrong = [s for s in steps if s["algorithm"] == "wrong"]
    assert {s["error_type"] for s in wrong} == {"AlgorithmError"}
    assert "must return a ControlCommands, got dict" in wrong[0]["error_message"]


def test_fail_fast_stops_at_the_first_failure(demo_bag: Path, tmp_path: Path) -> None:
    stages = ((("straight", "Straight"),), (("wrong", "WrongType"),))
    report = run(demo_bag, tmp_path / "run", pipeline(*stages, fail_fast=True))
    assert report.status == "failed"
    assert report.failure is not None
    index, step = report.failure
    assert (index, step.algorithm, step.error_type) == (0, "wrong", "AlgorithmError")
    r = open_run(tmp_path / "run")
    assert r.manifest.status is RunStatus.FAILED
    assert r.table("frames").num_rows == 1  # the failing frame is recorded


def test_a_missing_input_is_refused_before_the_first_frame(demo_bag: Path, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="needs a CAMERA sensor"):
        run(demo_bag, tmp_path / "run", pipeline((("cam", "NeedsCamera"),)))
    assert not (tmp_path / "run").exists()


def test_roles_must_not_go_backwards(demo_bag: Path, tmp_path: Path) -> None:
    stages = ((("straight", "Straight"),), (("centroid", "Centroid"),))
    with pytest.raises(ConfigError, match="order stages perception"):
        run(demo_bag, tmp_path / "run", pipeline(*stages))


def test_frame_range(demo_bag: Path, tmp_path: Path) -> None:
    report = run(demo_bag, tmp_path / "run", pipeline(*STANDARD), first_frame=10, stop_frame=25)
    assert report.frames == 15
    idx = open_run(tmp_path / "run").table("frames").column("frame_index").to_pylist()
    assert idx == list(range(10, 25))


def test_real_time_pacing_counts_late_frames(demo_bag: Path, tmp_path: Path) -> None:
    # 10 Hz frames, 0.25 s of work each at real time: the run falls behind and frames are late
    slow = PipelineConfig(
        stages=(
            StageSpec(
                name="slow",
                algorithms=(
                    AlgorithmSpec(name="slow", plugin=P + "Slow", config={"sleep_s": 0.25}),
                ),
            ),
        )
    )
    report = run(demo_bag, tmp_path / "slow", slow, stop_frame=6, rate=1.0)
    assert report.frames == 6
    assert report.late_frames == 5  # all but the first
    late = open_run(tmp_path / "slow").table("frames").column("late").to_pylist()
    assert late == [False] + [True] * 5
    # paced at 1x with no work: wall time ≈ log time, nothing late
    quick = run(demo_bag, tmp_path / "quick", pipeline(*STANDARD), stop_frame=6, rate=1.0)
    assert quick.late_frames == 0
    assert quick.wall_s >= 0.45


def test_resources_are_sampled(demo_bag: Path, tmp_path: Path) -> None:
    run(demo_bag, tmp_path / "run", pipeline(*STANDARD, executor="processes"), stop_frame=5)
    res = open_run(tmp_path / "run").table("resources").to_pylist()
    labels = {r["label"] for r in res}
    assert "engine" in labels
    assert {"stage0/centroid", "stage1/straight", "stage2/follow"} <= labels
    assert all(r["rss_bytes"] > 1_000_000 for r in res)


def test_a_cut_off_log_keeps_the_frames_before_the_damage(demo_bag: Path, tmp_path: Path) -> None:
    from redrive.errors import LogError

    data = demo_bag.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    with pytest.raises(LogError):
        run(cut, tmp_path / "run", pipeline(*STANDARD))
    r = open_run(tmp_path / "run")
    assert r.manifest.status is RunStatus.FAILED
    assert r.manifest.summary is not None
    assert "LogDamagedError" in (r.manifest.summary.error or "")  # a LogTruncatedError
    frames = r.table("frames").column("frame_index").to_pylist()
    assert 10 < len(frames) < 50
    assert frames == list(range(len(frames)))
    # not strict (`redrive run` without --strict): the intact part, the damage in the report
    report = run(cut, tmp_path / "lenient", pipeline(*STANDARD), strict=False)
    assert report.status == "complete"
    assert report.frames >= len(frames)
    assert any(d.stop_byte == cut.stat().st_size for d in report.damage)


@pytest.mark.parametrize("executor", ["threads", "processes"])
def test_algorithms_see_only_the_sensors_they_declare(
    demo_bag: Path, tmp_path: Path, executor: str
) -> None:
    stages = ((("only", "OnlyDeclared"),), (("straight", "Straight"),))
    report = run(demo_bag, tmp_path / "run", pipeline(*stages, executor=executor), stop_frame=5)
    assert report.algorithms[0].ok == 5, report.algorithms[0].first_error


def test_pipelined_runs_sample_cpu_per_stage_thread(demo_bag: Path, tmp_path: Path) -> None:
    slow = PipelineConfig(
        stages=(
            StageSpec(
                name="slow",
                algorithms=(
                    AlgorithmSpec(name="slow", plugin=P + "Slow", config={"sleep_s": 0.05}),
                ),
            ),
            StageSpec(name="plan", algorithms=(AlgorithmSpec(name="s", plugin=P + "Straight"),)),
        ),
        mode="pipelined",
    )
    run(demo_bag, tmp_path / "run", slow, stop_frame=30)
    res = open_run(tmp_path / "run").table("resources").to_pylist()
    labels = {r["label"] for r in res}
    assert {"engine", "thread:main", "thread:reader", "thread:slow", "thread:plan"} <= labels
    sleeping = [r["cpu_percent"] for r in res if r["label"] == "thread:slow"]
    assert max(sleeping) < 50  # it sleeps: little CPU
