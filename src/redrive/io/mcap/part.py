"""One MCAP file being written: its :class:`~redrive.io.mcap.stream.McapStream`, the ``.part``
file it goes to (:mod:`redrive.io.partfiles`) and the target it becomes.

:meth:`McapPart.close` finishes the file (summary, footer), syncs it and moves it into place;
:meth:`McapPart.abort` drops it. A write that fails because the disk is full (or a quota or a
file-size limit, :data:`~redrive.errors.NO_SPACE`) loses nothing that reached the file:
:meth:`McapPart.out_of_space` cuts the part back to its last whole chunk, closes it with the
summary of what it holds when there is room, puts it at the target (or beside it, never over an
existing file) and returns the :class:`~redrive.errors.DiskFullError` that says where it is.
"""

from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path

from redrive.errors import DiskFullError, LogError, is_no_space
from redrive.io.mcap.stream import McapStream, StreamCompression
from redrive.io.partfiles import create_part, keep_part

__all__ = ["McapPart"]

logger = logging.getLogger(__name__)


class McapPart:
    """An MCAP file written to a part beside ``target`` (see the module text).

    Args:
        target: the file it becomes.
        profile: the MCAP header's profile (``ros1``, ``ros2``; "" for none).
        library: the header's library.
        compression, chunk_size_bytes, live, zstd_level: as :class:`McapStream`.

    Raises:
        LogError: the folder cannot be written.
    """

    def __init__(
        self,
        target: Path,
        *,
        profile: str,
        library: str = "redrive",
        compression: StreamCompression = "zstd",
        chunk_size_bytes: int = 1 << 20,
        live: bool = False,
        zstd_level: int | None = None,
    ) -> None:
        self.target = target
        try:
            fd, self.tmp = create_part(target)
        except OSError as err:
            msg = (
                f"{target}: cannot create a file in {target.parent} ({err.strerror}); check the "
                "folder exists, is writable and has space"
            )
            raise LogError(msg) from err
        self.fd: int | None = fd
        self.stream = McapStream(
            fd,
            compression=compression,
            chunk_size_bytes=chunk_size_bytes,
            live=live,
            zstd_level=zstd_level,
        )
        try:
            self.stream.start(profile=profile, library=library)
        except OSError as err:
            self.abort()  # not even the header: nothing to keep
            if is_no_space(err):
                msg = f"{target}: no space left ({err.strerror}); nothing was written to it"
                raise DiskFullError(msg, path=str(target)) from err
            raise

    @property
    def is_open(self) -> bool:
        return self.fd is not None

    def close(self) -> Path:
        """Finish the file, sync it and move it to the target; returns the target.

        Raises:
            DiskFullError: the disk filled while finishing (what was written is kept).
        """
        fd = self.fd
        if fd is None:
            return self.target
        try:
            self.stream.finish()
            os.fsync(fd)
        except OSError as err:
            if is_no_space(err):
                raise self.out_of_space(err) from err
            self.abort()
            raise
        except BaseException:
            self.abort()
            raise
        self.fd = None
        try:
            os.close(fd)
            os.replace(self.tmp, self.target)
        except BaseException:
            self.tmp.unlink(missing_ok=True)
            raise
        return self.target

    def abort(self) -> None:
        """Drop the file (nothing appears at the target). Idempotent."""
        fd, self.fd = self.fd, None
        if fd is None:
            return
        self.stream.abandon()
        with contextlib.suppress(OSError):
            os.close(fd)
        self.tmp.unlink(missing_ok=True)

    def out_of_space(self, err: OSError) -> DiskFullError:
        """Keep what reached the file after ``err`` (a write that found no space): the part cut
        to its last whole chunk and closed with its summary when there is room, moved to the
        target (or beside it); the error that says so, to raise."""
        fd, self.fd = self.fd, None
        kept: Path | None = None
        indexed = False
        if fd is not None:
            try:
                indexed = self.stream.salvage()
            except OSError:  # cannot even cut it back: the part stays as it is
                logger.debug("salvaging %s", self.tmp, exc_info=True)
            with contextlib.suppress(OSError):
                os.close(fd)
            kept = keep_part(self.tmp, self.target)
        size = kept.stat().st_size if kept is not None and kept.exists() else 0
        messages = self.stream.written_messages
        how = (
            "with its index"
            if indexed
            else "without its index (`redrive repair` writes an indexed copy)"
        )
        where = f"kept in {kept}" if kept is not None else "lost"
        msg = (
            f"{self.target}: no space left ({err.strerror or err}) after {messages} messages, "
            f"{size} bytes: what was written is {where}, readable {how}; free some space "
            "and run the command again"
        )
        return DiskFullError(
            msg, path=str(self.target), kept=None if kept is None else str(kept), written_bytes=size
        )
