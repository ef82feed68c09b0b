"""The damage report of a log reader: what was skipped, where, and how many messages it held.

Readers of damaged logs opened with ``strict=False`` skip what they cannot read and resume at the
next intact record; each skip is one :class:`LogDamage` in the reader's ``damage_report``.  With
``strict=True`` the first one raises :class:`~redrive.errors.LogDamagedError` instead (after every
message before it was yielded).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from redrive.errors import LogDamagedError

__all__ = ["DamageLog", "LogDamage", "damage_report", "refused"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class LogDamage:
    """One damaged part of a log.

    Attributes:
        what: what is damaged and how (``"chunk does not decompress (…)"``).
        start_byte: first byte of the damaged part in the file (None in a database).
        stop_byte: the byte after it: reading resumed there (the file size when nothing after it
            was readable).
        messages_lost: messages the damaged part held, when the log says (an index, a
            statistics record); None when unknown.
        message_index: in a log without byte offsets (a ROS 2 database), the index of the first
            message that could not be read.
    """

    what: str
    start_byte: int | None = None
    stop_byte: int | None = None
    messages_lost: int | None = None
    message_index: int | None = None

    def __str__(self) -> str:
        where = (
            f"bytes {self.start_byte}–{self.stop_byte}: "
            if self.start_byte is not None
            else f"from message {self.message_index}: "
            if self.message_index is not None
            else ""
        )
        lost = (
            "messages lost unknown"
            if self.messages_lost is None
            else f"{self.messages_lost} message{'s' if self.messages_lost != 1 else ''} lost"
        )
        return f"{where}{self.what} ({lost})"

    def to_json(self) -> dict[str, object]:
        return {
            "what": self.what,
            "start_byte": self.start_byte,
            "stop_byte": self.stop_byte,
            "messages_lost": self.messages_lost,
            "message_index": self.message_index,
        }


class DamageLog:
    """A reader's list of damage, de-duplicated (a log read twice meets its damage twice), and
    the strict / lenient decision in one place."""

    def __init__(self, path: Path, *, strict: bool) -> None:
        self.path = path
        self.strict = strict
        self.items: list[LogDamage] = []

    def add(self, damage: LogDamage) -> None:
        """Record ``damage`` (logged as a warning the first time)."""
        if damage not in self.items:
            self.items.append(damage)
            logger.warning("%s: damaged, skipped %s", self.path, damage)

    def hit(self, damage: LogDamage, *, messages_read: int) -> None:
        """Reading reached ``damage``: raise when strict, else record it and go on."""
        if self.strict:
            raise refused(self.path, damage, messages_read=messages_read)
        self.add(damage)


def refused(path: Path, damage: LogDamage, *, messages_read: int) -> LogDamagedError:
    """The error that refuses the log at ``path`` for ``damage`` (strict reading)."""
    msg = (
        f"{path}: damaged {'at ' if damage.start_byte is not None else ''}{damage}; "
        f"{messages_read} messages were read before it. "
        "`redrive info` lists all the damage, `redrive repair` saves what is intact. To "
        "read past it: `redrive run` or `info` without --strict, `redrive convert "
        "--skip-damaged`, open_log(..., strict=False)."
    )
    return LogDamagedError(msg, messages_read=messages_read, offset=damage.start_byte)


def damage_report(log: object) -> tuple[LogDamage, ...]:
    """The damage a reader met so far (``damage_report`` attribute; () for readers without)."""
    items = getattr(log, "damage_report", ())
    return tuple(items)
