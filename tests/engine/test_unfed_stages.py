"""Stages a log cannot feed (issue 35 item 2): skipped with the reason unless refused."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.config import AlgorithmSpec, PipelineConfig, StageSpec
from redrive.engine import LogInputs, build_graph
from redrive.errors import MissingInputError
from redrive.results import open_run, read_manifest
from redrive.types import SensorType

_REFERENCE = (
    ("detection", "clusters", "cluster-detector"),
    ("planning", "planner", "idm-planner"),
    ("control", "controller", "pure-pursuit-pid"),
)
_LIDAR_ONLY = LogInputs(sensors={"velodyne": SensorType.LIDAR}, has_ground_truth=True)


def _pipeline(*stages: tuple[str, str, str]) -> PipelineConfig:
    return PipelineConfig(
        stages=tuple(
            StageSpec(name=stage, algorithms=(AlgorithmSpec(name=name, plugin=plugin),))
            for stage, name, plugin in stages
        )
    )


def test_the_stages_a_log_cannot_feed_are_refused_by_default() -> None:
    with pytest.raises(MissingInputError, match=r"stage 'planning'.*needs vehicle state"):
        build_graph(_pipeline(*_REFERENCE), _LIDAR_ONLY)


def test_skipping_keeps_what_the_log_feeds_and_says_why_for_the_rest() -> None:
    graph = build_graph(_pipeline(*_REFERENCE), _LIDAR_ONLY, skip_unfed=True)
    assert [name for name, _ in graph.stages] == ["detection"]
    assert list(graph.skipped) == ["planner", "controller"]
    assert "needs vehicle state, which this log does not have" in graph.skipped["planner"]
    assert "sensor map file" not in graph.skipped["planner"]  # advice for a refusal only
    assert "planning stage was skipped" in graph.skipped["controller"]
    # a log with the ego state feeds everything: nothing is skipped
    full = LogInputs(
        sensors={"velodyne": SensorType.LIDAR}, has_vehicle_state=True, has_ground_truth=True
    )
    graph = build_graph(_pipeline(*_REFERENCE), full, skip_unfed=True)
    assert [name for name, _ in graph.stages] == ["detection", "planning", "control"]
    assert graph.skipped == {}


def test_a_pipeline_the_log_feeds_nothing_of_is_refused_with_every_reason() -> None:
    with pytest.raises(MissingInputError, match=r"no stage of the pipeline can run.*planner"):
        build_graph(_pipeline(*_REFERENCE[1:]), _LIDAR_ONLY, skip_unfed=True)


def test_the_default_run_of_the_real_kitti_folder_runs_perception_and_stores_the_skips(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    kitti = shared_data / "kitti_object" / "training"
    out = tmp_path / "run"
    assert main(["run", str(kitti), "--out", str(out), "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "skipped planner" in said
    assert "needs vehicle state" in said
    manifest = read_manifest(out)
    assert manifest.pipeline.stages == ("detection", "tracking")
    assert set(manifest.pipeline.skipped) == {"planner", "controller"}
    assert len(open_run(out).detections("clusters")) == 3  # every frame's detections
    # --strict refuses it, as before
    assert main(["run", str(kitti), "--out", str(tmp_path / "strict"), "--strict"]) != 0
    assert "needs vehicle state" in capsys.readouterr().err
