"""`redrive bench engine` runs and reports consistent numbers (a smoke test: no timing asserts)."""

from __future__ import annotations

import json

import pytest

from redrive.benchmarks.engine import EngineBenchResult, bench_engine
from redrive.cli.main import main


def test_bench_engine_small() -> None:
    result = bench_engine(frames=20, work_ms=0.05, repeats=1)
    assert result.frames == 20
    for value in (result.bare_s, result.sequential_s, result.pipelined_s, result.noop_engine_s):
        assert value > 0
    assert result.sequential_ratio > 0
    assert result.writer_us_per_frame is not None


def test_bench_engine_cli_json(capsys: pytest.CaptureFixture[str]) -> None:
    status = main(
        ["bench", "engine", "--frames", "10", "--work-ms", "0.05", "--repeat", "1", "--json"]
    )
    assert status == 0
    out = json.loads(capsys.readouterr().out)
    assert out["engine"]["frames"] == 10
    assert {"sequential_ratio", "pipelined_ratio", "overhead_us_per_frame"} <= set(out["engine"])


def test_spreads_are_computed_pass_by_pass() -> None:
    passes = {
        "bare": [3.0, 2.0, 4.0],
        "sequential": [3.0, 2.5, 4.0],
        "pipelined": [2.0, 1.0, 4.0],
        "noop_bare": [0.001, 0.001, 0.001],
        "noop_engine": [0.011, 0.031, 0.021],
        "noop_bare_cpu": [0.001, 0.001, 0.001],
        "noop_engine_cpu": [0.006, 0.011, 0.016],
    }
    result = EngineBenchResult(
        frames=1000, work_ms=1.0, work_elements=1, bare_s=3.0, sequential_s=3.0,
        pipelined_s=2.0, noop_bare_s=0.001, noop_engine_s=0.021, writer_s=None,
        noop_bare_cpu_s=0.001, noop_engine_cpu_s=0.011, passes=passes,
    )  # fmt: skip
    spreads = {s.name: s for s in result.spreads()}
    assert set(spreads) == {
        "sequential ÷ bare loop",
        "pipelined ÷ bare loop",
        "engine µs/frame, wall",
        "engine µs/frame, CPU",
    }
    seq = spreads["sequential ÷ bare loop"]
    assert seq.values == pytest.approx((1.0, 0.8, 1.0))
    assert (seq.min, seq.median, seq.max) == pytest.approx((0.8, 1.0, 1.0))
    assert seq.met is True  # median 1.0 ≥ 0.95 although one pass missed
    pipe = spreads["pipelined ÷ bare loop"]
    assert pipe.median == pytest.approx(1.5)
    assert pipe.met is True
    wall = spreads["engine µs/frame, wall"]
    assert wall.values == pytest.approx((10.0, 30.0, 20.0))
    assert wall.met is True  # median 20 ≤ 20
    cpu = spreads["engine µs/frame, CPU"]
    assert cpu.median == pytest.approx(10.0)
    assert result.overhead_cpu_us_per_frame == pytest.approx(10.0)


def test_bench_engine_cli_repeat_prints_the_spread(capsys: pytest.CaptureFixture[str]) -> None:
    status = main(["bench", "engine", "--frames", "10", "--work-ms", "0.05", "--repeat", "3"])
    assert status == 0
    out = capsys.readouterr().out
    assert "targets over 3 interleaved passes" in out
    for name in ("sequential ÷ bare loop", "pipelined ÷ bare loop", "with writer µs/frame, CPU"):
        assert name in out
    assert "thread CPU time" in out
