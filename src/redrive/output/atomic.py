"""The one atomic write: a temp file in the same folder, fsync it, rename it, fsync the folder.

Readers see the old file or the new one, never a part; after the call returns the new file
survives a power cut (its bytes and its name are both on disk).  A failure (an exception,
Ctrl-C) removes the temp file and leaves the old file as it was::

    with atomic_path(out / "table.parquet") as tmp:
        pq.write_table(table, tmp)          # any writer that takes a path

    write_atomic(out / "report.html", page)  # str or bytes

A temp file is named ``NAME.tmp`` beside its target (``temp=`` names another, e.g. one unique
per process when several may write one target).  Run directories commit several files at once
(:func:`redrive.results._files.write_files`) with :func:`fsync_file`, :func:`replace` and
:func:`fsync_dir` of this module.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

__all__ = [
    "atomic_path",
    "fsync_dir",
    "fsync_file",
    "replace",
    "sync_tree",
    "temp_path",
    "write_atomic",
]


def temp_path(path: Path) -> Path:
    """The default temp file of ``path``: ``NAME.tmp`` in the same folder."""
    return path.with_name(path.name + ".tmp")


def fsync_file(path: Path) -> None:
    """fsync the file at ``path`` (its data and size, whoever wrote them)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(folder: Path) -> None:
    """fsync a folder, so that the names renamed into it are durable (no-op where folders
    cannot be opened, e.g. Windows)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some filesystems refuse fsync on a directory
        pass
    finally:
        os.close(fd)


def replace(tmp: Path, path: Path) -> None:
    """Rename ``tmp`` over ``path`` (the caller fsyncs the folder once after its renames)."""
    os.replace(tmp, path)


def sync_tree(folder: Path) -> None:
    """fsync every file and folder under ``folder`` (a folder about to be renamed into place)."""
    for root, _dirs, files in os.walk(folder):
        for name in files:
            fsync_file(Path(root) / name)
        fsync_dir(Path(root))


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], *, temp: Path | None = None) -> Iterator[Path]:
    """A temp path to write ``path``'s new content to; when the block ends normally the temp
    file is fsynced, renamed over ``path`` and the folder fsynced.  On an exception the temp
    file is removed and ``path`` is left as it was."""
    target = Path(path)
    tmp = temp_path(target) if temp is None else temp
    try:
        yield tmp
        fsync_file(tmp)
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_dir(target.parent)


def write_atomic(path: str | os.PathLike[str], data: str | bytes) -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` atomically and durably; returns the path."""
    payload = data.encode("utf-8") if isinstance(data, str) else data
    with atomic_path(path) as tmp:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            view = memoryview(payload)
            while view:
                view = view[os.write(fd, view) :]
        finally:
            os.close(fd)
    return Path(path)
