"""What a damaged sqlite3 ROS 2 bag still holds, row by row.

rosbags reads a ``.db3`` with one ``SELECT … ORDER BY timestamp``, which stops at the first page
SQLite finds malformed.  :func:`salvage_sqlite` asks for every message row by its id instead, so
a damaged page loses only the rows stored in it; each run of unreadable ids becomes one
:class:`~redrive.io.damage.LogDamage` (``message_index``: the first id; ``messages_lost``: how
many ids failed).
"""

from __future__ import annotations

import logging
import sqlite3
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from redrive.io.damage import LogDamage

__all__ = ["SalvagedRows", "salvage_sqlite"]

logger = logging.getLogger(__name__)


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
            try:
                row = con.execute("SELECT max(id) FROM messages").fetchone()
                last = int(row[0]) if row and row[0] is not None else 0
            except sqlite3.Error:
                last = expected + 1000
            _rows_by_id(con, db, topics, last=last, decompress=decompress, out=out)
        finally:
            con.close()
    out.rows.sort(key=lambda r: r[0])
    return out


def _rows_by_id(
    con: sqlite3.Connection,
    db: Path,
    topics: Mapping[int, str],
    *,
    last: int,
    decompress: Callable[[bytes], bytes] | None,
    out: SalvagedRows,
) -> None:
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
        out.rows.append((int(stamp), topic, payload))
    close_run()
