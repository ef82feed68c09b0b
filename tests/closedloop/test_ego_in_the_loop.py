"""The ego in closed loop (issue 33, items 5 and 6): the built-in tracker starts from rest on a
scenario and on a real bag; the tyres' friction circle holds a weaving planner."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.config import PipelineConfig, load_pipeline, pipeline_from_plugins
from redrive.results import Run, RunStatus, open_run
from redrive.sim.ego import TyreLimit

PLUGINS = "tests.closedloop.plugins"
HUSKY = "rosbag1_real/robot_localization_test1_husky.bag"
#: urban.toml's lights: west/east red from 5 s to 22 s, then green
URBAN_GREEN_S = 22.0


def _run(out: Path, scenario: str, pipeline: PipelineConfig, **kw: object) -> Run:
    request = ClosedLoopRequest(scenario=scenario, pipeline=pipeline, out=out, **kw)  # type: ignore[arg-type]
    report = run_closed_loop(request)
    assert report.status is RunStatus.COMPLETE
    return open_run(out)


def _pipeline(tmp_path: Path, plugin: str, role: str, config: str = "") -> PipelineConfig:
    toml = tmp_path / "pipeline.toml"
    toml.write_text(
        f'[[stage]]\nname = "{role}"\n[[stage.algorithm]]\nname = "it"\n'
        f'plugin = "{plugin}"\n' + (f"config = {{ {config} }}\n" if config else "")
    )
    return load_pipeline(toml)


@pytest.mark.parametrize(
    "perception", [(), ("noisy-oracle",)], ids=["planner-only", "with-perception"]
)
def test_urban_idm_planner_without_control_crosses_after_the_green(
    tmp_path: Path, perception: tuple[str, ...]
) -> None:
    """`redrive run urban --closed-loop --planning idm-planner`: the planner stops the ego at the
    red light (with `--perception noisy-oracle`: behind the lead car queued there) and, once the
    light is green, the ego drives off across the junction (the old tracker held the brake from
    frame ~120 to the end: its reference speed at t = 0 of a plan from rest was 0).  Planning
    blind, the ego drives through the queued lead car: that is the planner's doing."""
    pipeline = pipeline_from_plugins(perception=list(perception), planning=["idm-planner"])
    run = _run(tmp_path / "urban", "urban", pipeline)
    rows = run.table("closed_loop").to_pylist()
    assert {r["source"] for r in rows} == {"tracker"}
    ego = run.ego()
    t0 = ego[0].stamp_ns
    t_s = {i: (s.stamp_ns - t0) / 1e9 for i, s in ego.items()}
    x = {i: float(s.position[0]) for i, s in ego.items()}
    # it waited: standing (below 0.5 m/s) before the junction from 12 s to the green
    waiting = [i for i in ego if 12.0 <= t_s[i] < URBAN_GREEN_S]
    assert waiting
    assert all(ego[i].speed_mps < 0.5 and x[i] < -10.0 for i in waiting)
    # … and crossed: into the junction (x > 0) only after the green, out of it on the far side
    into = min(i for i in ego if x[i] > 0.0)
    assert t_s[into] > URBAN_GREEN_S
    assert x[max(ego)] > 50.0
    assert ego[max(ego)].speed_mps > 5.0


def test_husky_bag_the_ego_starts_when_the_plan_says_so(shared_data: Path, tmp_path: Path) -> None:
    """The real Husky bag starts at 0.18 m/s; a planner that wants 1 m/s gets it (the old
    tracker read the plan's speed at t = 0 and never passed 0.18 m/s)."""
    bag = shared_data / HUSKY
    pipeline = _pipeline(tmp_path, "idm-planner", "planning", "v0_mps = 1.0")
    run = _run(tmp_path / "husky", str(bag), pipeline, duration_s=15.0)
    speeds = np.array([s.speed_mps for _, s in sorted(run.ego().items())])
    assert speeds[0] < 0.2
    assert speeds.max() > 0.9
    assert speeds[-50:].min() == pytest.approx(1.0, abs=0.1)  # it holds the plan's 1 m/s


@pytest.mark.parametrize(
    ("plugin", "role"),
    [(f"{PLUGINS}:Weaver", "control"), (f"{PLUGINS}:WeavingPlanner", "planning")],
    ids=["control", "through-the-tracker"],
)
def test_a_weaver_stays_inside_the_friction_circle(tmp_path: Path, plugin: str, role: str) -> None:
    """Full lock left and right at 25 m/s (cut_in): 150 m/s² of lateral acceleration asked of
    the tyres; the ego gets at most μ·g = 8.83 m/s², combined with its longitudinal
    acceleration, and a yaw rate of at most μ·g / v."""
    run = _run(tmp_path / "weave", "cut_in", _pipeline(tmp_path, plugin, role), duration_s=6.0)
    limit = TyreLimit().max_accel_mps2
    ego = run.manifest.closed_loop["ego"]
    assert ego["tyres"]["friction_coefficient"] == 0.9
    assert ego["tyres"]["friction_circle_mps2"] == pytest.approx(limit)
    states = [s for _, s in sorted(run.ego().items())]
    total = np.array([float(np.hypot(*s.acceleration[:2])) for s in states])
    lateral = np.array([s.speed_mps * abs(s.yaw_rate_rad_s) for s in states])
    yaw_rate = np.array([abs(s.yaw_rate_rad_s) for s in states])
    speed = np.array([s.speed_mps for s in states])
    assert total.max() <= limit * (1.0 + 1e-9)
    assert lateral.max() <= limit * (1.0 + 1e-9)
    assert lateral.max() > 0.9 * limit  # it did weave at the limit
    moving = speed > 1.0
    assert (yaw_rate[moving] <= limit / speed[moving] * (1.0 + 1e-9)).all()
    # it weaved: the yaw rate changes sign
    signs = {math.copysign(1.0, s.yaw_rate_rad_s) for s in states if abs(s.yaw_rate_rad_s) > 0.05}
    assert signs == {-1.0, 1.0}
