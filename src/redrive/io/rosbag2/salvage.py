"""What a damaged sqlite3 ROS 2 bag still holds, row by row.

rosbags opens a ``.db3`` with queries over the whole ``messages`` table (message counts per
topic, first and last time) and reads it with one ``SELECT … ORDER BY timestamp``: either stops
at the first page SQLite finds malformed.  Here every message row is asked for by its id instead,
so a damaged page loses only the rows stored in it; each run of unreadable ids becomes one
:class:`~redrive.io.damage.LogDamage` (``message_index``: the first id; ``messages_lost``: how
many ids failed).

- :class:`SalvagingSqlite3Reader` is rosbags' sqlite3 storage plugin, which opens a database
  that rosbags cannot open (its topics and definitions read as they are, its rows one by one);
  an intact database is opened and read by rosbags itself, as fast as before.
- :func:`salvage_sqlite` reads every readable row of a bag's databases after rosbags stopped in
  the middle of reading one.
"""

from __future__ import annotations

import logging
import sqlite3
from collections.abc import Callable, Collection, Generator, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import apsw
from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag2,
    MessageDefinition,
    MessageDefinitionFormat,
)
from rosbags.rosbag2 import ReaderError
from rosbags.rosbag2.metadata import ReaderMetadata, parse_qos
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from redrive.io.damage import LogDamage

__all__ = ["SalvagedRows", "SalvagingSqlite3Reader", "salvage_sqlite"]

logger = logging.getLogger(__name__)

_FORMATS = {"ros2msg": MessageDefinitionFormat.MSG, "ros2idl": MessageDefinitionFormat.IDL}


@dataclass(slots=True)
class SalvagedRows:
    """Readable rows, (timestamp ns, topic, data) sorted by time, and the damage met."""

    rows: list[tuple[int, str, bytes]] = field(default_factory=list)
    damage: list[LogDamage] = field(default_factory=list)


def _connect(db: Path) -> sqlite3.Connection:
    return sqlite3.connect(f"file:{db}?mode=ro&immutable=1", uri=True)


def salvage_sqlite(
    dbs: list[Path],
    *,
    expected: int,
    decompress: Callable[[bytes], bytes] | None = None,
) -> SalvagedRows:
    """Every readable message row of the ``.db3`` files ``dbs``.

    Args:
        dbs: the storage files of the bag.
        expected: the message count ``metadata.yaml`` gives (bounds the ids tried when the
            table's largest id is unreadable).
        decompress: applied to each row's data (bags compressed per message), None for none.
    """
    out = SalvagedRows()
    for db in dbs:
        try:
            con = _connect(db)
            topics: Mapping[int, str] = dict(con.execute("SELECT id, name FROM topics").fetchall())
        except sqlite3.Error as err:
            out.damage.append(
                LogDamage(
                    what=f"{db.name}: its topics table is unreadable ({err}); no message in it is"
                )
            )
            continue
        try:
            for _, stamp, topic, payload in _rows_by_id(
                con, db, topics, last=_last_id(con, expected), decompress=decompress, out=out
            ):
                out.rows.append((stamp, topic, payload))
        finally:
            con.close()
    out.rows.sort(key=lambda r: r[0])
    return out


def _last_id(con: sqlite3.Connection, expected: int) -> int:
    """The largest message id, or a bound on it when the table's last page is unreadable."""
    try:
        row = con.execute("SELECT max(id) FROM messages").fetchone()
        return int(row[0]) if row and row[0] is not None else 0
    except sqlite3.Error:
        return expected + 1000


def _rows_by_id(
    con: sqlite3.Connection,
    db: Path,
    topics: Mapping[int, str],
    *,
    last: int,
    decompress: Callable[[bytes], bytes] | None,
    out: SalvagedRows,
) -> Iterator[tuple[int, int, str, bytes]]:
    """(id, timestamp, topic, data) of every readable row with an id up to ``last``; each run of
    unreadable ids is added to ``out.damage``."""
    query = "SELECT topic_id, timestamp, data FROM messages WHERE id = ?"
    bad_first: int | None = None
    bad_count = 0
    why = ""

    def close_run() -> None:
        nonlocal bad_first, bad_count
        if bad_first is not None:
            out.damage.append(
                LogDamage(
                    what=f"{db.name}: message rows {bad_first}–{bad_first + bad_count - 1} are "
                    f"unreadable ({why})",
                    message_index=bad_first,
                    messages_lost=bad_count,
                )
            )
        bad_first, bad_count = None, 0

    for mid in range(1, last + 1):
        try:
            row = con.execute(query, (mid,)).fetchone()
            if row is None:
                close_run()
                continue
            topic_id, stamp, data = row
            topic = topics.get(int(topic_id))
            if topic is None:
                raise sqlite3.DataError(f"topic id {topic_id} is not in the topics table")
            payload = decompress(bytes(data)) if decompress is not None else bytes(data)
        except Exception as err:  # sqlite3.Error on a bad page; zstd or type errors on bad data
            if bad_first is None:
                bad_first, why = mid, f"{type(err).__name__}: {err}"
            bad_count += 1
            continue
        close_run()
        yield mid, int(stamp), topic, payload
    close_run()


