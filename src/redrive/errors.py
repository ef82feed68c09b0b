"""The redrive exception hierarchy.

Every error redrive raises on purpose derives from :class:`RedriveError`.  Third-party errors are
translated at the boundary (``raise LogError(msg) from err``).  Messages say *what* went wrong,
*where* (file, topic, offset, frame index) and *what to do*.
"""

from __future__ import annotations

import errno

__all__ = [
    "NO_SPACE",
    "AlgorithmError",
    "ConfigError",
    "DiskFullError",
    "LogDamagedError",
    "LogError",
    "LogTruncatedError",
    "MapError",
    "MissingInputError",
    "PluginError",
    "RedriveError",
    "SimulationError",
    "TransportError",
    "UnsupportedMessageError",
    "is_no_space",
]

#: ``errno`` values that mean a file cannot grow: a full disk, a full quota, a file-size limit
NO_SPACE = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


def is_no_space(err: BaseException) -> bool:
    """Whether ``err`` says a file cannot grow (a full disk, a quota, a file-size limit) — an
    ``OSError`` with such an errno, or one from Arrow, which keeps only the text."""
    if not isinstance(err, OSError):
        return False
    if err.errno is not None:
        return err.errno in NO_SPACE
    text = str(err)
    return "No space left on device" in text or "Disk quota exceeded" in text


class RedriveError(Exception):
    """Root of every error redrive raises on purpose."""


class LogError(RedriveError):
    """A log (bag, MCAP, KITTI folder) cannot be opened or read."""


class LogTruncatedError(LogError):
    """A log ends or breaks in the middle; everything before the damage was delivered.

    Attributes:
        messages_read: how many messages were yielded before the damage was hit.
    """

    def __init__(self, msg: str, *, messages_read: int = 0) -> None:
        super().__init__(msg)
        self.messages_read = messages_read


class LogDamagedError(LogTruncatedError):
    """A log holds a damaged record (a corrupt chunk, a malformed header, a cut-off end).

    Raised by readers opened with ``strict=True`` when they reach the damage, after every message
    before it was yielded.  Opened with ``strict=False`` they skip the damage instead and list it
    in their ``damage_report``.

    Attributes:
        messages_read: how many messages were yielded before the damage was hit.
        offset: the byte offset of the damage in the file (None when unknown, e.g. in a database).
    """

    def __init__(self, msg: str, *, messages_read: int = 0, offset: int | None = None) -> None:
        super().__init__(msg, messages_read=messages_read)
        self.offset = offset


class DiskFullError(RedriveError):
    """A file could not be written to its end: the disk (or a quota, or a file-size limit) is
    full.  What was written before is kept and reads back intact (the message says where).

    Attributes:
        path: the file that was being written.
        kept: where what was written is now (None when nothing could be kept).
        written_bytes: its size.
    """

    def __init__(self, msg: str, *, path: str, kept: str | None = None, written_bytes: int = 0):
        super().__init__(msg)
        self.path = path
        self.kept = kept
        self.written_bytes = written_bytes


class UnsupportedMessageError(RedriveError):
    """A message type has no decoder, or a message cannot be decoded into the data model."""


class ConfigError(RedriveError):
    """A user configuration (TOML file, CLI argument) is invalid."""


class MapError(RedriveError):
    """A map file (Lanelet2 OSM, Argoverse 2 vector map …) cannot be read, or one of its
    elements is not valid (the message names the file and the element)."""


class MissingInputError(ConfigError):
    """An algorithm declares an input (a sensor, the ego state, ground truth) the log lacks."""


class PluginError(RedriveError):
    """An algorithm or metric plugin cannot be found, loaded or registered."""


class AlgorithmError(RedriveError):
    """A user algorithm violated its contract (wrong output type, missing input)."""


class TransportError(RedriveError):
    """The shared-memory transport failed (segment missing, version mismatch, torn slot)."""


class SimulationError(RedriveError):
    """The synthetic world or a sensor model was configured or driven inconsistently."""
