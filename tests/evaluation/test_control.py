"""Control metrics on a hand-built run with a known offset between the logged ego and the plan.

The logged ego drives straight at 10 m/s with heading 0.5 rad; frames every 0.1 s. Every plan
(base_link of its frame) is a straight line from (0, 0.5) in direction a = atan(0.1) at 12 m/s.
At the next frame the ego is 1 m ahead, at (1, 0) in the plan's base_link; so, with
sin a = 0.1/√1.01 = 0.0995037, cos a = 1/√1.01 = 0.9950372:

* lateral error = (1 − 0, 0 − 0.5) · (−sin a, cos a) = −sin a − 0.5 cos a = −0.5970223 m
* heading error = 0 − a = −0.0996687 rad
* speed error = 10 − 12 = −2 m/s
* longitudinal error = (1, −0.5) · (cos a, sin a) − 12 · 0.1 = 0.9452853 − 1.2 = −0.2547147 m
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import ConfigError
from redrive.evaluation.base import EvalData, MetricSkipped
from redrive.evaluation.control import ControlMetrics
from redrive.results import (
    AlgorithmEntry,
    FrameRecord,
    PipelineInfo,
    RunSetup,
    RunWriter,
    SourceLog,
    StepRecord,
    open_run,
)
from redrive.types import ControlCommands, PlannedPath, Role, VehicleState

T0_NS = 1_700_000_000_000_000_000
DT_NS = 100_000_000
HEADING = 0.5
A = math.atan(0.1)


def setup(planners: tuple[str, ...] = ("planner",)) -> RunSetup:
    algos = [
        AlgorithmEntry(name=p, version="1", config_hash=p, role=Role.PLANNING) for p in planners
    ]
    algos.append(AlgorithmEntry(name="ctrl", version="1", config_hash="c", role=Role.CONTROL))
    return RunSetup(
        log=SourceLog(path="synthetic", sha256="x", format="synthetic"),
        seed=0,
        pipeline=PipelineInfo(first_frame=0),
        algorithms=tuple(algos),
    )


def plan(stamp_ns: int) -> PlannedPath:
    t = np.round(np.arange(0.0, 1.0 + 1e-9, 0.1), 10)
    s = 12.0 * t
    wp = np.column_stack([s * math.cos(A), 0.5 + s * math.sin(A), 0 * t, t])
    return PlannedPath(stamp_ns=stamp_ns, waypoints=wp)


def make_run(tmp_path: Path, *, n: int = 10, planners: tuple[str, ...] = ("planner",)) -> Path:
    out = tmp_path / "run"
    c, s = math.cos(HEADING), math.sin(HEADING)
    with RunWriter(out, setup=setup(planners)) as writer:
        for i in range(n):
            stamp = T0_NS + i * DT_NS
            steps = [
                StepRecord(
                    algorithm=p, stage="planning", role="planning", status="ok", output=plan(stamp)
                )
                for p in planners
            ]
            # steering alternates ±0.1 rad, throttle ramps 0.05 per frame; frame 5 is skipped
            cmd = ControlCommands(throttle=0.05 * i, brake=0.0, steering_angle_rad=0.1 * (-1) ** i)
            steps.append(
                StepRecord(
                    algorithm="ctrl",
                    stage="control",
                    role="control",
                    status="skipped" if i == 5 else "ok",
                    output=None if i == 5 else cmd,
                )
            )
            ego = VehicleState(
                stamp_ns=stamp,
                position=np.array([10.0 + i * c, -4.0 + i * s, 0.0]),
                velocity=np.array([10.0 * c, 10.0 * s, 0.0]),
                heading_rad=HEADING,
            )
            writer.write_frame(
                FrameRecord(frame_index=i, stamp_ns=stamp, steps=tuple(steps), vehicle_state=ego)
            )
    return out


def test_tracking_errors_on_a_known_offset(tmp_path: Path) -> None:
    res = ControlMetrics().evaluate(EvalData(open_run(make_run(tmp_path)), "ctrl"))
    assert res.headline == "lateral_rmse_m"
    # frames 0…8 have a next ego state; frame 5 has no command → 8 frames
    frames, lateral = res.per_frame["lateral_error_m"]
    assert frames.tolist() == [0, 1, 2, 3, 4, 6, 7, 8]
    np.testing.assert_allclose(lateral, -0.5970223, atol=1e-6)
    assert res.values["lateral_rmse_m"] == pytest.approx(0.5970223, abs=1e-6)
    assert res.values["lateral_max_m"] == pytest.approx(0.5970223, abs=1e-6)
    assert res.values["heading_rmse_rad"] == pytest.approx(0.0996687, abs=1e-6)
    np.testing.assert_allclose(res.per_frame["heading_error_rad"][1], -0.0996687, atol=1e-6)
    assert res.values["speed_rmse_mps"] == pytest.approx(2.0, abs=1e-9)
    np.testing.assert_allclose(res.per_frame["speed_error_mps"][1], -2.0, atol=1e-9)
    assert res.values["longitudinal_rmse_m"] == pytest.approx(0.2547147, abs=1e-6)
    assert res.values["frames"] == 8


def test_command_smoothness(tmp_path: Path) -> None:
    res = ControlMetrics().evaluate(EvalData(open_run(make_run(tmp_path)), "ctrl"))
    # commands at frames 0-4, 6-9 → 8 pairs; steering ±0.1 alternating: Δ = ±0.2 over 0.1 s
    # = ±2 rad/s, except 4 → 6 (both +0.1 over 0.2 s) = 0:
    # RMSE = sqrt(7 · 2² / 8) = sqrt(3.5) = 1.8708287, max 2
    frames, steer = res.per_frame["steering_rate_rad_s"]
    assert frames.tolist() == [1, 2, 3, 4, 6, 7, 8, 9]
    np.testing.assert_allclose(steer, [-2, 2, -2, 2, 0, -2, 2, -2], atol=1e-9)
    assert res.values["steering_rate_rmse_rad_s"] == pytest.approx(math.sqrt(3.5))
    assert res.values["steering_rate_max_rad_s"] == pytest.approx(2.0)
    # throttle 0.05 per 0.1 s = 0.5 /s everywhere (4 → 6: 0.1 over 0.2 s)
    assert res.values["throttle_rate_rmse_1_s"] == pytest.approx(0.5)
    assert res.values["throttle_rate_max_1_s"] == pytest.approx(0.5)
    assert res.values["brake_rate_max_1_s"] == 0.0


def test_the_planner_must_be_unambiguous(tmp_path: Path) -> None:
    run = open_run(make_run(tmp_path, n=3, planners=("a", "b")))
    with pytest.raises(MetricSkipped, match="pass planner=NAME"):
        ControlMetrics().evaluate(EvalData(run, "ctrl"))
    with pytest.raises(ConfigError, match="no planning algorithm 'c'"):
        ControlMetrics(planner="c").evaluate(EvalData(run, "ctrl"))
    res = ControlMetrics(planner="b").evaluate(EvalData(run, "ctrl"))
    assert res.values["lateral_rmse_m"] == pytest.approx(0.5970223, abs=1e-6)


def test_a_single_frame_gives_nan_not_zero(tmp_path: Path) -> None:
    res = ControlMetrics().evaluate(EvalData(open_run(make_run(tmp_path, n=1)), "ctrl"))
    assert math.isnan(res.values["lateral_rmse_m"])
    assert math.isnan(res.values["steering_rate_rmse_rad_s"])
    assert res.values["frames"] == 0


def test_demo_run_gives_finite_values(demo_run: Path) -> None:
    res = ControlMetrics().evaluate(EvalData(open_run(demo_run), "controller"))
    assert all(math.isfinite(v) for v in res.values.values()), dict(res.values)
    assert res.values["frames"] > 0
