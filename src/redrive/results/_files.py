"""Files of a run directory written atomically and durably: a temp file, fsync, rename.

:func:`write_files` writes several at once (a flush: one Parquet part per table, then the
manifest): every temp file is written first, then all are fsynced *concurrently*, then renamed
into place in the order given.  Each file is still fsynced before it is renamed, exactly as when
they were written one after another; fsyncs issued together let the filesystem commit them in one
journal transaction (ext4 groups them) instead of one commit per file — four parts and a manifest
cost about one commit's wait instead of five (BENCHMARKS.md, branch h-engine5).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, BinaryIO

import pyarrow as pa
import pyarrow.parquet as pq

__all__ = ["PARQUET_OPTIONS", "json_bytes", "write_files", "write_json_atomic"]

#: Parquet writer options: fixed, so equal tables give equal bytes.
PARQUET_OPTIONS: dict[str, Any] = {"compression": "zstd", "use_dictionary": True}

_POOL: tuple[int, ThreadPoolExecutor] | None = None


def _pool() -> ThreadPoolExecutor:
    """The threads the concurrent fsyncs run on (made again in a forked child, whose copy of
    the parent's pool has no threads)."""
    global _POOL  # noqa: PLW0603 (one pool per process, made on first use)
    if _POOL is None or _POOL[0] != os.getpid():
        _POOL = (os.getpid(), ThreadPoolExecutor(8, thread_name_prefix="redrive-fsync"))
    return _POOL[1]


def json_bytes(data: Mapping[str, Any]) -> bytes:
    """``data`` as the indented JSON text the run directory's JSON files hold."""
    return (json.dumps(data, indent=2, sort_keys=False, allow_nan=False) + "\n").encode("utf-8")


def write_json_atomic(path: Path, data: Mapping[str, Any]) -> None:
    """Write ``data`` as indented JSON to ``path`` through a temp file and ``os.replace``."""
    write_files([(path, json_bytes(data))])


def _write(fh: BinaryIO, payload: pa.Table | bytes) -> None:
    if isinstance(payload, pa.Table):
        pq.write_table(payload, fh, **PARQUET_OPTIONS)
    else:
        fh.write(payload)
    fh.flush()


def write_files(files: Sequence[tuple[Path, pa.Table | bytes]]) -> None:
    """Write each ``(path, payload)`` — a table as a Parquet file, bytes as they are — to
    ``path.tmp``, fsync them all (concurrently), then rename each into place, in order.

    A failure before the renames leaves only temp files (which readers ignore and a resume
    deletes); the renames happen in the order given, so the file that commits a flush goes last.
    """
    tmps = [path.with_name(path.name + ".tmp") for path, _ in files]
    handles: list[BinaryIO] = []
    try:
        for tmp, (_, payload) in zip(tmps, files, strict=True):
            out = open(tmp, "wb")  # noqa: SIM115 (closed below, after the fsyncs)
            handles.append(out)
            _write(out, payload)
        fds = [fh.fileno() for fh in handles]
        if len(fds) == 1:
            os.fsync(fds[0])
        else:
            others = [_pool().submit(os.fsync, fd) for fd in fds[1:]]
            try:
                os.fsync(fds[0])
            finally:
                for future in others:
                    future.result()  # every fsync done (or its error raised) before closing
    finally:
        for fh in handles:
            fh.close()
    for tmp, (path, _) in zip(tmps, files, strict=True):
        os.replace(tmp, path)
