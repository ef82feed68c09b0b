"""ROS 2 bag directories (``metadata.yaml`` + sqlite3 ``.db3`` or ``.mcap`` storage) via rosbags.

When rosbags stops on damaged storage, a reader opened with ``strict=False`` goes on with what is
still readable: the message rows of a ``.db3`` one by one (:mod:`redrive.io.rosbag2.salvage`), an
``.mcap`` storage file with redrive's own damage-tolerant MCAP reader.
"""

from __future__ import annotations

import logging
import sqlite3
from collections.abc import Collection, Iterator, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.rosbag2 import ReaderError as RosbagsReaderError
from rosbags.rosbag2.reader import DirectoryReader

from redrive.errors import LogError
from redrive.io.base import LogMessage, TopicInfo
from redrive.io.damage import DamageLog, LogDamage
from redrive.io.ros._reader_base import RosReaderBase
from redrive.io.ros.deserialize import Deserializer
from redrive.io.ros.typestore import typestore_for
from redrive.io.rosbag2.salvage import SalvagingSqlite3Reader, salvage_sqlite

__all__ = ["Ros2BagReader"]

logger = logging.getLogger(__name__)

_SQLITE_MAGIC = b"SQLite format 3\x00"


class _SalvagingDirectory(DirectoryReader):
    """rosbags' bag directory, its sqlite3 databases opened even when their pages are damaged."""

    STORAGE_PLUGINS: Mapping[str, type[Any]] = {
        **DirectoryReader.STORAGE_PLUGINS,
        "sqlite3": SalvagingSqlite3Reader,
    }


