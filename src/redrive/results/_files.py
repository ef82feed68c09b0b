"""Files of a run directory written atomically and durably: a temp file, fsync, rename, fsync of
the folder (the steps of :mod:`redrive.output.atomic`).

:func:`write_files` writes several at once (a flush: one Parquet part per table, then the
manifest): each temp file is written and fsynced on a thread of its own, all at the same time,
and only when every one is durable are they renamed into place, in the order given.  Each file is
still fsynced before it is renamed, exactly as when they were written one after another; fsyncs
issued together let the filesystem commit them in one journal transaction (ext4 groups them)
instead of one commit per file — four parts and a manifest cost about one commit's wait instead
of five — and Arrow encodes the parts side by side with the GIL released (BENCHMARKS.md, branch
h-engine5).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from redrive.output.atomic import fsync_dir, replace, temp_path

__all__ = ["PARQUET_OPTIONS", "json_bytes", "write_files", "write_json_atomic"]

#: Parquet writer options: fixed, so equal tables give equal bytes.
PARQUET_OPTIONS: dict[str, Any] = {"compression": "zstd", "use_dictionary": True}

_POOL: tuple[int, ThreadPoolExecutor] | None = None


def _pool() -> ThreadPoolExecutor:
    """The threads a flush's files are written and fsynced on (made again in a forked child,
    whose copy of the parent's pool has no threads)."""
    global _POOL  # noqa: PLW0603 (one pool per process, made on first use)
    if _POOL is None or _POOL[0] != os.getpid():
        _POOL = (os.getpid(), ThreadPoolExecutor(8, thread_name_prefix="redrive-write"))
    return _POOL[1]


def json_bytes(data: Mapping[str, Any]) -> bytes:
    """``data`` as the indented JSON text the run directory's JSON files hold."""
    return (json.dumps(data, indent=2, sort_keys=False, allow_nan=False) + "\n").encode("utf-8")


def write_json_atomic(path: Path, data: Mapping[str, Any]) -> None:
    """Write ``data`` as indented JSON to ``path`` atomically and durably (temp, fsync, rename,
    fsync of the folder)."""
    write_files([(path, json_bytes(data))])


def _write_synced(tmp: Path, payload: pa.Table | bytes) -> None:
    """``payload`` into ``tmp``, fsynced.  A table is encoded and written by Arrow's own file
    (the GIL released throughout: several parts encode at once on the pool's threads)."""
    if isinstance(payload, pa.Table):
        with pa.OSFile(str(tmp), mode="wb") as sink:  # a plain path, never parsed as a URI
            pq.write_table(payload, sink, **PARQUET_OPTIONS)
        fd = os.open(tmp, os.O_RDONLY)
    else:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            view = memoryview(payload)
            while view:
                view = view[os.write(fd, view) :]
        except BaseException:
            os.close(fd)
            raise
    try:
        os.fsync(fd)  # the file's data and size, whichever descriptor asks
    finally:
        os.close(fd)


def write_files(
    files: Sequence[tuple[Path, pa.Table | bytes]],
    *,
    last: Callable[[], tuple[Path, bytes]] | None = None,
) -> None:
    """Write each ``(path, payload)`` — a table as a Parquet file, bytes as they are — to
    ``path.tmp`` and fsync it, all at once on a pool's threads; meanwhile call ``last`` on this
    thread and write the file it returns (a flush's manifest, whose summary is computed while
    the parts are encoded) the same way; once every one is durable, rename each into place in
    the order given, ``last``'s file after them, and fsync their folders.

    A failure before the renames leaves only temp files (which readers ignore and a resume
    deletes); the renames happen in the order given, so the file that commits a flush goes last.
    """
    tmps = [temp_path(path) for path, _ in files]
    pending: list[Future[None]] = []
    for tmp, (_, payload) in zip(tmps, files, strict=True):
        try:
            pending.append(_pool().submit(_write_synced, tmp, payload))
        except RuntimeError:  # no thread to be had (an address-space limit): write it here
            done: Future[None] = Future()
            try:
                _write_synced(tmp, payload)
                done.set_result(None)
            except BaseException as exc:
                done.set_exception(exc)
            pending.append(done)
    final: tuple[Path, Path] | None = None
    try:
        if last is not None:
            path, payload = last()
            final = (temp_path(path), path)
            _write_synced(final[0], payload)
    finally:
        # even on an error or Ctrl-C here: once this returns nothing writes these temp files
        # any more (a retry of the same flush writes the same names)
        futures_wait(pending)
    for future in pending:
        future.result()  # every write done, or its error raised, before any rename
    for tmp, (path, _) in zip(tmps, files, strict=True):
        replace(tmp, path)
    if final is not None:
        replace(*final)
    folders = [path.parent for path, _ in files] + ([final[1].parent] if final else [])
    for folder in dict.fromkeys(folders):
        fsync_dir(folder)  # the new names durable too
