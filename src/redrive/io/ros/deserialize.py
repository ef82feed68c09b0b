"""Deserialising ROS 1 / CDR message bytes with a log's typestore, with errors that say where."""

from __future__ import annotations

from pathlib import Path

from rosbags.typesys.store import Typestore

from redrive.errors import UnsupportedMessageError
from redrive.io.base import LogMessage

__all__ = ["Deserializer"]


class Deserializer:
    """``deserialize(message)`` for one log: ROS 1 bytes with one typestore, CDR with another."""

    def __init__(self, path: Path, *, ros1: Typestore | None, cdr: Typestore | None) -> None:
        self.path = path
        self.ros1 = ros1
        self.cdr = cdr

    @property
    def typestores(self) -> dict[str, Typestore]:
        """Encoding (``ros1`` / ``cdr``) → the typestore its bytes are read with."""
        out: dict[str, Typestore] = {}
        if self.ros1 is not None:
            out["ros1"] = self.ros1
        if self.cdr is not None:
            out["cdr"] = self.cdr
        return out

    def knows(self, msgtype: str, encoding: str) -> bool:
        store = self.ros1 if encoding == "ros1" else self.cdr if encoding == "cdr" else None
        return store is not None and msgtype in store.fielddefs

    def __call__(self, message: LogMessage) -> object:
        where = f"{self.path}: topic {message.topic} at {message.log_time_ns} ns"
        if message.encoding == "native":
            msg = f"{where}: the message is already decoded (native); it has no ROS bytes"
            raise UnsupportedMessageError(msg)
        if not self.knows(message.msgtype, message.encoding):
            msg = (
                f"{where}: no definition of {message.msgtype} is known (the log embeds none that "
                "parses, and redrive ships none); its messages pass through undecoded"
            )
            raise UnsupportedMessageError(msg)
        try:
            if message.encoding == "ros1":
                assert self.ros1 is not None
                return self.ros1.deserialize_ros1(message.raw, message.msgtype)
            assert self.cdr is not None
            return self.cdr.deserialize_cdr(message.raw, message.msgtype)
        except Exception as err:  # rosbags raises plain struct/index errors on bad bytes
            msg = (
                f"{where}: the {message.msgtype} message does not deserialise "
                f"({type(err).__name__}: {err}); the log may be damaged or its definition wrong"
            )
            raise UnsupportedMessageError(msg) from err
