"""Closed loop on the synthetic backend: the outputs move the ego, the run directory holds the
driven and the logged ego and what moved the car, and the same seed gives the same run."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from redrive.cli.main import main
from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.config import PipelineConfig, load_pipeline, pipeline_from_plugins
from redrive.errors import ConfigError
from redrive.evaluation import Metric
from redrive.evaluation.closedloop import (
    AtFaultCollisions,
    EgoProgress,
    FallbackCommands,
    NavsimPdms,
)
from redrive.evaluation.compare import compare_runs
from redrive.evaluation.evaluator import evaluate_run
from redrive.results import RunStatus, open_run

PLUGINS = "tests.closedloop.plugins"


def _run(out: Path, planning: str, *, scenario: str = "cut_in", duration_s: float = 4.0, **kw):  # type: ignore[no-untyped-def]
    pipeline = pipeline_from_plugins(planning=[planning])
    request = ClosedLoopRequest(
        scenario=scenario, pipeline=pipeline, out=out, duration_s=duration_s, **kw
    )
    report = run_closed_loop(request)
    assert report.status is RunStatus.COMPLETE
    return open_run(out)


def _without_timing(table: pa.Table) -> pa.Table:
    timing = {"wall_ns", "latency_ns", "cpu_ns"}
    return table.drop_columns([c for c in table.column_names if c in timing])


def test_the_planner_drives_and_the_world_follows(tmp_path: Path) -> None:
    run = _run(tmp_path / "still", f"{PLUGINS}:StandStill", duration_s=6.0)
    manifest = run.manifest
    assert manifest.pipeline.mode_manager == "closed_loop"
    assert manifest.closed_loop["backend"] == "synthetic"
    assert manifest.closed_loop["agents"] == "replay"
    assert manifest.closed_loop["tracker"]["name"] == "lqr"
    driven, logged = run.ego(), run.logged_ego()
    assert sorted(driven) == sorted(logged) == list(range(60))  # 6 s at 10 Hz
    start = driven[0].position[:2]
    # a planner that stands still: from 25 m/s the ego brakes — at full brake (8 m/s²) while
    # nuPlan's longitudinal law a = −10/11 · v asks for more, then with that law, v decaying as
    # e^(−0.91 t) from about 9 m/s: ~34 m + ~10 m
    assert driven[0].speed_mps == pytest.approx(25.0)
    speeds = [driven[i].speed_mps for i in range(60)]
    assert speeds[59] < 0.3
    assert all(b <= a for a, b in itertools.pairwise(speeds))  # it only slows
    assert 35.0 < np.linalg.norm(driven[59].position[:2] - start) < 50.0
    # the logged ego (the scenario's own driver) drove on
    assert np.linalg.norm(logged[59].position[:2] - driven[59].position[:2]) > 50.0
    table = run.table("closed_loop").to_pylist()
    assert {r["source"] for r in table} == {"tracker"}
    assert table[-1]["deviation_m"] > 50.0
    assert run.road_map() is not None


@pytest.mark.parametrize("agents", ["replay", "reactive"])
def test_same_seed_same_run(tmp_path: Path, agents: str) -> None:
    a = _run(tmp_path / "a", f"{PLUGINS}:Straight", seed=3, agents=agents)
    b = _run(tmp_path / "b", f"{PLUGINS}:Straight", seed=3, agents=agents)
    for name in ("frames", "ego", "ego_logged", "ground_truth", "closed_loop"):
        assert _without_timing(a.table(name)).equals(_without_timing(b.table(name))), name


@pytest.mark.parametrize(
    ("planner", "reason"),
    [
        ("NanAfterTwoSeconds", "a path with NaN or infinite waypoints"),
        ("EmptyAfterTwoSeconds", "an empty path"),
        ("CameraFrameAfterTwoSeconds", "a path in frame 'camera_front'"),
    ],
)
def test_a_bad_path_brakes_the_run_completes_and_the_metric_shows_it(
    tmp_path: Path, planner: str, reason: str
) -> None:
    out = tmp_path / planner
    run = _run(out, f"{PLUGINS}:{planner}")
    rows = run.table("closed_loop").to_pylist()
    assert len(rows) == 40  # 4 s at 10 Hz: the run completed
    assert {r["source"] for r in rows[:20]} == {"tracker"}
    assert all(r["source"] == "fallback" for r in rows[20:])
    assert reason in rows[25]["reason"]
    assert rows[25]["brake"] == 1.0
    speeds = [s.speed_mps for _, s in sorted(run.ego().items())]
    assert speeds[-1] < speeds[20] - 3.0  # braking since frame 20
    summary = evaluate_run(out, metrics=[FallbackCommands()])
    (scored,) = summary.scored
    assert dict(scored.result.values) == {
        "fallback_frames": 20.0,
        "fallback_ratio": 0.5,
        "driven_frames": 20.0,
    }
    (mark,) = scored.result.bookmarks
    assert (mark.frame_index, mark.kind, mark.severity) == (20, "fallback", 20.0)
    assert reason in mark.detail


def test_the_fallback_metric_skips_an_open_loop_run(tmp_path: Path) -> None:
    log = tmp_path / "cut_in.mcap"
    assert main(["synth", "cut_in", "--duration", "1", "-o", str(log)]) == 0
    out = tmp_path / "open"
    assert main(["run", str(log), "--planning", "idm-planner", "--out", str(out),
                 "--no-progress"]) == 0  # fmt: skip
    summary = evaluate_run(out, metrics=[FallbackCommands()])
    assert not summary.scored
    (skipped,) = summary.skipped
    assert "closed-loop run" in skipped.reason


def test_a_sensor_reading_algorithm_is_refused_before_the_run(tmp_path: Path) -> None:
    pipeline = pipeline_from_plugins(perception=["cluster-detector"], planning=["idm-planner"])
    request = ClosedLoopRequest(scenario="cut_in", pipeline=pipeline, out=tmp_path / "x")
    with pytest.raises(ConfigError, match=r"cluster-detector.*reads lidar.*noisy-oracle"):
        run_closed_loop(request)
    assert not (tmp_path / "x" / "manifest.json").exists()


def test_cli_closed_loop_on_a_scenario_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cli"
    argv = [
        "run", "cut_in", "--closed-loop", "--duration", "2",
        "--perception", "noisy-oracle", "--planning", "idm-planner",
        "--control", "pure-pursuit-pid", "--out", str(out), "--no-progress",
    ]  # fmt: skip
    assert main(argv) == 0
    run = open_run(out)
    assert len(run.ego()) == 20
    assert {r["source"] for r in run.table("closed_loop").to_pylist()} == {"control"}
    capsys.readouterr()
    assert main(["run", "no_such_scenario", "--closed-loop"]) == 1
    assert "no_such_scenario: no such scenario" in capsys.readouterr().err


# -- scored: the closed-loop metrics on closed-loop runs -------------------------------------------

FOLLOWER = Path(__file__).parent / "data" / "follower.toml"


def _score(run_dir: Path, *metrics: Metric) -> dict[str, dict[str, float]]:
    summary = evaluate_run(run_dir, metrics=list(metrics))
    assert not summary.failed, summary.failed
    return {s.metric.name: dict(s.result.values) for s in summary.scored}


def _blind_file(tmp_path: Path, speed_mps: float) -> Path:
    toml = tmp_path / "blind.toml"
    toml.write_text(
        '[[stage]]\nname = "planning"\n[[stage.algorithm]]\nname = "blind"\n'
        f'plugin = "{PLUGINS}:Straight"\nconfig = {{ speed_mps = {speed_mps} }}\n'
    )
    return toml


def _blind(tmp_path: Path, speed_mps: float) -> PipelineConfig:
    return load_pipeline(_blind_file(tmp_path, speed_mps))


def test_a_blind_planner_rear_ends_the_braking_lead_and_is_at_fault(tmp_path: Path) -> None:
    out = tmp_path / "blind"
    request = ClosedLoopRequest(
        scenario="lead_vehicle_hard_brake", pipeline=_blind(tmp_path, 25.0), out=out
    )
    assert run_closed_loop(request).status is RunStatus.COMPLETE
    scores = _score(out, AtFaultCollisions(), NavsimPdms())
    assert scores["at_fault_collisions"]["at_fault_collisions"] >= 1
    assert scores["at_fault_collisions"]["no_at_fault_collisions"] == 0.0
    # NAVSIM: some 4-s plans drive into the braking lead's logged future (NC 0 there)
    assert scores["navsim_pdms"]["nc"] < 1.0
    assert scores["navsim_pdms"]["navsim_pdms"] < 1.0


def _touching(run_dir: Path) -> dict[int, list[int]]:
    """Frame → ids of the ground-truth objects the ego footprint intersects, by shapely on the
    stored tables (independent of the run's own check): ego 4.7 × 1.9 m, centre 1.4 m ahead of
    the rear axle; the objects in base_link."""
    from shapely.geometry import Polygon

    def rect(cx: float, cy: float, yaw: float, length: float, width: float) -> Polygon:
        c, s = np.cos(yaw), np.sin(yaw)
        pts = [(sx * length / 2, sy * width / 2) for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
        return Polygon([(cx + c * x - s * y, cy + s * x + c * y) for x, y in pts])

    ego = rect(4.7 / 2 - 0.95, 0.0, 0.0, 4.7, 1.9)
    out: dict[int, list[int]] = {}
    for frame, objects in open_run(run_dir).ground_truth().items():
        out[frame] = sorted(
            o.object_id
            for o in objects
            if ego.intersects(
                rect(*map(float, o.box.center[:2]), o.box.yaw_rad, *map(float, o.box.size[:2]))
            )
        )
    return out


def test_collisions_are_recorded_per_frame_and_the_run_drives_on(tmp_path: Path) -> None:
    out = tmp_path / "blind"
    request = ClosedLoopRequest(
        scenario="lead_vehicle_hard_brake", pipeline=_blind(tmp_path, 25.0), out=out
    )
    assert run_closed_loop(request).status is RunStatus.COMPLETE
    run = open_run(out)
    rows = {r["frame_index"]: r for r in run.table("closed_loop").to_pylist()}
    touching = _touching(out)
    hit = [f for f in sorted(rows) if touching.get(f)]
    assert hit  # the blind planner does drive into the braking lead
    for f, r in rows.items():
        assert r["collisions"] == len(touching.get(f, []))
        if touching.get(f):
            assert r["collision_object_id"] == touching[f][0]
            assert r["collision_object_class"] == "vehicle"
        else:
            assert r["collision_object_id"] is None
            assert r["collision_object_class"] == ""
    # continue (the default, as nuPlan): the run goes on to the scenario's end
    assert max(rows) > hit[-1] or max(rows) == len(rows) - 1
    assert len(rows) == round(run.manifest.closed_loop["duration_s"] * 10)
    summary = dict(run.manifest.summary.closed_loop)  # type: ignore[union-attr]
    assert run.manifest.closed_loop["on_collision"] == "continue"
    assert summary["on_collision"] == "continue"
    assert summary["collision_frames"] == len(hit)
    assert summary["first_collision_frame"] == hit[0]
    assert summary["stopped"] is None


def test_on_collision_stop_ends_the_run_at_the_first_collision(tmp_path: Path) -> None:
    out = tmp_path / "stop"
    code = main(
        [
            "run",
            "lead_vehicle_hard_brake",
            "--closed-loop",
            "--pipeline",
            str(_blind_file(tmp_path, 25.0)),
            "--on-collision",
            "stop",
            "--out",
            str(out),
            "--no-progress",
        ]
    )
    assert code == 0
    run = open_run(out)
    rows = run.table("closed_loop").to_pylist()
    first = min(f for f, ids in _touching(out).items() if ids)
    assert rows[-1]["frame_index"] == first  # the run ended with the frame of the collision
    assert rows[-1]["collisions"] >= 1
    assert all(r["collisions"] == 0 for r in rows[:-1])
    assert run.manifest.closed_loop["on_collision"] == "stop"
    stopped = dict(run.manifest.summary.closed_loop)["stopped"]  # type: ignore[union-attr]
    assert stopped["reason"] == "collision"
    assert stopped["frame_index"] == first
    assert stopped["object_id"] == rows[-1]["collision_object_id"]
    assert stopped["object_class"] == "vehicle"


def test_bad_closed_loop_options_are_refused(tmp_path: Path) -> None:
    pipeline = pipeline_from_plugins(planning=[f"{PLUGINS}:StandStill"])
    with pytest.raises(ConfigError, match="--on-collision must be one of continue, stop"):
        run_closed_loop(
            ClosedLoopRequest(
                scenario="cut_in", pipeline=pipeline, out=tmp_path / "a", on_collision="halt"
            )
        )
    with pytest.raises(ConfigError, match="friction coefficient must be a positive"):
        run_closed_loop(
            ClosedLoopRequest(
                scenario="cut_in", pipeline=pipeline, out=tmp_path / "b", friction_coefficient=0.0
            )
        )


def test_a_follower_rear_ends_a_braking_ego_when_replayed_and_brakes_when_reactive(
    tmp_path: Path,
) -> None:
    found = {}
    for agents in ("replay", "reactive"):
        out = tmp_path / agents
        _run(out, f"{PLUGINS}:StandStill", scenario=str(FOLLOWER), duration_s=8.0, agents=agents)
        found[agents] = _score(out, AtFaultCollisions())["at_fault_collisions"]
        behind = [
            -float(o.box.center[0])
            for objs in open_run(out).ground_truth().values()
            for o in objs
            if o.box.center[0] < 0
        ]
        found[agents]["closest_behind_m"] = min(behind)
    # replayed, the follower keeps its script and runs into the ego: a collision, not at fault
    assert found["replay"]["collisions"] >= 1
    assert found["replay"]["at_fault_collisions"] == 0
    assert found["replay"]["no_at_fault_collisions"] == 1.0
    # reactive, its IDM sees the ego brake: it stops behind (ego rear bumper at -0.95 m,
    # the follower's half length ~2.3 m behind its centre)
    assert found["reactive"]["collisions"] == 0
    assert found["reactive"]["closest_behind_m"] > 0.95 + 2.3


def test_a_planner_that_never_moves_makes_no_progress(tmp_path: Path) -> None:
    scenario = tmp_path / "parked_start.toml"
    scenario.write_text(
        FOLLOWER.read_text().replace(
            "set_speed_mps = 20.0", "set_speed_mps = 20.0\ninitial_speed_mps = 0.0"
        )
    )
    out = tmp_path / "still"
    _run(out, f"{PLUGINS}:StandStill", scenario=str(scenario), duration_s=8.0)
    driven = open_run(out).ego()
    assert max(s.speed_mps for s in driven.values()) < 0.01
    scores = _score(out, EgoProgress(), NavsimPdms())
    assert abs(scores["ego_progress"]["ego_progress_m"]) < 0.01
    # nuPlan's ratio floors both distances at 2 m: 2 m / the expert's ~45 m
    ratio = scores["ego_progress"]["ego_progress_ratio"]
    assert ratio == pytest.approx(2.0 / scores["ego_progress"]["expert_progress_m"])
    assert ratio < 0.05
    # NAVSIM: a standing plan makes no progress against PDM-Closed's (EP 0) unless PDM-Closed
    # itself makes less than 5 m (then EP is 1 for every proposal); it collides with nothing
    # and TTC ignores a stopped ego
    pdms = scores["navsim_pdms"]
    assert pdms["nc"] == pdms["dac"] == 1.0
    assert pdms["ep"] < 0.5
    assert pdms["navsim_pdms"] == pytest.approx(
        (5 * pdms["ep"] + 5 * pdms["ttc"] + 2 * pdms["c"]) / 12
    )


def test_two_planners_in_closed_loop_compare_on_the_same_scenario(tmp_path: Path) -> None:
    blind, careful = tmp_path / "blind", tmp_path / "careful"
    run_closed_loop(
        ClosedLoopRequest(
            scenario="lead_vehicle_hard_brake", pipeline=_blind(tmp_path, 25.0), out=blind
        )
    )
    reference = pipeline_from_plugins(
        perception=["noisy-oracle"], planning=["idm-planner"], control=["pure-pursuit-pid"]
    )
    run_closed_loop(
        ClosedLoopRequest(scenario="lead_vehicle_hard_brake", pipeline=reference, out=careful)
    )
    for out in (blind, careful):
        evaluate_run(out, metrics=[AtFaultCollisions()])
    cmp = compare_runs(blind, careful)
    assert "scenario lead_vehicle_hard_brake seed 2" in cmp.log_sha256
    deltas = {(v.metric, v.key): v for v in cmp.values}
    assert deltas["at_fault_collisions", "at_fault_collisions"].a >= 1
    assert deltas["at_fault_collisions", "at_fault_collisions"].b == 0
    other = tmp_path / "other"
    run_closed_loop(
        ClosedLoopRequest(scenario="cut_in", pipeline=reference, out=other, duration_s=2.0)
    )
    evaluate_run(other, metrics=[AtFaultCollisions()])
    with pytest.raises(ConfigError, match="different logs"):
        compare_runs(blind, other)


def test_sensors_apply_to_scenarios_only(
    demo_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", str(demo_log), "--closed-loop", "--sensors"]) == 1
    assert "--sensors re-renders a synthetic scenario's rig" in capsys.readouterr().err


def test_a_planner_that_reads_the_road_map_is_not_refused_at_object_level(
    tmp_path: Path,
) -> None:
    """The road map is no sensor: an object-level synthetic run hands it over (it was refused as
    a sensor the backend does not render)."""
    run = _run(tmp_path / "map", f"{PLUGINS}:MapReader", duration_s=1.0)
    assert set(run.table("steps").to_pydict()["status"]) == {"ok"}


def test_object_level_frames_are_the_constructors() -> None:
    # the synthetic backend builds its object-level frames unchecked: every field is what
    # Frame(...) makes of the same values (types, values, repr, a pickle round trip)
    import dataclasses
    import pickle

    from redrive.algorithms import StageOutputs
    from redrive.closedloop.synthetic import SyntheticSimulator
    from redrive.closedloop.tracker import LqrTracker
    from redrive.sim.scenario import load_scenario
    from redrive.types import Frame

    scenario = dataclasses.replace(load_scenario("urban"), duration_s=3.0)
    sim = SyntheticSimulator(scenario, tracker=LqrTracker(), agents="reactive")
    while not sim.done:
        frame = sim.observe()
        built = Frame(
            stamp_ns=frame.stamp_ns,
            index=frame.index,
            vehicle_state=frame.vehicle_state,
            traffic=frame.traffic,
            ground_truth=frame.ground_truth,
        )
        assert type(frame) is Frame
        for field in dataclasses.fields(Frame):
            got, want = getattr(frame, field.name), getattr(built, field.name)
            assert type(got) is type(want)
            assert got is want or got == want, field.name
        assert repr(pickle.loads(pickle.dumps(frame))) == repr(built)
        sim.step(StageOutputs(), sim.dt_s)
