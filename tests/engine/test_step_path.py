"""The engine's short per-frame path (one in-process algorithm per stage) records what the
general path records, and leaves an algorithm that overrides ``run_step`` on that override."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from redrive.algorithms import Algorithm, Role, StageOutputs
from redrive.config import AlgorithmSpec, PipelineConfig, StageSpec
from redrive.engine import Engine, LogInputs, build_graph
from redrive.engine import sequential as _seq
from redrive.engine.modes import ReplayMode
from redrive.engine.stats import StatsCollector
from redrive.results import FrameRecord, RunStatus
from redrive.types import ControlCommands, Frame

P = "tests.engine.plugins:"


def _run(*classes: str) -> list[FrameRecord]:
    pipeline = PipelineConfig(
        stages=tuple(
            StageSpec(
                name=f"s{i}",
                algorithms=(AlgorithmSpec(name=f"a{i}", plugin=cls if ":" in cls else P + cls),),
            )
            for i, cls in enumerate(classes)
        )
    )
    engine = Engine(build_graph(pipeline, LogInputs()), pipeline, inputs=LogInputs())
    kept: list[FrameRecord] = []
    try:
        engine.run([Frame(stamp_ns=i * 10, index=i) for i in range(3)], sink=kept.append)
    finally:
        engine.close()
    return kept


def test_an_overridden_run_step_is_used() -> None:
    records = _run("OwnRunStep")
    assert [r.steps[0].output.throttle for r in records] == [0.5, 0.5, 0.5]  # type: ignore[union-attr]


def test_records_of_the_short_path_are_complete() -> None:
    noop = "redrive.benchmarks.engine:"
    records = _run(noop + "NoopPerception", noop + "NoopPlanning", "WrongType")
    assert [r.frame_index for r in records] == [0, 1, 2]
    for r in records:
        assert [(s.algorithm, s.stage, s.role, s.status) for s in r.steps] == [
            ("a0", "s0", "perception", "ok"),
            ("a1", "s1", "planning", "ok"),
            ("a2", "s2", "control", "error"),
        ]
        assert r.steps[0].output == ()
        assert r.steps[2].error_type == "AlgorithmError"
        assert "frame " + str(r.frame_index) in r.steps[2].error_message
        assert r.steps[2].output is None
        assert all(s.latency_ns >= 0 and s.cpu_ns >= 0 for s in r.steps)


def _steps_of(records: list[FrameRecord]) -> list[tuple[object, ...]]:
    """What a run recorded, timing and traceback lines aside (the exception's last line kept)."""
    return [
        (
            r.frame_index,
            r.stamp_ns,
            r.late,
            tuple(
                (
                    s.algorithm,
                    s.stage,
                    s.role,
                    s.status,
                    s.output,
                    s.error_type,
                    s.error_message,
                    s.traceback.strip().splitlines()[-1:],
                )
                for s in r.steps
            ),
        )
        for r in records
    ]


def _three_stages(mode: str = "sequential", *, fail_fast: bool = False) -> PipelineConfig:
    """Perception failing every 10th frame, a no-op planner, a controller following speed."""
    noop = "redrive.benchmarks.engine:"
    return PipelineConfig(
        stages=(
            StageSpec(name="p", algorithms=(AlgorithmSpec(name="p", plugin=P + "FailEvery10th"),)),
            StageSpec(
                name="l", algorithms=(AlgorithmSpec(name="l", plugin=noop + "NoopPlanning"),)
            ),
            StageSpec(name="c", algorithms=(AlgorithmSpec(name="c", plugin=P + "FollowSpeed"),)),
        ),
        mode=mode,  # type: ignore[arg-type]
        fail_fast=fail_fast,
    )


def _run_in(mode: str, *, fail_fast: bool = False) -> tuple[list[FrameRecord], object]:
    pipeline = _three_stages(mode, fail_fast=fail_fast)
    engine = Engine(build_graph(pipeline, LogInputs()), pipeline, inputs=LogInputs())
    kept: list[FrameRecord] = []
    try:
        report = engine.run(
            [Frame(stamp_ns=i * 10, index=i) for i in range(12)],
            sink=kept.append,
            skip=frozenset({1}),
        )
    finally:
        engine.close()
    return kept, report.failure


def test_the_short_sequential_path_records_what_the_stage_path_records(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def not_here(*args: object, **kwargs: object) -> None:
        raise AssertionError("the frame-by-frame regime ran instead of the chained one")

    with monkeypatch.context() as patch:
        patch.setattr(ReplayMode, "before_frame", not_here)
        short, _ = _run_in("sequential")  # one in-process algorithm per stage: chained
    general, _ = _run_in("pipelined")  # the same stages through _Stage.run
    assert [r.frame_index for r in short] == [0, *range(2, 12)]
    assert _steps_of(short) == _steps_of(general)
    failed = [r for r in short if r.steps[0].status == "error"]
    assert [r.frame_index for r in failed] == [0, 10]
    assert "planned failure on frame 10" in failed[1].steps[0].traceback
    assert all(s.latency_ns >= 0 and s.cpu_ns >= 0 for r in short for s in r.steps)


def test_the_short_path_stops_a_fail_fast_run_at_the_first_failure() -> None:
    records, failure = _run_in("sequential", fail_fast=True)
    assert [r.frame_index for r in records] == [0]
    assert failure is not None
    index, step = failure  # type: ignore[misc]
    assert (index, step.algorithm, step.status) == (0, "p", "error")


class InterruptOn7(Algorithm):
    """Ctrl-C arrives while frame 7 is in this step."""

    role = Role.CONTROL

    def step(self, frame: Frame, upstream: StageOutputs) -> ControlCommands:
        if frame.index == 7:
            raise KeyboardInterrupt
        return ControlCommands()


def _burn(seconds: float) -> None:
    """Spend ``seconds`` of this thread's CPU time."""
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


def _noop_engine(*last: str) -> Engine:
    noop = "redrive.benchmarks.engine:"
    names = (noop + "NoopPerception", noop + "NoopPlanning", *(last or (noop + "NoopControl",)))
    pipeline = PipelineConfig(
        stages=tuple(
            StageSpec(name=f"s{i}", algorithms=(AlgorithmSpec(name=f"a{i}", plugin=cls),))
            for i, cls in enumerate(names)
        )
    )
    return Engine(build_graph(pipeline, LogInputs()), pipeline, inputs=LogInputs())


def test_the_short_path_keeps_log_reading_and_the_sink_out_of_the_steps_cpu() -> None:
    # the thread CPU clock is chained from step to step across frames: what the engine does
    # between two frames (reading the log, handing the record on) must not land in a step
    def frames() -> Iterator[Frame]:
        for i in range(3 * _seq.READ_AHEAD):
            if i in {5, 20}:
                _burn(0.02)  # a slow frame to read
            yield Frame(stamp_ns=i * 10, index=i)

    kept: list[FrameRecord] = []

    def sink(record: FrameRecord) -> None:
        if record.frame_index in {3, 30}:
            _burn(0.02)  # a slow write
        kept.append(record)

    engine = _noop_engine()
    try:
        report = engine.run(frames(), sink=sink)
    finally:
        engine.close()
    assert report.frames == len(kept) == 3 * _seq.READ_AHEAD
    assert [r.frame_index for r in kept] == list(range(3 * _seq.READ_AHEAD))
    assert max(s.cpu_ns for r in kept for s in r.steps) < 10_000_000  # ns; each burn is 20 ms


def test_the_short_path_hands_on_each_frame_before_reading_past_its_chain(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(_seq, "CHAIN_NS", 0)  # every chain ends after its first frame
    kept: list[FrameRecord] = []
    seen: list[int] = []

    def frames() -> Iterator[Frame]:
        for i in range(6):
            seen.append(len(kept))  # records handed on when frame i is read
            yield Frame(stamp_ns=i * 10, index=i)

    engine = _noop_engine()
    try:
        engine.run(frames(), sink=kept.append)
    finally:
        engine.close()
    assert seen == [0, 1, 2, 3, 4, 5]
    assert [r.frame_index for r in kept] == [0, 1, 2, 3, 4, 5]


def test_ctrl_c_in_a_short_path_step_hands_on_the_frames_before_it() -> None:
    kept: list[FrameRecord] = []
    engine = _noop_engine(f"{__name__}:InterruptOn7")
    try:
        report = engine.run([Frame(stamp_ns=i * 10, index=i) for i in range(12)], sink=kept.append)
    finally:
        engine.close()
    assert report.status is RunStatus.INTERRUPTED
    assert [r.frame_index for r in kept] == list(range(7))
    assert report.frames == 7


def _counted_one_by_one(engine: Engine, records: list[FrameRecord]) -> StatsCollector:
    stats = StatsCollector([p for _, planned in engine.graph.stages for p in planned])
    for record in records:
        stats.add(record)
    return stats


@pytest.mark.parametrize("stop_at", [None, 13])
def test_the_short_path_counts_what_it_hands_on(stop_at: int | None) -> None:
    # the short path counts its statistics a chain at a time: the report must be what counting
    # the frames handed on one by one gives — also when Ctrl-C lands in the sink mid-chain
    pipeline = _three_stages()
    engine = Engine(build_graph(pipeline, LogInputs()), pipeline, inputs=LogInputs())
    kept: list[FrameRecord] = []

    def sink(record: FrameRecord) -> None:
        if record.frame_index == stop_at:
            raise KeyboardInterrupt
        kept.append(record)

    try:
        report = engine.run(
            [Frame(stamp_ns=i * 10, index=i, missing=("gnss",) * (i % 3 == 0)) for i in range(25)],
            sink=sink,
        )
    finally:
        engine.close()
    assert [r.frame_index for r in kept] == list(range(25 if stop_at is None else stop_at))
    expected = _counted_one_by_one(engine, kept).report(
        status=report.status, wall_s=report.wall_s, late_frames=0, failure=None
    )
    assert report.frames == expected.frames == len(kept)
    assert report.failed_frames == expected.failed_frames == len(range(0, len(kept), 10))
    assert report.log_span_s == expected.log_span_s
    assert dict(report.missing_inputs) == dict(expected.missing_inputs)
    assert report.algorithms == expected.algorithms
    n = len(kept)
    assert [a.ok for a in report.algorithms] == [n - len(range(0, n, 10)), n, n]
