"""The forward scan of an MCAP file: every intact record and every damage, in file order
(:class:`McapScan`), what ``redrive repair``, a reader without a usable summary and
``redrive info`` of a damaged file read. The records and chunks it parses are
:mod:`redrive.io.mcap.scan`'s.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

from redrive.io.damage import LogDamage
from redrive.io.limits import max_chunk_bytes
from redrive.io.mcap.scan import (
    _ANY_OP,
    _CHUNK_OP,
    _KINDS,
    _MESSAGE,
    _OPLEN,
    _U16,
    MAGIC,
    OP_ATTACHMENT,
    OP_CHANNEL,
    OP_CHUNK,
    OP_DATA_END,
    OP_FOOTER,
    OP_MESSAGE,
    OP_METADATA,
    OP_SCHEMA,
    ChunkHead,
    McapChannel,
    McapMetadata,
    RecordError,
    ScanEvent,
    _attachment,
    _channel,
    _schema,
    _string,
    _string_map,
    chunk_head,
    message_index_count,
    read_chunk,
    salvage_cut_chunk,
)

__all__ = ["McapScan"]


class McapScan:
    """One forward pass over the records of an MCAP file in ``buf`` (see the module text);
    ``budget``: the most bytes a chunk is decompressed to (:mod:`redrive.io.limits`)."""

    def __init__(self, buf: memoryview, budget: int | None = None) -> None:
        self.buf = buf
        self.budget = max_chunk_bytes(budget)
        self.size = len(buf)
        self.channel_ids: set[int] = set()
        self.chunked = False

    def events(self, *, counts_only: bool = False) -> Iterator[ScanEvent]:
        """Every intact record's content and every damage, in file order.

        A whole chunk record is announced by ("chunk", :class:`ChunkHead`) before what it holds.

        ``counts_only``: a chunk whose message index records name only channels already seen is
        not decompressed; ("counts", (channel id → messages, first time, last time)) from its
        index and header stands for its messages (a quick pass to open a file without a
        summary; damage inside such a chunk is found when its messages are read).
        """
        buf, size = self.buf, self.size
        pos = len(MAGIC)
        data_done = False  # past the data section: damage there loses no message
        # a damaged chunk whose message index records follow: (damage, messages it yielded,
        # messages its index lists)
        lost: tuple[LogDamage, int, int | None] | None = None
        while pos < size:
            if lost is not None and (n := message_index_count(buf, pos, size)) is not None:
                lost = (lost[0], lost[1], (lost[2] or 0) + n)
                pos += 9 + _OPLEN.unpack_from(buf, pos)[1]
                continue
            if lost is not None:
                yield "damage", _counted(*lost)
                lost = None
            try:
                if pos + 9 > size:
                    raise RecordError("the file ends inside a record header")
                op, length = _OPLEN.unpack_from(buf, pos)
                stop = pos + 9 + length
                head: ChunkHead | None = None
                fixed: ChunkHead | None = None
                if op == OP_CHUNK and not data_done:
                    try:
                        head = chunk_head(buf, pos, size)
                    except RecordError:
                        from redrive.io.mcap.salvage import repaired_chunk_head

                        fixed = repaired_chunk_head(buf, pos, size)
                        if fixed is None and (stop > size or length > size):
                            self.chunked = True  # resync at chunks, not at records inside it
                            resume = self._resync(pos + 1)  # a damaged length, or the file cut
                            yield from self._cut_chunk(pos, length, resume)
                            if resume >= size:
                                return
                            pos = resume
                            continue
                if fixed is not None:
                    self.chunked = True
                    yield "chunk", fixed
                    messages, others, _ = read_chunk(buf, fixed, self.budget)
                    for record in others:
                        yield self._record(record)
                    for message in messages:
                        yield "message", message
                    yield (
                        "damage",
                        LogDamage(
                            what=f"a chunk record's length is damaged ({length} bytes); the "
                            f"chunk is {fixed.stop - pos} bytes long and passes its CRC check: "
                            "its records were read",
                            start_byte=pos,
                            stop_byte=fixed.stop,
                            messages_lost=0,
                        ),
                    )
                    pos = fixed.stop
                    continue
                if stop > size or length > size:
                    kind = _KINDS.get(op, f"an opcode-{op:#04x}")
                    raise RecordError(
                        f"the file is cut off (or a length is damaged): {kind} record of {length} "
                        f"bytes runs past its end at byte {size}"
                    )
                if op == OP_CHUNK:
                    self.chunked = True
                    head = head or chunk_head(buf, pos, size)
                    yield "chunk", head
                    listed = self._listed(stop) if counts_only else None
                    if listed is not None:
                        yield "counts", (listed, head.start_time, head.end_time)
                        pos = stop
                        continue
                    messages, others, why = read_chunk(buf, head, self.budget)
                    for record in others:
                        yield self._record(record)
                    for message in messages:
                        yield "message", message
                    if why is not None:
                        lost = (
                            LogDamage(what=why, start_byte=pos, stop_byte=stop),
                            len(messages),
                            None,
                        )
                elif op == OP_MESSAGE:
                    if length < _MESSAGE.size:
                        raise RecordError("a message record is too short")
                    cid, seq, log_time, pub_time = _MESSAGE.unpack_from(buf, pos + 9)
                    yield "message", (cid, seq, log_time, pub_time, buf[pos + 31 : stop])
                elif op == OP_SCHEMA:
                    yield self._record(_schema(buf, pos + 9, stop))
                elif op == OP_CHANNEL:
                    yield self._record(_channel(buf, pos + 9, stop))
                elif op == OP_METADATA:
                    name, at = _string(buf, pos + 9, stop)
                    yield "metadata", McapMetadata(name, _string_map(buf, at, stop)[0])
                elif op == OP_ATTACHMENT:
                    yield "attachment", _attachment(buf, pos + 9, stop)
                elif op == OP_DATA_END:
                    data_done = True
                elif op == OP_FOOTER:
                    return
                elif not (0 < op <= 0x11 or op >= 0x80):  # 0x80+: private records, skipped
                    raise RecordError(f"opcode {op:#04x} is not an MCAP record")
                pos = stop
            except RecordError as err:
                resume = self._resync(pos + 1)
                yield (
                    "damage",
                    LogDamage(
                        what=("the summary section: " if data_done else "")
                        + (str(err) if resume < size else f"{err}; nothing after it is readable"),
                        start_byte=pos,
                        stop_byte=resume,
                        messages_lost=0 if data_done else None,
                    ),
                )
                pos = resume
        if lost is not None:
            yield "damage", _counted(*lost)

    def _cut_chunk(self, pos: int, length: int, resume: int) -> Iterator[ScanEvent]:
        """:func:`salvage_cut_chunk` of a chunk record running past the end, and the damage."""
        messages, others = salvage_cut_chunk(self.buf, pos, self.budget)
        for record in others:
            yield self._record(record)
        for message in messages:
            yield "message", message
        yield (
            "damage",
            LogDamage(
                what=(
                    f"the file is cut off (or the record's length damaged) inside a chunk record "
                    f"of {length} bytes at byte {self.size}: {len(messages)} whole messages of "
                    "its start were read, the rest of it is lost"
                ),
                start_byte=pos,
                stop_byte=resume,
            ),
        )

    def _listed(self, pos: int) -> dict[int, int] | None:
        """Channel id → messages of the message index records at ``pos`` (after a chunk), or
        None when there are none or they name a channel not seen yet."""
        out: dict[int, int] = {}
        while (n := message_index_count(self.buf, pos, self.size)) is not None:
            (cid,) = _U16.unpack_from(self.buf, pos + 9)
            if cid not in self.channel_ids:
                return None
            out[cid] = out.get(cid, 0) + n
            pos += 9 + _OPLEN.unpack_from(self.buf, pos)[1]
        return out or None

    def _record(self, record: object) -> ScanEvent:
        if isinstance(record, McapChannel):
            self.channel_ids.add(record.id)
            return "channel", record
        return "schema", record

    def _resync(self, start: int) -> int:
        """The position of the next plausible record after ``start`` (the file size if none)."""
        pattern = _CHUNK_OP if self.chunked else _ANY_OP
        while True:
            found = pattern.search(self.buf, start)
            if found is None:
                return self.size
            pos = int(found.start())
            if self._plausible(pos):
                return pos
            start = pos + 1

    def _plausible(self, pos: int) -> bool:
        buf, size = self.buf, self.size
        if pos + 9 > size:
            return False
        op, length = _OPLEN.unpack_from(buf, pos)
        stop = pos + 9 + length
        if stop > size:
            return False
        try:
            if op == OP_CHUNK:
                chunk_head(buf, pos, size)
                return True
            if op == OP_DATA_END:
                return length == 4 and self._next_ok(stop)
            if op == OP_MESSAGE:
                ok = length >= _MESSAGE.size and (
                    _U16.unpack_from(buf, pos + 9)[0] in self.channel_ids
                )
            elif op == OP_SCHEMA:
                ok = _schema(buf, pos + 9, stop) is not None
            elif op == OP_CHANNEL:
                ok = _channel(buf, pos + 9, stop) is not None
            else:
                return False
        except RecordError:
            return False
        return ok and self._next_ok(stop)

    def _next_ok(self, pos: int) -> bool:
        """Whether a record (or the closing magic, or the end) follows at ``pos``."""
        if pos == self.size or bytes(self.buf[pos : pos + 8]) == MAGIC:
            return True
        if pos + 9 > self.size:
            return False
        op, length = _OPLEN.unpack_from(self.buf, pos)
        return bool(0 < op <= 0x11 and pos + 9 + length <= self.size)


def _counted(damage: LogDamage, read: int, listed: int | None) -> LogDamage:
    """``damage`` with the messages it lost: those the chunk's index lists, less those read."""
    return replace(damage, messages_lost=None if listed is None else max(listed - read, 0))
