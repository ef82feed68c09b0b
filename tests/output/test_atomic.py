"""The one atomic write: the new file complete, no temp left, the old file kept on failure."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from redrive.output import atomic
from redrive.output.atomic import atomic_path, sync_tree, write_atomic


def test_write_replaces_the_file_and_leaves_no_temp(tmp_path: Path) -> None:
    target = tmp_path / "out.json"
    target.write_text("old", encoding="utf-8")
    assert write_atomic(target, "new ✓") == target
    assert target.read_text(encoding="utf-8") == "new ✓"
    write_atomic(target, b"\x00" * 100_000)
    assert target.read_bytes() == b"\x00" * 100_000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_an_exception_keeps_the_old_file(tmp_path: Path) -> None:
    target = tmp_path / "table.csv"
    target.write_text("old", encoding="utf-8")

    def write_half() -> None:
        with atomic_path(target) as tmp:
            tmp.write_text("half", encoding="utf-8")
            raise RuntimeError("writer died")

    with pytest.raises(RuntimeError):
        write_half()
    assert target.read_text(encoding="utf-8") == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]


def test_file_and_folder_are_fsynced_before_and_after_the_rename(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    events: list[str] = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd: int) -> None:
        events.append("fsync-dir" if os.path.isdir(f"/proc/self/fd/{fd}") else "fsync-file")
        real_fsync(fd)

    def replace(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> None:
        events.append("rename")
        real_replace(a, b)

    monkeypatch.setattr(atomic.os, "fsync", fsync)
    monkeypatch.setattr(atomic.os, "replace", replace)
    write_atomic(tmp_path / "a.txt", "x")
    assert events == ["fsync-file", "rename", "fsync-dir"]


def test_a_named_temp_and_a_synced_tree(tmp_path: Path) -> None:
    target = tmp_path / "log.mcap"
    with atomic_path(target, temp=tmp_path / f".log.{os.getpid()}.mcap") as tmp:
        assert tmp.suffix == ".mcap"
        tmp.write_bytes(b"mcap")
    assert target.read_bytes() == b"mcap"
    (tmp_path / "d" / "e").mkdir(parents=True)
    (tmp_path / "d" / "e" / "f.parquet").write_bytes(b"x")
    sync_tree(tmp_path / "d")  # every file and folder opened and fsynced without error