class SalvagingSqlite3Reader(Sqlite3Reader):
    """rosbags' sqlite3 storage, which also opens a database whose message pages are damaged.

    When rosbags cannot open the database (an :mod:`apsw` error: its queries over the whole
    messages table meet a malformed page), its topics and message definitions are read as they
    are and its message rows one by one by id (:attr:`damage`: each run of unreadable ids); the
    readable rows are then read again by id, in time order, by :meth:`messages`. When the topics
    table itself is unreadable, rosbags' error is raised.
    """

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        #: why rosbags could not open the database ("" when it could)
        self.failure = ""
        #: the runs of unreadable message rows of a database rosbags could not open
        self.damage: list[LogDamage] = []
        self._con: sqlite3.Connection | None = None
        self._order: list[tuple[int, int, int]] = []  # (timestamp, id, topic id) of each row

    def open(self) -> None:
        try:
            super().open()
            return
        except ReaderError as err:
            if not isinstance(err.__cause__, apsw.Error):
                raise
            failure = err
        db = Path(str(self.path))
        con = _connect(db)
        try:
            self.connections = _connections(con, self)
        except (sqlite3.Error, ReaderError, ValueError, KeyError, TypeError):
            con.close()
            raise failure from None
        topics = {c.id: c.topic for c in self.connections}
        found = SalvagedRows()
        counts: dict[int, int] = {}
        by_topic = {c.topic: c.id for c in self.connections}
        for mid, stamp, topic, _ in _rows_by_id(
            con, db, topics, last=_last_id(con, 0), decompress=None, out=found
        ):
            cid = by_topic[topic]
            self._order.append((stamp, mid, cid))
            counts[cid] = counts.get(cid, 0) + 1
        self._order.sort()
        self.connections = [c._replace(msgcount=counts.get(c.id, 0)) for c in self.connections]
        self.damage = found.damage
        self.failure = str(failure.__cause__)
        self._con = con
        start = self._order[0][0] if self._order else 2**63 - 1
        end = self._order[-1][0] + 1 if self._order else 0
        self.metadata = ReaderMetadata(
            max(end - start, 0), start, end, len(self._order), None, None, None, None
        )

    def messages(
        self,
        connections: Collection[Connection],
        start: int | None = None,
        stop: int | None = None,
    ) -> Generator[tuple[Connection, int, bytes], None, None]:
        if self._con is None:
            yield from super().messages(connections, start, stop)
            return
        wanted = {c.id for c in connections}
        conns = {c.id: c for c in self.connections}
        query = "SELECT data FROM messages WHERE id = ?"
        for stamp, mid, cid in self._order:
            if cid not in wanted or (start is not None and stamp < start):
                continue
            if stop is not None and stamp >= stop:
                break
            try:
                row = self._con.execute(query, (mid,)).fetchone()
            except sqlite3.Error:  # read a moment ago: only a file changed since fails here
                continue
            if row is not None:
                yield conns[cid], stamp, bytes(row[0])

    def close(self) -> None:
        if self._con is None:
            super().close()
            return
        self._con.close()
        self._con = None
        self._order.clear()
        self.connections.clear()


def _connections(con: sqlite3.Connection, owner: object) -> list[Connection]:
    """The topics table's rows as rosbags' connections (message counts 0), with the message
    definitions the database holds (none when their table is missing or unreadable)."""
    columns = {row[1] for row in con.execute("PRAGMA table_info(topics)")}
    qos = "offered_qos_profiles" if "offered_qos_profiles" in columns else "''"
    digest = "type_description_hash" if "type_description_hash" in columns else "''"
    rows = con.execute(
        f"SELECT id, name, type, serialization_format, {qos}, {digest} FROM topics ORDER BY id"
    ).fetchall()
    definitions: dict[str, MessageDefinition] = {}
    try:
        for name, encoding, text in con.execute(
            "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
        ):
            if encoding in _FORMATS:
                definitions[name] = MessageDefinition(_FORMATS[encoding], text)
    except sqlite3.Error:
        logger.debug("message definitions unreadable", exc_info=True)
    none = MessageDefinition(MessageDefinitionFormat.NONE, "")
    return [
        Connection(
            int(cid),
            str(topic),
            str(msgtype),
            definitions.get(msgtype, none),
            str(dig or ""),
            0,
            ConnectionExtRosbag2(str(fmt), parse_qos(str(qos_text or ""))),
            owner,
        )
        for cid, topic, msgtype, fmt, qos_text, dig in rows
    ]
