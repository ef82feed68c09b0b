"""A full disk while writing an MCAP (issue 37): what reached the file is kept, reads back intact,
and the error names the file; ``synth``, ``convert`` and ``live --record`` exit with status 6.

The disk is a small tmpfs mounted for the test (root only; skipped otherwise); the case of no room
left even for the index is a byte budget on the writer's ``write_all``."""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import DiskFullError
from redrive.io import open_log
from redrive.io.mcap import stream as mcap_stream
from redrive.io.mcap.writer import McapWriter
from redrive.types import Imu, PointCloud

EXIT_DISK_FULL = 6


def _can_mount() -> bool:
    return os.geteuid() == 0 and shutil.which("mount") is not None


@pytest.fixture
def full_disk(tmp_path: Path) -> Iterator[Path]:
    """A 3 MiB tmpfs: a folder whose disk fills after about 3 MiB."""
    if not _can_mount():
        pytest.skip("mounting a small tmpfs needs root")
    folder = tmp_path / f"full-{uuid.uuid4().hex[:6]}"
    folder.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(folder)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


def _cloud(i: int) -> PointCloud:
    rng = np.random.default_rng(i)
    return PointCloud(xyz=rng.normal(size=(20_000, 3)).astype(np.float32), channels={})


def _fill(path: Path, *, compression: str = "none") -> tuple[DiskFullError, int]:
    """Write clouds and IMU samples to ``path`` until the disk is full; the messages handed to
    the writer (each cloud gets a chunk of its own, so the IMU sample before it may be kept)."""
    sent = 0
    imu = Imu(
        linear_acceleration=np.zeros(3),
        angular_velocity=np.zeros(3),
        orientation=np.array([0.0, 0.0, 0.0, 1.0]),
    )
    writer = McapWriter(path, compression=compression, chunk_size_bytes=256 << 10)  # type: ignore[arg-type]
    with pytest.raises(DiskFullError) as caught, writer as out:  # noqa: PT012 - the loop fills it
        for i in range(10_000):
            sent += 1  # messages handed to the writer, the one the disk refused included
            out.write("/imu", 1_000 + i, imu, frame_id="imu")
            sent += 1
            out.write("/lidar", 1_000 + i, _cloud(i), frame_id="lidar")
    return caught.value, sent


def _count(path: Path) -> int:
    with open_log(path) as log:
        return sum(1 for _ in log.messages())


@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_a_full_disk_keeps_what_was_written(full_disk: Path, compression: str) -> None:
    target = full_disk / "out.mcap"
    err, sent = _fill(target, compression=compression)
    assert err.path == str(target)
    assert err.kept == str(target)
    assert str(target) in str(err)
    assert "no space left" in str(err)
    assert "with its index" in str(err)
    assert not list(full_disk.glob(".*.part"))
    kept = _count(target)
    assert 0 < kept < sent
    assert f"after {kept} messages" in str(err)
    with open_log(target) as log:  # the summary: the topics and counts of what the file holds
        assert sum(t.count for t in log.topics.values()) == kept


def test_a_full_disk_never_replaces_an_existing_file(full_disk: Path) -> None:
    target = full_disk / "out.mcap"
    target.write_bytes(b"the user's old file")
    err, _ = _fill(target)
    assert target.read_bytes() == b"the user's old file"
    assert err.kept == str(full_disk / "out.incomplete.mcap")
    assert _count(full_disk / "out.incomplete.mcap") > 0


