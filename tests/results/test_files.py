"""A flush's files: written and fsynced at once, then renamed in order (the one ``last`` makes
after the others); nothing renamed on failure.  The JSON files' text is ``json.dumps``'s."""

from __future__ import annotations

import enum
import json
import math
import os
import re
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from redrive.results import _files
from redrive.results._files import json_bytes, write_files


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


class _Count(enum.IntEnum):
    THREE = 3


@pytest.mark.parametrize(
    "data",
    [
        {},
        {"a": [], "b": {}, "c": [[], {}, [1, [2, {"x": None}]]], "t": (1, 2.5, "x")},
        {"ü": 'é\n\t"\\', 7: 2.5, 2.0: True, None: False, True: 1e300, False: -0.0},
        {"e": _Count.THREE, "big": 10**30, "small": 1e-7, "one": 1.0, "neg": -12, "f": False},
    ],
)
def test_json_bytes_is_json_dumps_indented(data: dict[Any, Any]) -> None:
    assert json_bytes(data) == (json.dumps(data, indent=2, allow_nan=False) + "\n").encode()


@pytest.mark.parametrize("bad", [{"x": math.nan}, {"x": {1, 2}}, {(1, 2): 3}, {"x": -math.inf}])
def test_json_bytes_refuses_what_json_dumps_refuses(bad: dict[Any, Any]) -> None:
    with pytest.raises((TypeError, ValueError)) as want:
        json.dumps(bad, indent=2, allow_nan=False)
    with pytest.raises(want.type, match=re.escape(str(want.value))):
        json_bytes(bad)
    cycle: dict[str, Any] = {}
    cycle["self"] = cycle
    with pytest.raises(ValueError, match="Circular reference"):
        json_bytes(cycle)
