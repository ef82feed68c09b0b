"""A synthetic log carries its scenario's road map (MCAP metadata); replaying it stores the map in
the run, so the map metrics score an open-loop run of a synthetic log too."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.config import pipeline_from_plugins
from redrive.engine import RunRequest, run_log
from redrive.evaluation.closedloop import DrivableAreaCompliance
from redrive.evaluation.evaluator import evaluate_run
from redrive.io import open_log
from redrive.io.content import LogScenario, log_road_map, log_scenario
from redrive.results import open_run
from redrive.sim.roadmap import scenario_road_map
from redrive.sim.scenario import load_scenario
from redrive.sim.synth import synthesize
from redrive.testing.demo_log import write_demo_bag


@pytest.fixture(scope="module")
def cut_in_1s(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """1 s of ``cut_in``, made once for the module's tests (they only read it)."""
    log = tmp_path_factory.mktemp("cut_in") / "cut_in.mcap"
    synthesize(load_scenario("cut_in"), log, duration_s=1.0)
    return log


def test_a_replayed_synthetic_log_brings_its_road_map(cut_in_1s: Path, tmp_path: Path) -> None:
    log = cut_in_1s
    with open_log(log) as reader:
        assert reader.capabilities.road_map
        assert reader.capabilities.scenario
        assert log_road_map(reader) is not None
        assert log_scenario(reader) == LogScenario(name="cut_in", seed=3, duration_s=1.0)
    out = tmp_path / "run"
    pipeline = pipeline_from_plugins(perception=["noisy-oracle"], planning=["idm-planner"])
    run_log(RunRequest(log=log, pipeline=pipeline, out=out))
    stored = open_run(out).road_map()
    assert stored is not None
    expected = scenario_road_map(load_scenario("cut_in"))
    assert [lane.lane_id for lane in stored.lanes] == [lane.lane_id for lane in expected.lanes]
    # and what it was made from: compare pairs it with a closed loop of the same scenario
    assert open_run(out).manifest.log.scenario == {"name": "cut_in", "seed": 3, "duration_s": 1.0}
    summary = evaluate_run(out, metrics=[DrivableAreaCompliance()])
    assert not summary.skipped
    (scored,) = summary.scored
    assert scored.result.values["drivable_area_compliance"] == 1.0  # the scripted ego


def test_a_closed_loop_on_a_synthetic_log_brings_its_road_map(
    cut_in_1s: Path, tmp_path: Path
) -> None:
    log = cut_in_1s
    out = tmp_path / "closed"
    pipeline = pipeline_from_plugins(perception=["noisy-oracle"], planning=["idm-planner"])
    run_closed_loop(ClosedLoopRequest(scenario=str(log), pipeline=pipeline, out=out))
    stored = open_run(out).road_map()
    assert stored is not None
    expected = scenario_road_map(load_scenario("cut_in"))
    assert [lane.lane_id for lane in stored.lanes] == [lane.lane_id for lane in expected.lanes]
    summary = evaluate_run(out, metrics=[DrivableAreaCompliance()])
    assert not summary.skipped, summary.skipped


def test_a_log_without_a_map_gives_a_run_without_one(tmp_path: Path) -> None:
    bag = write_demo_bag(tmp_path / "demo.bag")  # a ROS 1 bag: no named metadata at all
    with open_log(bag) as reader:
        assert not reader.capabilities.road_map
        assert log_road_map(reader) is None
        assert log_scenario(reader) is None
    out = tmp_path / "run"
    run_log(RunRequest(log=bag, pipeline=pipeline_from_plugins(planning=["idm-planner"]), out=out))
    assert open_run(out).road_map() is None
    assert open_run(out).manifest.log.scenario == {}
