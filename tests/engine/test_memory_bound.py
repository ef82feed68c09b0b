"""The per-algorithm memory bound (``--max-rss``, ``max_rss_mb``; issue 37): a worker past it is
killed, the step recorded as a ``MemoryLimit`` error on its frame with the reason, and a fresh
worker takes the next frame; the run goes on as after any failed step."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from redrive.cli.main import main
from redrive.config import AlgorithmSpec, PipelineConfig, StageSpec, load_pipeline
from redrive.engine import RunRequest, memory, run_log
from redrive.errors import ConfigError
from redrive.results import RunStatus, open_run

HOG = "tests.engine.plugins:Hog"


def _pipeline(bound_mb: float, **hog: object) -> PipelineConfig:
    spec = AlgorithmSpec(name="hog", plugin=HOG, config=hog)
    return PipelineConfig(stages=(StageSpec(name="det", algorithms=(spec,), max_rss_mb=bound_mb),))


def _steps(out: Path) -> list[dict[str, object]]:
    return [s for s in open_run(out).table("steps").to_pylist() if s["algorithm"] == "hog"]


def test_a_step_growing_past_the_bound_is_killed_and_recorded(
    demo_bag: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run"
    pipe = _pipeline(400, frame=2, mib=2048, keep=True)
    report = run_log(RunRequest(log=demo_bag, pipeline=pipe, out=out, stop_frame=5))
    assert report.status == "complete"
    hog = report.algorithms[0]
    assert (hog.ok, hog.error) == (4, 1)  # frames 3 and 4 ran in a fresh worker
    steps = _steps(out)
    failed = [s for s in steps if s["status"] != "ok"]
    assert [(s["frame_index"], s["status"], s["error_type"]) for s in failed] == [
        (2, "error", "MemoryLimit")
    ]
    message = str(failed[0]["error_message"])
    assert "over its bound of 400 MiB" in message
    assert "while its step ran" in message  # the watch killed it, not the peak afterwards
    manifest = open_run(out).manifest
    assert manifest.status is RunStatus.COMPLETE
    assert dict(manifest.pipeline.max_rss_mb) == {"det": 400.0}


def test_a_peak_between_two_reads_of_the_rss_is_caught_after_the_step(
    demo_bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A step that allocates 600 MiB and frees it again before the watch looks (the watch made
    blind here) is still over the bound: the worker's peak after the step says so."""
    monkeypatch.setattr(memory, "WATCH_INTERVAL_S", 3600.0)
    out = tmp_path / "run"
    pipe = _pipeline(400, frame=1, mib=600, keep=False)
    report = run_log(RunRequest(log=demo_bag, pipeline=pipe, out=out, stop_frame=3))
    assert (report.algorithms[0].ok, report.algorithms[0].error) == (2, 1)
    (failed,) = [s for s in _steps(out) if s["status"] != "ok"]
    assert failed["frame_index"] == 1
    assert failed["error_type"] == "MemoryLimit"
    assert "its peak during the step" in str(failed["error_message"])


def test_a_bound_below_what_the_worker_needs_to_start_is_said(
    demo_bag: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run"
    report = run_log(RunRequest(log=demo_bag, pipeline=_pipeline(8), out=out, stop_frame=1))
    assert report.algorithms[0].error == 1
    (step,) = _steps(out)
    assert step["error_type"] == "MemoryLimit"
    assert "to start" in str(step["error_message"])
    assert "over its bound of 8 MiB" in str(step["error_message"])


def test_the_bound_from_the_pipeline_file(tmp_path: Path) -> None:
    toml = tmp_path / "pipeline.toml"
    toml.write_text(
        'max_rss_mb = 1024\n[[stage]]\nname = "a"\n[[stage.algorithm]]\nplugin = "m:A"\n'
        '[[stage]]\nname = "b"\nmax_rss_mb = 256\n[[stage.algorithm]]\nplugin = "m:B"\n'
    )
    pipe = load_pipeline(toml)
    assert pipe.max_rss_by_stage == {"a": 1024.0, "b": 256.0}
    assert pipe.isolated
    # --max-rss replaces the pipeline's bound; a stage's own one stays
    assert pipe.with_options(max_rss_mb=300).max_rss_by_stage == {"a": 300.0, "b": 256.0}
    unbounded = PipelineConfig(
        stages=(StageSpec(name="a", algorithms=(AlgorithmSpec(name="x", plugin="m:A"),)),)
    )
    assert not unbounded.isolated
    assert unbounded.max_rss_by_stage == {}
    toml.write_text('[[stage]]\nmax_rss_mb = 0\n[[stage.algorithm]]\nplugin = "m:A"\n')
    with pytest.raises(ConfigError, match="max_rss_mb"):
        load_pipeline(toml)
    with pytest.raises(ConfigError, match="max_rss_mb must be > 0"):
        unbounded.with_options(max_rss_mb=-1)


def test_redrive_run_max_rss(
    demo_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    argv = ["run", str(demo_bag), "--perception", HOG, "--max-rss", "400"]
    status = main([*argv, "--frames", "0:4", "--out", str(out), "--no-progress"])
    assert status == 0  # some frames failed: the run is complete, the failures stored
    printed = " ".join(capsys.readouterr().out.split())
    assert "1 of 4 frames had a failed step" in printed
    assert "MemoryLimit" in printed
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["pipeline"]["max_rss_mb"] == {"perception": 400.0}
