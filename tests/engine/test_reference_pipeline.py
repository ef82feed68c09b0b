"""The reference pipeline (detector → tracker → IDM planner → pure pursuit) on a synthetic log:
it runs end to end, is deterministic, and sequential, pipelined and process runs agree."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.config import reference_pipeline
from redrive.engine import RunRequest, run_log
from redrive.results import open_run
from redrive.sim.scenario import load_scenario
from redrive.sim.synth import synthesize
from tests.engine._runs import OUTPUT_TABLES, outputs


@pytest.fixture(scope="module")
def cut_in(cut_in_log: Path) -> Path:
    """2 s of ``cut_in`` (the session's, see tests/conftest.py)."""
    return cut_in_log


def test_reference_pipeline_runs_and_is_deterministic(cut_in: Path, tmp_path: Path) -> None:
    reports = []
    for name, options in (
        ("a", {}),
        ("b", {}),
        ("pipelined", {"mode": "pipelined"}),
        ("processes", {"mode": "pipelined", "executor": "processes"}),
    ):
        pipeline = reference_pipeline().with_options(**options)
        reports.append(run_log(RunRequest(log=cut_in, pipeline=pipeline, out=tmp_path / name)))
    first = reports[0]
    assert first.status == "complete"
    assert first.frames == 20
    by_name = {a.name: a for a in first.algorithms}
    assert [a.ok for a in first.algorithms] == [20, 20, 20, 20]
    assert by_name["clusters"].outputs > 20  # it sees the cars around the ego
    assert by_name["tracker"].outputs > 0
    reference = outputs(tmp_path / "a")
    for name in ("b", "pipelined", "processes"):
        other = outputs(tmp_path / name)
        for table in OUTPUT_TABLES:
            assert reference[table].equals(other[table]), f"{name}: {table} differs"
    commands = open_run(tmp_path / "a").table("commands")
    assert commands.num_rows == 20


def test_pipelined_equals_sequential_on_the_demo_scenario(tmp_path: Path) -> None:
    """`make demo`'s scenario (traffic lights, a strided LiDAR cloud, a camera the pipeline does
    not read): the pipelined run's tables are the sequential run's, timing columns aside."""
    log = tmp_path / "urban.mcap"
    synthesize(load_scenario("urban"), log, duration_s=2.0)
    for mode in ("sequential", "pipelined"):
        pipeline = reference_pipeline().with_options(mode=mode)
        report = run_log(RunRequest(log=log, pipeline=pipeline, out=tmp_path / mode))
        assert report.status == "complete"
        assert report.frames == 20
    sequential, pipelined = outputs(tmp_path / "sequential"), outputs(tmp_path / "pipelined")
    assert sequential["detections"].num_rows > 0
    for table in OUTPUT_TABLES:
        assert sequential[table].equals(pipelined[table]), f"{table} differs"
