"""``redrive batch`` with the local executor: identical cells with 2 workers and 1, a SIGKILLed
worker and a corrupt log fail only their cells, a re-run skips complete cells, --force redoes."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from redrive.batch import CellStatus, read_batch_manifest
from redrive.cli.batch import EXIT_CELLS_FAILED
from redrive.cli.main import main
from redrive.results import RunStatus, read_manifest

from .outputs import batch, batch_outputs

PLUGINS = Path(__file__).with_name("plugins.py")


def test_every_cell_is_an_ordinary_complete_run(two_workers: Path, logs: list[Path]) -> None:
    manifest = read_batch_manifest(two_workers)
    assert manifest.status == "complete"
    assert manifest.executor == "local"
    assert len(manifest.cells) == 8
    assert {c.status for c in manifest.cells} == {CellStatus.COMPLETE}
    assert [c.cell_id for c in manifest.cells[:4]] == [f"a/open/drive{i}" for i in range(4)]
    for cell in manifest.cells:
        run = read_manifest(two_workers / cell.run_dir)
        assert run.status is RunStatus.COMPLETE
        assert run.log.path == str(logs[int(cell.log_id[-1])].resolve())
        assert cell.key is not None
        assert cell.key.log == run.log.sha256
        assert cell.frames == run.frames_done > 0
    # a cell is a run directory every command reads
    cell = two_workers / manifest.cells[0].run_dir
    assert main(["evaluate", str(cell)]) == 0
    assert main(["export", str(cell), "--format", "csv"]) == 0


def test_one_worker_gives_the_same_outputs(
    two_workers: Path, logs: list[Path], pipelines: list[Path], tmp_path: Path
) -> None:
    args = [str(p) for p in logs]
    for p in pipelines:
        args += ["--pipeline", str(p)]
    assert batch(tmp_path / "one", *args, "--workers", "1") == 0
    one = batch_outputs(tmp_path / "one")
    assert len(one) == 8
    assert one == batch_outputs(two_workers)


def test_rerun_skips_complete_cells_and_force_redoes_them(
    two_workers: Path, logs: list[Path], pipelines: list[Path], tmp_path: Path
) -> None:
    out = tmp_path / "copy"
    shutil.copytree(two_workers, out)
    # as if interrupted: one cell's run directory never completed, another never started
    (out / "runs/a/open/drive1/manifest.json").unlink()
    shutil.rmtree(out / "runs/b/open/drive3")
    (out / "cells/b/open/drive3.json").unlink()
    args = [str(p) for p in logs]
    for p in pipelines:
        args += ["--pipeline", str(p)]
    assert batch(out, *args, "--workers", "2") == 0
    cells = {c.cell_id: c for c in read_batch_manifest(out).cells}
    redone = {i for i, c in cells.items() if c.status is CellStatus.COMPLETE}
    assert redone == {"a/open/drive1", "b/open/drive3"}
    assert all(c.status is CellStatus.SKIPPED for i, c in cells.items() if i not in redone)
    assert batch_outputs(out) == batch_outputs(two_workers)

    assert batch(out, *args, "--workers", "2", "--force") == 0
    assert {c.status for c in read_batch_manifest(out).cells} == {CellStatus.COMPLETE}


def test_a_changed_pipeline_is_not_skipped(
    two_workers: Path, logs: list[Path], pipelines: list[Path], tmp_path: Path
) -> None:
    out = tmp_path / "copy"
    shutil.copytree(two_workers, out)
    changed = tmp_path / "a.toml"  # same name: same cells, other config
    changed.write_text("seed = 5\n" + pipelines[0].read_text(encoding="utf-8"), encoding="utf-8")
    assert batch(out, str(logs[0]), "--pipeline", str(changed), "--workers", "1") == 0
    (cell,) = read_batch_manifest(out).cells
    assert cell.status is CellStatus.COMPLETE
    assert read_manifest(out / cell.run_dir).seed == 5


def test_a_corrupt_log_fails_only_its_cell_with_the_readers_error(
    logs: list[Path], pipelines: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    corrupt = tmp_path / "corrupt.bag"
    data = logs[0].read_bytes()
    corrupt.write_bytes(data[: len(data) // 2])
    out = tmp_path / "batch"
    status = batch(
        out,
        str(logs[0]),
        str(corrupt),
        str(logs[1]),
        "--pipeline",
        str(pipelines[0]),
        "--workers",
        "2",
    )
    assert status == EXIT_CELLS_FAILED
    cells = {c.log_id: c for c in read_batch_manifest(out).cells}
    assert cells["drive0"].status is cells["drive1"].status is CellStatus.COMPLETE
    bad = cells["corrupt"]
    assert bad.status is CellStatus.FAILED
    assert bad.attempts == 1  # a corrupt log is not retried: it would fail the same way
    assert bad.error is not None
    assert bad.error.startswith("LogDamagedError: ")  # the reader's error, as it was raised
    assert str(corrupt) in bad.error
    assert "the bag is cut off" in bad.error
    assert read_batch_manifest(out).status == "failed"
    assert "failed a/open/corrupt: LogDamagedError" in capsys.readouterr().out


def test_a_sigkilled_worker_fails_only_its_cell_after_its_retries(
    logs: list[Path], tmp_path: Path
) -> None:
    long_log = tmp_path / "long.bag"
    from redrive.testing.demo_log import write_demo_bag

    write_demo_bag(long_log, duration_s=3.0)  # 30 frames: reaches frame 25, the others do not
    out = tmp_path / "batch"
    status = batch(
        out,
        str(logs[0]),
        str(long_log),
        str(logs[1]),
        "--planning",
        f"{PLUGINS}:KillAtFrame",
        "--workers",
        "2",
        "--retries",
        "1",
    )
    assert status == EXIT_CELLS_FAILED
    cells = {c.log_id: c for c in read_batch_manifest(out).cells}
    killed = cells["long"]
    assert killed.status is CellStatus.FAILED
    assert killed.attempts == 2
    assert killed.error == "WorkerDied: the worker process was killed by SIGKILL"
    for name in ("drive0", "drive1"):
        assert cells[name].status is CellStatus.COMPLETE
        assert read_manifest(out / cells[name].run_dir).status is RunStatus.COMPLETE
    record = json.loads((out / "cells/flags/open/long.json").read_text(encoding="utf-8"))
    assert record["status"] == "failed"


def test_a_worker_killed_once_is_retried_and_completes(logs: list[Path], tmp_path: Path) -> None:
    marker = tmp_path / "killed-once"
    pipeline = tmp_path / "once.toml"
    pipeline.write_text(
        f'[[stage]]\nname = "planning"\n[[stage.algorithm]]\nplugin = "{PLUGINS}:KillOnce"\n'
        f'config = {{ marker = "{marker}" }}\n',
        encoding="utf-8",
    )
    out = tmp_path / "batch"
    assert batch(out, *map(str, logs[:3]), "--pipeline", str(pipeline), "--workers", "2") == 0
    assert marker.exists()
    cells = read_batch_manifest(out).cells
    assert {c.status for c in cells} == {CellStatus.COMPLETE}
    assert sorted(c.attempts for c in cells) == [1, 1, 2]


def test_retries_zero_fails_the_killed_cell_at_once(logs: list[Path], tmp_path: Path) -> None:
    marker = tmp_path / "killed-once"
    pipeline = tmp_path / "once.toml"
    pipeline.write_text(
        f'[[stage]]\nname = "planning"\n[[stage.algorithm]]\nplugin = "{PLUGINS}:KillOnce"\n'
        f'config = {{ marker = "{marker}" }}\n',
        encoding="utf-8",
    )
    out = tmp_path / "batch"
    status = batch(out, str(logs[0]), "--pipeline", str(pipeline), "--retries", "0")
    assert status == EXIT_CELLS_FAILED
    (cell,) = read_batch_manifest(out).cells
    assert cell.status is CellStatus.FAILED
    assert cell.attempts == 1
    assert "SIGKILL" in (cell.error or "")
    # the same command again: the failed cell runs again (the marker lets it live now)
    assert batch(out, str(logs[0]), "--pipeline", str(pipeline), "--retries", "0") == 0


def test_ctrl_c_then_the_same_command_runs_only_the_missing_cells(
    logs: list[Path], tmp_path: Path
) -> None:
    marker = tmp_path / "interrupted-once"
    pipeline = tmp_path / "ctrl_c.toml"
    pipeline.write_text(
        f'[[stage]]\nname = "planning"\n[[stage.algorithm]]\nplugin = "{PLUGINS}:InterruptDriver"\n'
        f'config = {{ driver_pid = {os.getpid()}, marker = "{marker}" }}\n',
        encoding="utf-8",
    )
    args = [*map(str, logs), "--pipeline", str(pipeline), "--workers", "1"]
    out = tmp_path / "batch"
    # one worker: drive0 and drive1 (20, 21 frames) complete, drive2 reaches frame 21 and
    # presses Ctrl-C on this process, drive3 never starts
    assert batch(out, *args) == 130
    manifest = read_batch_manifest(out)
    assert manifest.status == "interrupted"
    status = {c.log_id: c.status for c in manifest.cells}
    assert status == {
        "drive0": CellStatus.COMPLETE,
        "drive1": CellStatus.COMPLETE,
        "drive2": CellStatus.INTERRUPTED,
        "drive3": CellStatus.PENDING,
    }
    assert read_manifest(out / "runs/ctrl_c/open/drive2").status is RunStatus.INTERRUPTED
    assert batch(out, *args) == 0
    status = {c.log_id: c.status for c in read_batch_manifest(out).cells}
    assert status == {
        "drive0": CellStatus.SKIPPED,
        "drive1": CellStatus.SKIPPED,
        "drive2": CellStatus.COMPLETE,
        "drive3": CellStatus.COMPLETE,
    }