def test_no_room_for_the_index_leaves_a_file_cut_after_its_last_chunk(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    budget = [2 << 20]
    real = mcap_stream.write_all

    def write_all(fd: int, pieces: list[bytes | memoryview]) -> int:
        size = sum(memoryview(p).nbytes for p in pieces)
        if size > budget[0]:  # the disk fills part-way through these bytes
            os.write(fd, memoryview(pieces[0]).cast("B")[: budget[0] // 2])
            budget[0] = 0
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        budget[0] -= size
        return real(fd, pieces)

    monkeypatch.setattr(mcap_stream, "write_all", write_all)
    target = tmp_path / "out.mcap"
    err, sent = _fill(target)
    assert "without its index" in str(err)
    assert "redrive repair" in str(err)
    kept = _count(target)  # read as a log cut off after its last whole chunk
    assert 0 < kept < sent
    fixed = tmp_path / "fixed.mcap"
    monkeypatch.setattr(mcap_stream, "write_all", real)
    done = _redrive("repair", str(target), "-o", str(fixed))
    assert done.returncode in (0, 5), done.stderr
    assert _count(fixed) == kept


def _redrive(*argv: str, timeout_s: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "redrive", *argv],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
    )


def _check_cli(done: subprocess.CompletedProcess[str], target: Path) -> int:
    assert done.returncode == EXIT_DISK_FULL, done.stderr
    assert "Traceback" not in done.stderr
    assert "internal error" not in done.stderr
    assert f"{target}: no space left" in done.stderr
    kept = _count(target)
    assert kept > 0
    assert f"after {kept} messages" in done.stderr
    return kept


def test_synth_on_a_full_disk(full_disk: Path) -> None:
    target = full_disk / "urban.mcap"
    _check_cli(_redrive("synth", "urban", "--duration", "5", "-o", str(target)), target)


def test_convert_on_a_full_disk(demo_log: Path, full_disk: Path) -> None:
    target = full_disk / "copy.mcap"
    _check_cli(_redrive("convert", str(demo_log), str(target)), target)


def test_live_record_on_a_full_disk_keeps_the_recording(demo_log: Path, full_disk: Path) -> None:
    """`live --replay LOG --record FULL/live.mcap`: the session ends by itself with the reason,
    and the recording up to the full disk stays, readable; the summary counts what it holds."""
    target = full_disk / "live.mcap"
    done = _redrive("live", "--replay", str(demo_log), "--rate", "4", "--record", str(target))
    kept = _check_cli(done, target)
    assert "the recording could not go on" in " ".join(done.stdout.split())
    assert f"{kept}" in done.stdout  # the total of the summary table is what the file holds


def test_live_pipeline_and_record_on_a_full_disk(
    demo_log: Path, full_disk: Path, tmp_path: Path
) -> None:
    from redrive.results import RunStatus, read_manifest

    target = full_disk / "live.mcap"
    done = _redrive(
        "live", "--replay", str(demo_log), "--rate", "4", "--record", str(target),
        "--planning", "idm-planner", "--out", str(tmp_path / "run"), "--duration", "60",
    )  # fmt: skip
    _check_cli(done, target)
    assert read_manifest(tmp_path / "run").status in (RunStatus.COMPLETE, RunStatus.INTERRUPTED)


def test_run_on_a_full_disk_keeps_the_frames_stored_and_resumes(
    demo_log: Path, full_disk: Path
) -> None:
    """`redrive run --out FULL/run`: the frames of the flushes before the disk filled read back,
    the manifest agrees with them, and after room is made `--resume` completes the run."""
    from redrive.results import RunStatus, open_run, read_manifest

    # room for map.json (80 kB since it is written compact) and the manifest, not for the tables
    subprocess.run(["mount", "-o", "remount,size=200k", str(full_disk)], check=True)
    out = full_disk / "run"
    argv = ("run", str(demo_log), "--out", str(out))
    done = _redrive(*argv)
    assert done.returncode == EXIT_DISK_FULL, done.stderr
    assert "Traceback" not in done.stderr
    assert f"{out}: no space left writing {out}/" in done.stderr
    manifest = read_manifest(out)
    assert manifest.frames_done == open_run(out).table("frames").num_rows
    assert f"holds the {manifest.frames_done} frames stored before" in done.stderr
    subprocess.run(["mount", "-o", "remount,size=64m", str(full_disk)], check=True)
    again = _redrive(*argv, "--resume")
    assert again.returncode == 0, again.stderr
    run = open_run(out)
    assert run.manifest.status is RunStatus.COMPLETE
    assert sorted(run.table("frames").column("frame_index").to_pylist()) == list(range(100))
