"""Cancelling a run from another thread (the GUI's Cancel button): ``run_log(..., cancel=event)``."""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from redrive.config import AlgorithmSpec, PipelineConfig, StageSpec
from redrive.engine import RunRequest, run_log
from redrive.results import RunStatus, open_run
from tests.engine._runs import outputs

P = "tests.engine.plugins:"


def _pipeline(mode: str = "sequential") -> PipelineConfig:
    return PipelineConfig(
        stages=(
            StageSpec(name="p", algorithms=(AlgorithmSpec(name="c", plugin=P + "Centroid"),)),
            StageSpec(name="s", algorithms=(AlgorithmSpec(name="s", plugin=P + "Straight"),)),
        ),
        mode=mode,  # type: ignore[arg-type]
    )


def _cancel_after(n: int, event: threading.Event) -> Callable[[int], None]:
    def progress(done: int) -> None:
        if done == n:
            event.set()

    return progress


def test_cancel_stops_reading_and_closes_the_run_as_interrupted(
    demo_bag: Path, tmp_path: Path
) -> None:
    cancel = threading.Event()
    request = RunRequest(log=demo_bag, pipeline=_pipeline(), out=tmp_path / "run")
    report = run_log(request, progress=_cancel_after(5, cancel), cancel=cancel)

    assert report.status == "interrupted"
    run = open_run(tmp_path / "run")
    assert run.manifest.status is RunStatus.INTERRUPTED
    assert run.table("frames").column("frame_index").to_pylist() == [0, 1, 2, 3, 4]

    resumed = run_log(
        RunRequest(log=demo_bag, pipeline=_pipeline(), out=tmp_path / "run", resume=True)
    )
    assert resumed.status == "complete"
    run_log(RunRequest(log=demo_bag, pipeline=_pipeline(), out=tmp_path / "whole"))
    assert outputs(tmp_path / "run")["steps"].equals(outputs(tmp_path / "whole")["steps"])


@pytest.mark.parametrize("mode", ["sequential", "pipelined"])
def test_cancel_set_before_the_start_processes_nothing(
    demo_bag: Path, tmp_path: Path, mode: str
) -> None:
    cancel = threading.Event()
    cancel.set()
    request = RunRequest(log=demo_bag, pipeline=_pipeline(mode), out=tmp_path / "run")
    report = run_log(request, cancel=cancel)

    assert report.status == "interrupted"
    assert open_run(tmp_path / "run").manifest.status is RunStatus.INTERRUPTED
    assert open_run(tmp_path / "run").table("frames").num_rows == 0


def test_cancel_in_pipelined_mode_finishes_the_frames_in_flight(
    demo_bag: Path, tmp_path: Path
) -> None:
    cancel = threading.Event()
    request = RunRequest(log=demo_bag, pipeline=_pipeline("pipelined"), out=tmp_path / "run")
    report = run_log(request, progress=_cancel_after(3, cancel), cancel=cancel)

    assert report.status == "interrupted"
    done = open_run(tmp_path / "run").table("frames").column("frame_index").to_pylist()
    assert 3 <= len(done) < 50
    assert done == list(range(len(done)))  # in order, no gap


def test_an_unset_cancel_event_changes_nothing(demo_bag: Path, tmp_path: Path) -> None:
    request = RunRequest(log=demo_bag, pipeline=_pipeline(), out=tmp_path / "run")
    assert run_log(request, cancel=threading.Event()).status == "complete"
    assert open_run(tmp_path / "run").table("frames").num_rows == 50


def test_ctrl_c_while_a_finished_run_is_closed_leaves_it_complete(
    demo_bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A batch driver stops its cells with SIGINT; one that arrives after the last frame, while
    the run directory is being closed, used to leave the manifest ``running`` (CI, stop 39)."""
    from redrive.results import RunWriter

    original = RunWriter.write_resources

    def write_resources_then_ctrl_c(self: RunWriter, *args: object, **kwargs: object) -> None:
        os.kill(os.getpid(), signal.SIGINT)
        original(self, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(RunWriter, "write_resources", write_resources_then_ctrl_c)
    report = run_log(RunRequest(log=demo_bag, pipeline=_pipeline(), out=tmp_path / "run"))

    assert report.status == "complete"
    run = open_run(tmp_path / "run")
    assert run.manifest.status is RunStatus.COMPLETE
    assert run.manifest.frames_done == len(run.table("frames"))
    # the handler the run found is back
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