class _SalvagingReader(RosbagsReader):
    STORAGE_PLUGINS: Mapping[str, type[Any]] = {
        **RosbagsReader.STORAGE_PLUGINS,
        "dir": _SalvagingDirectory,
    }


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
        self._damage = DamageLog(self.path, strict=strict)
        try:
            reader = _SalvagingReader(self.path)
            reader.open()
        except Exception as err:  # rosbags: ReaderError, apsw/sqlite3 errors, YAML, KeyError …
            if not isinstance(err, RosbagsReaderError | sqlite3.Error | OSError | ValueError):
                logger.debug("rosbags failed to open %s", self.path, exc_info=True)
            msg = (
                f"{self.path}: not a readable ROS 2 bag ({type(err).__name__}: {err}); check "
                "metadata.yaml and the storage files it lists (a storage file damaged at its "
                "start holds nothing redrive can read)"
            )
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
        store, _ = typestore_for(
            2, definitions, needed={c.msgtype for c in reader.connections}, source=self.path
        )
        self._deserializer = Deserializer(self.path, ros1=None, cdr=store)
        self._topics = self._summarise(reader.connections)
        self._opened_damaged = self._open_damage(reader)

    def _open_damage(self, reader: RosbagsReader) -> bool:
        """Record the damage of the databases rosbags could not open (read row by row);
        whether there was any."""
        damaged = False
        for storage in getattr(reader.storage, "storages", ()):
            if not isinstance(storage, SalvagingSqlite3Reader) or not storage.failure:
                continue
            damaged = True
            name = Path(str(storage.path)).name
            for damage in storage.damage or [
                LogDamage(
                    what=f"{name}: the database is damaged ({storage.failure}), but every "
                    "message row in it was read one by one",
                    messages_lost=0,
                )
            ]:
                self._damage.add(damage)
        return damaged

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
        asked = None if topics is None else set(topics)
        conns = [c for c in self._reader.connections if asked is None or c.topic in asked]
        if topics is not None and not conns:
            return
        if self.strict and self._opened_damaged:  # rows of damaged pages: their times unknown
            self._damage.hit(self._damage.items[0], messages_read=0)
        count = 0
        last_ns, at_last = -1, 0  # the last time yielded, and how many messages had it
        try:
            for conn, time_ns, raw in self._reader.messages(conns, start=start_ns, stop=stop_ns):
                count += 1
                at_last = at_last + 1 if time_ns == last_ns else 1
                last_ns = int(time_ns)
                yield LogMessage(
                    topic=conn.topic,
                    msgtype=conn.msgtype,
                    log_time_ns=int(time_ns),
                    encoding="cdr",
                    raw=raw,
                )
            return
        except Exception as err:  # rosbags: apsw.CorruptError, sqlite3, zstd, ReaderError …
            failure = LogDamage(
                what=f"the {self.storage} storage stopped reading after {count} messages "
                f"({type(err).__name__}: {err})",
                message_index=count,
            )
        if self.strict:
            self._damage.hit(failure, messages_read=count)  # raises
        # lenient: the salvage below reports the damage, with what it found
        msgtypes = {c.topic: c.msgtype for c in self._reader.connections}
        wanted = None if topics is None else set(topics)
        salvaged: Iterator[tuple[int, str, bytes | memoryview]] = self._salvaged(failure)
        for time_ns, topic, data in salvaged:
            if (wanted is not None and topic not in wanted) or topic not in msgtypes:
                continue
            if (start_ns is not None and time_ns < start_ns) or (
                stop_ns is not None and time_ns >= stop_ns
            ):
                continue
            if time_ns < last_ns or (time_ns == last_ns and at_last > 0):
                at_last -= time_ns == last_ns
                continue  # yielded before the storage stopped
            yield LogMessage(
                topic=topic,
                msgtype=msgtypes[topic],
                log_time_ns=time_ns,
                encoding="cdr",
                raw=data,
            )

    def _salvaged(self, failure: LogDamage) -> Iterator[tuple[int, str, bytes | memoryview]]:
        """Every message still readable from the storage files, in time order (the damage
        met is added to the report)."""
        if self.storage == "sqlite3":
            compressed = self._reader.compression_mode == "message"
            decompress = None
            if compressed:
                import zstandard

                decompress = zstandard.ZstdDecompressor().decompress
            found = salvage_sqlite(
                sorted(self.path.glob("*.db3")),
                expected=self._reader.message_count,
                decompress=decompress,
            )
            missing = self._reader.message_count - len(found.rows)  # metadata.yaml's count
            for damage in found.damage or [
                replace(
                    failure,
                    what=f"{failure.what}; {len(found.rows)} rows were then read one by one, "
                    f"{max(missing, 0)} of the {self._reader.message_count} that metadata.yaml "
                    "counts are missing",
                    messages_lost=max(missing, 0),
                )
            ]:
                self._damage.add(damage)
            yield from found.rows
            return
        from redrive.io.mcap.reader import McapFileReader

        for storage in sorted(self.path.glob("*.mcap")):
            try:
                reader = McapFileReader(storage, strict=False)
            except LogError as err:
                self._damage.add(LogDamage(what=f"{storage.name}: {err}"))
                continue
            with reader:
                for message in reader.messages():
                    yield message.log_time_ns, message.topic, message.raw
                for damage in reader.damage_report:
                    self._damage.add(replace(damage, what=f"{storage.name}: {damage.what}"))
        if not self._damage.items:  # redrive's reader read past what stopped rosbags
            self._damage.add(failure)

    def definitions(self) -> dict[str, tuple[str, str, str]]:
        """Topic → (message type, definition format ``msg``/``idl`` or "" when the bag holds
        none, definition text) as the bag stores them."""
        out: dict[str, tuple[str, str, str]] = {}
        for conn in self._reader.connections:
            fmt = conn.msgdef.format
            kind = (
                "msg"
                if fmt == MessageDefinitionFormat.MSG and conn.msgdef.data
                else "idl"
                if fmt == MessageDefinitionFormat.IDL and conn.msgdef.data
                else ""
            )
            out[conn.topic] = (conn.msgtype, kind, conn.msgdef.data if kind else "")
        return out

    @property
    def damage_report(self) -> tuple[LogDamage, ...]:
        return tuple(self._damage.items)

    @property
    def damage(self) -> str | None:
        """The damage met so far, as one line (None while none was met)."""
        return "; ".join(str(d) for d in self._damage.items) or None

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()


def _idl_body(data: str) -> str:
    """rosbag2 stores several IDL files separated by ``====…\\nIDL: name`` banners: join them."""
    sep = "=" * 80 + "\n"
    if not data.startswith(f"{sep}IDL: "):
        return data
    return "\n".join(part.split("\n", 1)[1] for part in data.split(sep)[1:])
