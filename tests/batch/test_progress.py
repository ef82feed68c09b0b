"""What ``redrive batch`` shows while it works: the bar on a terminal, plain lines otherwise."""

from __future__ import annotations

import io

import pytest
from rich.console import Console

from redrive.batch import BatchProgress, CellRecord, CellStatus
from redrive.cli._batch_progress import BatchBar, BatchLines, batch_progress


def _record(cell_id: str, status: CellStatus, **kw: object) -> CellRecord:
    return CellRecord(
        cell_id=cell_id,
        log_id=cell_id.rsplit("/", 1)[-1],
        log=f"/logs/{cell_id}.mcap",
        pipeline="ref",
        loop="open",
        run_dir=f"runs/{cell_id}",
        status=status,
        **kw,  # type: ignore[arg-type]
    )


def _events(show: object) -> BatchProgress:
    """Four cells: one skipped, two complete (100 and 300 frames), one failed."""
    counts = BatchProgress(total=4, skipped=1, started_at=0.0)
    assert callable(show)
    show("skipped", _record("ref/open/a", CellStatus.SKIPPED), counts)
    for name, frames in (("b", 100), ("c", 300)):
        counts.running += 1
        show("started", _record(f"ref/open/{name}", CellStatus.RUNNING), counts)
        counts.running -= 1
        counts.done += 1
        counts.frames += frames
        counts.walls.append(2.0)
        show("complete", _record(f"ref/open/{name}", CellStatus.COMPLETE, wall_s=2.0), counts)
    counts.running += 1
    show("started", _record("ref/open/d", CellStatus.RUNNING), counts)
    counts.running -= 1
    counts.failed += 1
    show(
        "failed",
        _record("ref/open/d", CellStatus.FAILED, error="LogError: truncated\nmore"),
        counts,
    )
    return counts


def test_the_bar_counts_cells_frames_and_failures() -> None:
    out = io.StringIO()
    console = Console(file=out, force_terminal=True, width=160, color_system=None)
    bar = BatchBar(workers=2, total=4, console=console)
    with bar:
        counts = _events(bar)
        fields = bar.progress.tasks[0].fields
        assert bar.progress.tasks[0].completed == 4 == counts.finished
        assert fields["states"] == "2 done, 1 failed, 0 running, 1 skipped"
        assert fields["rate"].endswith(" frames/s")
        assert fields["rate"] != "? frames/s"
        bar.progress.refresh()
    text = out.getvalue()
    assert "failed ref/open/d: LogError: truncated" in text  # the reason stays above the bar
    assert "4/4" in text
    assert "2 done, 1 failed" in text


def test_lines_when_not_a_terminal() -> None:
    out = io.StringIO()
    show = batch_progress(2, 4, quiet=False, stream=out)
    assert isinstance(show, BatchLines)
    _events(show)
    lines = out.getvalue().splitlines()
    assert len(lines) == 7  # skipped, started and complete twice, started, failed
    assert lines[0].startswith("batch: skipped     ref/open/a | 1/4 done")
    assert "? frames/s" in lines[0]  # nothing completed yet in this run
    assert lines[2].startswith("batch: complete    ref/open/b (2.0 s) | 2/4 done")
    assert (
        "failed      ref/open/d: LogError: truncated | 4/4 done (1 failed, 1 skipped)" in lines[-1]
    )
    assert batch_progress(2, 4, quiet=True, stream=out) is None


def test_frames_per_second_is_over_the_batch_wall_time() -> None:
    counts = BatchProgress(total=2, started_at=10.0)
    assert counts.frames_per_s(now=20.0) is None
    counts.frames = 250
    assert counts.frames_per_s(now=20.0) == 25.0


def test_batch_json_is_rewritten_at_most_once_a_second_while_cells_run(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from redrive.batch import run as batch_run

    clock = [100.0]
    monkeypatch.setattr(batch_run.time, "perf_counter", lambda: clock[0])
    throttle = batch_run._Throttle()
    assert throttle.due()  # the first write
    throttle.wrote(0.01)
    clock[0] += 0.5
    assert not throttle.due()
    clock[0] += 0.5
    assert throttle.due()
    throttle.wrote(0.3)  # a manifest of thousands of cells: wait 10× its write time
    clock[0] += 2.9
    assert not throttle.due()
    clock[0] += 0.1
    assert throttle.due()
