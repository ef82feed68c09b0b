"""ROS 2 bag directories (``metadata.yaml`` + sqlite3 ``.db3`` or ``.mcap`` storage) via rosbags."""

from __future__ import annotations

import logging
import sqlite3
from collections.abc import Collection, Iterator
from pathlib import Path

from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.rosbag2 import ReaderError as RosbagsReaderError

from redrive.errors import LogError, LogTruncatedError
from redrive.io._deserialize import Deserializer
from redrive.io._reader_base import RosReaderBase
from redrive.io.base import LogMessage, TopicInfo
from redrive.io.typestore import typestore_for

__all__ = ["Ros2BagReader"]

logger = logging.getLogger(__name__)

_SQLITE_MAGIC = b"SQLite format 3\x00"


class Ros2BagReader(RosReaderBase):
    """A rosbag2 directory.  Message bytes are CDR; definitions come from the bag when it embeds
    them (newer bags do), else from ROS 2 Humble plus the packages redrive ships.
    """

    format = "ros2"
    description = (
        "a ROS 2 bag directory (metadata.yaml with sqlite3 or mcap storage; give the directory, "
        "its metadata.yaml or a .db3 in it)"
    )

    @classmethod
    def recognises(cls, path: Path) -> bool:
        if path.is_dir():
            return (path / "metadata.yaml").is_file()
        if path.name == "metadata.yaml":
            return True
        if not (path.parent / "metadata.yaml").is_file():
            return False
        with path.open("rb") as fh:
            return fh.read(len(_SQLITE_MAGIC)) == _SQLITE_MAGIC

    def __init__(self, path: Path, *, strict: bool = True) -> None:
        path = Path(path)
        self.path = path if path.is_dir() else path.parent
        self.strict = strict
        self.damage: str | None = None
        reader = RosbagsReader(self.path)
        try:
            reader.open()
        except (RosbagsReaderError, sqlite3.Error, OSError, ValueError, KeyError) as err:
            msg = f"{self.path}: not a readable ROS 2 bag ({err}); check metadata.yaml and the storage files it lists"
            raise LogError(msg) from err
        self._reader = reader
        #: the storage plugin of the bag: ``mcap`` or ``sqlite3``.
        self.storage = "mcap" if any(self.path.glob("*.mcap")) else "sqlite3"
        definitions: dict[str, tuple[str, str]] = {}
        for conn in reader.connections:
            fmt = conn.msgdef.format
            if fmt == MessageDefinitionFormat.MSG:
                definitions[conn.msgtype] = ("msg", conn.msgdef.data)
            elif fmt == MessageDefinitionFormat.IDL:
                definitions[conn.msgtype] = ("idl", _idl_body(conn.msgdef.data))
        store, _ = typestore_for(2, definitions, needed={c.msgtype for c in reader.connections})
        self._deserializer = Deserializer(self.path, ros1=None, cdr=store)
        self._topics = self._summarise(reader.connections)

    def _summarise(self, connections: list[Connection]) -> dict[str, TopicInfo]:
        out: dict[str, TopicInfo] = {}
        for conn in connections:
            prev = out.get(conn.topic)
            out[conn.topic] = TopicInfo(
                topic=conn.topic,
                msgtype=conn.msgtype,
                count=conn.msgcount + (prev.count if prev else 0),
                encoding="cdr",
                has_definition=self._deserializer.knows(conn.msgtype, "cdr"),
            )
        return dict(sorted(out.items()))

    @property
    def start_ns(self) -> int:
        return int(self._reader.start_time) if self.message_count else 0

    @property
    def end_ns(self) -> int:
        return max(int(self._reader.end_time) - 1, 0) if self.message_count else 0

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        conns = [c for c in self._reader.connections if topics is None or c.topic in topics]
        if topics is not None and not conns:
            return
        count = 0
        try:
            for conn, time_ns, raw in self._reader.messages(conns, start=start_ns, stop=stop_ns):
                count += 1
                yield LogMessage(
                    topic=conn.topic,
                    msgtype=conn.msgtype,
                    log_time_ns=int(time_ns),
                    encoding="cdr",
                    raw=raw,
                )
        except (RosbagsReaderError, sqlite3.Error, OSError, ValueError, EOFError) as err:
            self.damage = f"reading stopped after {count} messages: {err}"
            msg = f"{self.path}: {self.damage}; the storage file may be damaged or cut off"
            if self.strict:
                raise LogTruncatedError(msg, messages_read=count) from err
            logger.warning("%s", msg)

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()


def _idl_body(data: str) -> str:
    """rosbag2 stores several IDL files separated by ``====…\\nIDL: name`` banners: join them."""
    sep = "=" * 80 + "\n"
    if not data.startswith(f"{sep}IDL: "):
        return data
    return "\n".join(part.split("\n", 1)[1] for part in data.split(sep)[1:])
