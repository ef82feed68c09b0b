"""``redrive.live.run_live(request)``: the library call behind ``redrive live`` with a pipeline."""

from __future__ import annotations

from pathlib import Path

from redrive.config import pipeline_from_plugins
from redrive.io import open_log
from redrive.live.run import LiveRequest, LiveSource, run_live
from redrive.results import RunStatus, open_run


def test_run_live_on_a_replay_source_runs_and_records(demo_log: Path, tmp_path: Path) -> None:
    seen: list[str] = []
    request = LiveRequest(
        source=LiveSource(kind="replay", target=str(demo_log), rate=2.0),
        pipeline=pipeline_from_plugins(perception=["cluster-detector"]),
        out=tmp_path / "run",
        frames=5,
        duration_s=60,
        record=tmp_path / "copy.mcap",
    )
    report = run_live(request, on_receiving=lambda session: seen.append(session.name))
    assert len(seen) == 1
    assert report.received_frames == 5
    assert report.run.status is RunStatus.COMPLETE
    run = open_run(tmp_path / "run")
    assert run.table("frames").num_rows == 5 - report.skipped_frames >= 1
    assert run.manifest.log.format == "live"
    assert report.failure is None
    assert report.files == (tmp_path / "copy.mcap",)
    assert report.recorded is not None
    with open_log(tmp_path / "copy.mcap") as copy:
        counts = {t: i.count for t, i in copy.topics.items()}
    assert counts == {t: n for t, n in report.recorded.items() if n}
    assert report.received["/lidar_top"] >= 1
