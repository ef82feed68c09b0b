"""A flush's files: written and fsynced at once, then renamed in order (the one ``last`` makes
after the others); nothing renamed on failure."""

from __future__ import annotations

import os
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from redrive.results import _files
from redrive.results._files import write_files


def test_every_file_is_fsynced_before_any_is_renamed_in_order(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[tuple[str, str]] = []
    replace = os.replace

    def fsynced(fd: int) -> None:  # recorded, not done: a loaded disk's fsync takes seconds
        calls.append(("fsync", Path(os.readlink(f"/proc/self/fd/{fd}")).name))

    def renamed(src: Path, dst: Path) -> None:
        calls.append(("rename", Path(dst).name))
        replace(src, dst)

    monkeypatch.setattr(_files.os, "fsync", fsynced)
    monkeypatch.setattr(_files.os, "replace", renamed)
    table = pa.table({"x": pa.array([1, 2, 3], type=pa.int64())})
    names = ["b.parquet", "a.parquet", "manifest.json"]
    write_files(
        [(tmp_path / names[0], table), (tmp_path / names[1], table)],
        last=lambda: (tmp_path / names[2], b"{}"),  # made while the others are written
    )
    assert sorted(calls[:3]) == sorted(("fsync", n + ".tmp") for n in names)
    assert calls[3:6] == [("rename", n) for n in names]
    assert calls[6:] == [("fsync", tmp_path.name)]  # then the folder, so the names are durable
    assert pq.read_table(tmp_path / "a.parquet").equals(table)
    assert (tmp_path / "manifest.json").read_bytes() == b"{}"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)


def test_a_failed_write_renames_nothing(tmp_path: Path) -> None:
    table = pa.table({"x": pa.array([1], type=pa.int64())})
    with pytest.raises(TypeError):
        write_files([(tmp_path / "a.parquet", table), (tmp_path / "b", "not bytes")])  # type: ignore[list-item]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.parquet.tmp", "b.tmp"]
