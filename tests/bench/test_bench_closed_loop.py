"""`redrive bench closed-loop` runs a short closed loop and reports a consistent split (no timing
asserts: speed targets are met in the benchmark, BENCHMARKS.md)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from redrive.benchmarks import cli as closed_loop_cli
from redrive.benchmarks import closed_loop
from redrive.benchmarks.closed_loop import bench_closed_loop, scenario_with_lidar
from redrive.cli.main import main
from redrive.errors import ConfigError
from redrive.sim.scenario import load_scenario


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
    assert result.cpu_s > 0
    # the CPU split: parts of the process's CPU, the world alone's apart
    assert 0 < result.simulation_cpu_s + result.algorithms_cpu_s <= result.cpu_s
    assert result.baseline_cpu_s > 0
    # the frame loop's CPU holds the simulation's and the algorithms' (same thread)
    assert result.simulation_cpu_s + result.algorithms_cpu_s <= result.loop_cpu_s <= result.cpu_s
    assert result.cpu_ratio == pytest.approx(result.loop_cpu_s / result.baseline_cpu_s)
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
    assert set(out["split_s"]) == {"rendering", "simulation", "algorithms", "other"}
    assert out["split_s"]["rendering"] == 0.0  # nothing is rendered at object level
    assert out["lidar"] is None
    assert out["target"] == 100.0
    assert len(out["passes"]["baseline"]) == 1


def test_bench_sensor_level_splits_rendering_out_with_the_64_beam_lidar() -> None:
    result = bench_closed_loop(scenario="cut_in", duration_s=0.4, level="sensor", repeats=1)
    assert result.lidar == "HDL-64E"
    assert result.frames == 3  # the first frame comes one LiDAR period after the start
    assert result.rendering_s > 0
    assert result.simulation_s > 0
    parts = result.rendering_s + result.simulation_s + result.algorithms_s + result.other_s
    assert parts == pytest.approx(result.wall_s)
    assert result.to_json()["split_s"]["rendering"] == result.rendering_s


def test_scenario_with_lidar_swaps_only_the_first_3d_lidar(tmp_path: Path) -> None:
    path = scenario_with_lidar("urban", "HDL-64E", tmp_path)
    swapped, original = load_scenario(path), load_scenario("urban")
    assert swapped.rig["lidar_top"]["preset"] == "HDL-64E"
    assert original.rig["lidar_top"]["preset"] == "HDL-32E"
    rest = {k: v for k, v in swapped.rig.items() if k != "lidar_top"}
    assert rest == {k: v for k, v in original.rig.items() if k != "lidar_top"}
    assert dataclasses.replace(swapped, rig=original.rig, source=original.source) == original


def test_scenario_with_lidar_refuses_what_is_not_a_3d_lidar(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="'UTM-30LX' is not a 3D LiDAR preset"):
        scenario_with_lidar("urban", "UTM-30LX", tmp_path)
    with pytest.raises(ConfigError, match="--lidar applies to the sensor level"):
        bench_closed_loop(level="object", lidar="HDL-64E", repeats=1)
