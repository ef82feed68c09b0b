"""The verdict on closed-loop drives: nuPlan's comfort (the reference pipeline's hard stop behind
the braking lead fails it, a planner that keeps changing its speed fails it, one that holds its
speed passes), nuPlan's scenario score of those drives, and deviation as part of the verdict
(a log-backed closed loop that left its log gets a caveat)."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.config import load_pipeline, pipeline_from_plugins
from redrive.evaluation import EvalData
from redrive.evaluation.closedloop import Comfort, NuplanScenarioScore
from redrive.evaluation.closedloop.deviation import deviation_caveat
from redrive.results import RunStatus, open_run

PLUGINS = "tests.closedloop.plugins"
FOLLOWER = Path(__file__).parent / "data" / "follower.toml"


def _values(out: Path, metric: Comfort | NuplanScenarioScore) -> dict[str, float]:
    return dict(metric.evaluate(EvalData(open_run(out))).values)


def test_the_reference_pipelines_hard_stop_behind_the_braking_lead_is_uncomfortable(
    tmp_path: Path,
) -> None:
    out = tmp_path / "reference"
    # the catalogue's reference pipeline (docs/closed_loop.md), default configuration
    pipeline = pipeline_from_plugins(
        perception=["noisy-oracle"], planning=["idm-planner"], control=["pure-pursuit-pid"]
    )
    request = ClosedLoopRequest(scenario="lead_vehicle_hard_brake", pipeline=pipeline, out=out)
    assert run_closed_loop(request).status is RunStatus.COMPLETE
    comfort = _values(out, Comfort())
    # the ego stops behind its lead at about -8 m/s² (the states' own acceleration, smoothed
    # with nuPlan's window of 8): far below nuPlan's -4.05 m/s²
    assert comfort["acceleration_from_states"] == 1.0
    assert comfort["min_lon_accel_mps2"] < -7.0
    assert comfort["lon_accel_mps2_within_bound"] == 0.0
    assert comfort["comfortable"] == 0.0
    score = _values(out, NuplanScenarioScore())
    assert score["ego_is_comfortable"] == 0.0
    assert score["no_ego_at_fault_collisions"] == 1.0
    # every multiplier 1: the score is the weighted average without comfort's 2 of 16
    assert score["multiplier"] == 1.0
    expected = (
        5 * score["ego_progress_along_expert_route"]
        + 5 * score["time_to_collision_within_bound"]
        + 4 * score["speed_limit_compliance"]
    ) / 16
    assert abs(score["nuplan_scenario_score"] - expected) < 1e-12


def _drive(tmp_path: Path, name: str, plugin: str, config: str = "") -> Path:
    out = tmp_path / name
    toml = tmp_path / f"{name}.toml"
    toml.write_text(
        '[[stage]]\nname = "planning"\n[[stage.algorithm]]\n'
        f'name = "{name}"\nplugin = "{PLUGINS}:{plugin}"\nconfig = {{ {config} }}\n'
    )
    pipeline = load_pipeline(toml)
    request = ClosedLoopRequest(scenario=str(FOLLOWER), pipeline=pipeline, out=out)
    assert run_closed_loop(request).status is RunStatus.COMPLETE
    return out


def test_a_jerky_planner_is_uncomfortable_and_a_steady_one_is_not(tmp_path: Path) -> None:
    jerky = _values(_drive(tmp_path, "jerky", "Jerky"), Comfort())
    assert jerky["comfortable"] == 0.0
    # braking from 20 to 12 m/s and back every second: past the acceleration and jerk bounds
    assert jerky["min_lon_accel_mps2"] < -4.05
    assert jerky["max_abs_lon_jerk_mps3"] > 4.13
    steady = _values(_drive(tmp_path, "steady", "Straight", "speed_mps = 20.0"), Comfort())
    assert steady["comfortable"] == 1.0
    assert steady["min_lon_accel_mps2"] > -0.5
    assert steady["max_abs_jerk_mps3"] < 1.0


def test_a_deviated_log_backed_closed_loop_gets_a_caveat(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize

    scenario = tmp_path / "follower.toml"  # an IMU only: the log is paced by it, cheap to write
    scenario.write_text(
        FOLLOWER.read_text() + '\n[rig.imu]\nkind = "imu"\nxyz = [0.0, 0.0, 0.5]\nrate_hz = 10\n'
    )
    log = tmp_path / "follower.mcap"
    synthesize(load_scenario(str(scenario)), log, duration_s=3.0, seed=5)
    out = tmp_path / "still"
    pipeline = pipeline_from_plugins(planning=[f"{PLUGINS}:StandStill"])
    request = ClosedLoopRequest(scenario=str(log), pipeline=pipeline, out=out)
    assert run_closed_loop(request).status is RunStatus.COMPLETE
    run = open_run(out)
    assert run.manifest.closed_loop["backend"] == "log"
    flagged = [r["frame_index"] for r in run.table("closed_loop").to_pylist() if r["deviated"]]
    assert flagged  # the logged ego drives on at 20 m/s, the driven one stops
    comfort = _values(out, Comfort())
    assert comfort["deviated_frames"] == len(flagged)
    assert main(["evaluate", str(out), "--metric", "comfort"]) == 0
    printed = " ".join(capsys.readouterr().out.split())
    assert f"caveat: this log-backed closed loop drove {len(flagged)} of" in printed
    assert "past 2 m / 10°" in printed
    assert "deviated_frames" in printed
    # a synthetic closed loop re-simulates its world: no caveat there
    synthetic = _drive(tmp_path, "steady", "Straight", "speed_mps = 20.0")
    assert deviation_caveat(open_run(synthetic)) is None
