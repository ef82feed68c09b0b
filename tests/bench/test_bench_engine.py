"""`redrive bench engine` runs and reports consistent numbers (a smoke test: no timing asserts)."""

from __future__ import annotations

import json

import pytest

from redrive.benchmarks.engine import bench_engine
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
