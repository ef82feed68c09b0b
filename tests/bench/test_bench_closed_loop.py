"""`redrive bench closed-loop` runs a short closed loop and reports a consistent split (no timing
asserts: speed targets are met in the benchmark, BENCHMARKS.md)."""

from __future__ import annotations

import json

import pytest

from redrive.benchmarks import closed_loop
from redrive.benchmarks.cli import closed_loop as closed_loop_cli
from redrive.benchmarks.closed_loop import bench_closed_loop
from redrive.cli.main import main
from redrive.errors import ConfigError


def test_bench_closed_loop_split_adds_up() -> None:
    result = bench_closed_loop(scenario="cut_in", duration_s=1.0, repeats=1)
    assert result.frames == 10
    assert result.duration_s == pytest.approx(1.0)
    assert result.simulation_s > 0
    assert result.algorithms_s > 0
    assert result.baseline_s > 0
    parts = result.simulation_s + result.algorithms_s + result.other_s
    assert parts == pytest.approx(result.wall_s)
    assert result.total_s >= result.wall_s
    assert set(result.algorithm_ms) == {"noisy-oracle", "idm-planner", "pure-pursuit-pid"}
    # the closed loop steps two worlds and runs three algorithms: never cheaper than one world
    assert result.ratio > 1.0


def test_bench_closed_loop_refuses_an_unknown_level() -> None:
    with pytest.raises(ConfigError, match="level 'pixels' is not one of object, sensor"):
        bench_closed_loop(level="pixels", repeats=1)


def test_cli_levels_match_the_benchmark() -> None:
    assert closed_loop_cli.LEVELS == closed_loop.LEVELS


def test_bench_closed_loop_cli_json(capsys: pytest.CaptureFixture[str]) -> None:
    status = main(
        [
            "bench",
            "closed-loop",
            "--scenario",
            "cut_in",
            "--duration",
            "0.5",
            "--repeat",
            "1",
            "--json",
        ]
    )
    assert status == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frames"] == 5
    assert out["level"] == "object"
    assert set(out["split_s"]) == {"simulation", "algorithms", "other"}
    assert out["target"] == 100.0
    assert len(out["passes"]["baseline"]) == 1
