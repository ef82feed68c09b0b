"""The engine's short per-frame path (one in-process algorithm per stage) records what the
general path records, and leaves an algorithm that overrides ``run_step`` on that override."""

from __future__ import annotations

from redrive.config import AlgorithmSpec, PipelineConfig, StageSpec
from redrive.engine import Engine, LogInputs, build_graph
from redrive.results import FrameRecord
from redrive.types import Frame

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
