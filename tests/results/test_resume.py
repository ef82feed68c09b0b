"""A killed writer leaves a readable run that a resume continues without losing or doubling frames."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

from redrive.results import RunStatus, RunWriter, open_run
from tests.results._records import SETUP, frame

_ROOT = Path(__file__).resolve().parents[2]

_CRASH = """
import os, signal, sys
from redrive.results import RunWriter
from tests.results._records import SETUP, frame
writer = RunWriter(sys.argv[1], setup=SETUP, flush_every=50)
for i in range(170):  # 150 frames flushed in 3 parts, 20 still buffered
    writer.write_frame(frame(i))
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_resume_after_kill(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    run_dir = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-c", _CRASH, str(run_dir)], cwd=_ROOT, check=False, timeout=120
    )
    assert proc.returncode == -signal.SIGKILL
    # what a crash in the middle of the next flush would leave: parts without their frames part
    for name in ("steps", "detections"):
        src = run_dir / name / "part-00000.parquet"
        (run_dir / name / "part-00003.parquet").write_bytes(src.read_bytes())
    (run_dir / "ego" / "part-00003.parquet.tmp").write_bytes(b"PAR1 half written")

    crashed = open_run(run_dir)
    assert crashed.manifest.status is RunStatus.RUNNING
    assert crashed.manifest.frames_done == 150
    assert crashed.table("frames").num_rows == 150
    assert crashed.table("steps").num_rows == 150 * 4  # the orphan part is not read

    with RunWriter(run_dir, setup=SETUP, resume=True, flush_every=50) as writer:
        assert writer.done_frames == frozenset(range(150))
        # a resumed run says that its algorithms (trackers, planners with memory) start fresh
        (said,) = [r.getMessage() for r in caplog.records if "fresh state" in r.getMessage()]
        assert said.startswith("resuming after 150 frames done: the algorithms start from a")
        assert "can differ from those of an uninterrupted run" in said
        for i in range(200):
            if i not in writer.done_frames:
                writer.write_frame(frame(i))

    run = open_run(run_dir)
    assert run.manifest.status is RunStatus.COMPLETE
    assert run.manifest.frames_done == 200
    (resume,) = run.manifest.resumes
    assert resume.previous_status is RunStatus.RUNNING
    assert resume.frames_done == 150
    assert resume.removed_incomplete_files == 3
    assert not list(run_dir.rglob("*.tmp"))
    assert [p.name for p in run.part_paths("steps")][-1] == "part-00003.parquet"

    frames = run.table("frames").column("frame_index").to_pylist()
    assert frames == list(range(200))
    steps = run.table("steps")
    assert steps.num_rows == 200 * 4
    pairs = list(
        zip(
            steps.column("frame_index").to_pylist(),
            steps.column("algorithm").to_pylist(),
            strict=True,
        )
    )
    assert len(set(pairs)) == len(pairs)
    dets = run.detections("det")
    assert sorted(dets) == list(range(200))
    assert [len(dets[i]) for i in range(200)] == [i % 3 for i in range(200)]
    # the summary written at close (the parts from before the resume read back, this writer's
    # flushes kept in memory) is the one all the run's parts give when read back
    summary = run.manifest.summary
    assert summary is not None
    assert (summary.frames, summary.late_frames) == (200, 1)
    assert [dict(a) for a in summary.algorithms] == run.summary().to_pylist()


def test_resume_of_missing_directory_starts_a_run(tmp_path: Path) -> None:
    with RunWriter(tmp_path / "new", setup=SETUP, resume=True) as writer:
        assert writer.done_frames == frozenset()
        writer.write_frame(frame(0))
    run = open_run(tmp_path / "new")
    assert run.manifest.resumes == ()
    assert run.table("frames").num_rows == 1
