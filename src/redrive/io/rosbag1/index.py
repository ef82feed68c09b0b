"""The index of an intact ROS 1 bag as arrays, and the messages of one chunk found and checked
with a few array operations instead of a header walk per message.

:class:`~redrive.io.rosbag1.reader.Ros1BagReader` reads a chunk's messages from the offsets of the
bag's index.  Every message must carry the index's time and connection (a damaged index points
at other bytes).  :func:`chunk_spans` checks that for all messages of a chunk at once: when their
record headers all have the length and the field layout of the first (what every recorder
writes), comparing each header with the first one's bytes, the index's ``conn`` / ``time``
values written into it, is the same check as walking each header.  Many messages are compared
as one gathered array; a few (a chunk of large clouds holds a dozen or so) one ``bytes`` at a
time, which costs less than the array operations' fixed cost.  When they do not, it returns
None and the reader walks each message as before (and reports the damage at the right message).
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Mapping, Sequence
from itertools import chain
from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.rosbag1 import Reader as RosbagsReader

from redrive.io._byte_rows import byte_rows
from redrive.io.rosbag1.records import OP_MSGDATA, TIME, U32, DamageError, record_op

__all__ = [
    "ARRAYS_FROM",
    "REGULAR_FROM",
    "IndexArrays",
    "chunk_counts",
    "chunk_spans",
    "index_contradiction",
    "merged_index",
    "ros1_times",
]

_I64 = npt.NDArray[np.int64]

#: From this many messages a chunk's headers are compared as one array (≈ 30 numpy calls, a
#: fixed cost); fewer are compared one ``bytes`` at a time (≈ 1 µs a message).
ARRAYS_FROM = 32


class IndexArrays:
    """One connection's index entries as arrays, in the index's (time, chunk, offset) order."""

    __slots__ = ("chunk_pos", "offsets", "times")

    def __init__(self, entries: Sequence[Any]) -> None:
        # ``np.fromiter`` over the flattened (time, chunk, offset) triples: ≈ 0.2 µs an entry,
        # where ``np.array(entries)`` discovers the shape of every tuple (≈ 1.3 µs an entry —
        # a pass over a 15,000-message bag paid 19 ms for it before its first message).
        count = 3 * len(entries)
        flat = np.fromiter(chain.from_iterable(entries), dtype=np.int64, count=count)
        table = flat.reshape(len(entries), 3)
        self.times: _I64 = table[:, 0].copy()
        self.chunk_pos: _I64 = table[:, 1].copy()
        self.offsets: _I64 = table[:, 2].copy()


def merged_index(
    arrays: Mapping[int, IndexArrays], conn_ids: Sequence[int], start_ns: int | None
) -> tuple[_I64, _I64, _I64, _I64]:
    """(times, chunk positions, offsets, connection ids) of the entries of ``conn_ids`` at or
    after ``start_ns``, ordered as ``heapq.merge`` of the per-connection (time, chunk, offset,
    connection) streams orders them."""
    parts: list[tuple[_I64, _I64, _I64, _I64]] = []
    for conn_id in conn_ids:
        index = arrays[conn_id]
        first = 0 if start_ns is None else int(np.searchsorted(index.times, start_ns, "left"))
        n = len(index.times) - first
        parts.append(
            (
                index.times[first:],
                index.chunk_pos[first:],
                index.offsets[first:],
                np.full(n, conn_id, dtype=np.int64),
            )
        )
    if not parts:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty, empty
    if len(parts) == 1:
        return parts[0]
    times, chunks, offsets, conns = (np.concatenate(column) for column in zip(*parts, strict=True))
    order = np.lexsort((conns, offsets, chunks, times))
    return times[order], chunks[order], offsets[order], conns[order]


def _value_spans(head: bytes) -> dict[bytes, tuple[int, int]] | None:
    """Field name → (start, stop) of its value in a record header's field bytes; None when a
    name repeats (the header is then walked message by message)."""
    spans: dict[bytes, tuple[int, int]] = {}
    at = 0
    while at + 4 <= len(head):
        (flen,) = U32.unpack_from(head, at)
        at += 4
        end = at + flen
        sep = head.find(b"=", at, end)
        if sep < 0 or end > len(head):
            return None
        name = head[at:sep]
        if name in spans:
            return None
        spans[name] = (sep + 1, end)
        at = end
    return spans


def chunk_spans(
    chunk: memoryview,
    offsets: Sequence[int],
    times: Sequence[int],
    conns: Sequence[int],
    *,
    stamps: bytes | None = None,
) -> tuple[Sequence[int], Sequence[int], int | None] | None:
    """(starts, stops, stride) of the data of the messages the index places at ``offsets`` of
    ``chunk`` (lists or int64 arrays, as ``times`` and ``conns``), when each is a message
    record carrying the index's time and connection; None when the records cannot be checked
    all at once (or one fails): walk them one by one then.  ``stride`` is the fixed distance
    between consecutive messages when they lie at one and all have one size (a chunk of one
    sensor's clouds; starts and stops are then ``range`` objects), else None (lists).
    ``stamps``: ``times`` as :func:`ros1_times` gives them, when the caller has them.

    Every header must have the first header's length and bytes, but for the values of ``conn``
    and ``time``, which must be the index's.  The first header is walked as
    :func:`~redrive.io.rosbag1.records.record_op` walks any (its ``op`` must be a message's).
    """
    end = len(chunk)
    at = _as_list(offsets)
    count = len(at)
    if count == 0:
        return None
    first = at[0]
    stride = at[1] - first if count > 1 else 0
    regular = count >= REGULAR_FROM and stride > 0 and at == list(range(first, at[-1] + 1, stride))
    low, last = (first, at[-1]) if regular else (min(at), max(at))
    if last + 8 > end or low < 0 or first + 4 > end:
        return None
    (size,) = U32.unpack_from(chunk, first)
    if first + 4 + size > end:
        return None
    template = bytes(chunk[first + 4 : first + 4 + size])
    found = _template_spans(template)
    if found is None:
        return None
    conn_span, time_span = found
    if last + 8 + size > end:
        return None
    if regular:
        if stamps is None:
            stamps = ros1_times(np.asarray(times, dtype=np.int64))
        spans = (
            None
            if stamps is None
            else _regular_spans(
                chunk,
                (first, stride, count),
                (stamps, _as_list(conns)),
                template,
                (conn_span, time_span),
            )
        )
        if spans is not None:
            return spans
    if count < ARRAYS_FROM:
        return _spans_one_by_one(
            chunk,
            (at, _as_list(times), _as_list(conns)),
            template,
            conn_span=conn_span,
            time_span=time_span,
        )
    # One gather: per message its header length, header and data length.
    offsets_at = np.asarray(offsets, dtype=np.int64)
    rows = byte_rows(chunk, offsets_at, size + 8)
    same = (rows == rows[0]).all(axis=0)
    same[4 + conn_span[0] : 4 + conn_span[1]] = True
    same[4 + time_span[0] : 4 + time_span[1]] = True
    same[size + 4 :] = True
    if not same.all() or rows[0, :4].tobytes() != U32.pack(size):
        return None
    # The values the index gives, as the header would hold them (what the walk compares).
    secs, nsecs = np.divmod(np.asarray(times, dtype=np.int64), 1_000_000_000)
    want_time = np.stack([secs, nsecs], axis=1).astype("<u4").view(np.uint8)
    want_conn = np.asarray(conns, dtype=np.int64).astype("<u4").view(np.uint8).reshape(count, 4)
    if not (
        (rows[:, 4 + time_span[0] : 4 + time_span[1]] == want_time).all()
        and (rows[:, 4 + conn_span[0] : 4 + conn_span[1]] == want_conn).all()
    ):
        return None
    starts = offsets_at + (8 + size)
    stops = starts + rows[:, size + 4 :].copy().view("<u4")[:, 0]
    if int(stops.max()) > end:
        return None
    return starts.tolist(), stops.tolist(), None


def _as_list(values: Sequence[int]) -> list[int]:
    """``values`` as a list of ints (an array's ``tolist``; a list as it is)."""
    if type(values) is list:
        return values
    tolist = getattr(values, "tolist", None)
    return list(tolist()) if tolist is not None else list(values)


#: From this many messages at a fixed distance a chunk is checked as one ``struct`` unpack
#: (:func:`_regular_spans`: a few list comparisons, no numpy call).
REGULAR_FROM = 2

#: The record header layouts seen last: the header's length → (the header with its conn and
#: time values zeroed, (conn span, time span)); a chunk's first header of a known layout is
#: then not walked again (the walk's result depends on no byte of those values).
_LAYOUTS: dict[int, tuple[bytes, tuple[tuple[int, int], tuple[int, int]]]] = {}


def _masked(template: bytes, conn_span: tuple[int, int], time_span: tuple[int, int]) -> bytes:
    (a, b), (c, d) = sorted((conn_span, time_span))
    return b"".join((template[:a], bytes(b - a), template[b:c], bytes(d - c), template[d:]))


def _template_spans(
    template: bytes,
) -> tuple[tuple[int, int], tuple[int, int]] | None:
    """(conn span, time span) of the values in a chunk's first record header (its field
    bytes), when it is a message record's with a 4-byte ``conn`` and an 8-byte ``time``; None
    otherwise.  The header is walked as :func:`~redrive.io.rosbag1.records.record_op` walks
    any, unless it has the layout of the last header of its length (:data:`_LAYOUTS`)."""
    known = _LAYOUTS.get(len(template))
    if known is not None and _masked(template, *known[1]) == known[0]:
        return known[1]
    size = len(template)
    try:
        op, _ = record_op(U32.pack(size) + template, 0, size + 4)
    except DamageError:
        return None
    if op != OP_MSGDATA:
        return None
    spans = _value_spans(template)
    if spans is None:
        return None
    conn_span = spans.get(b"conn")
    time_span = spans.get(b"time")
    if conn_span is None or time_span is None:
        return None
    if conn_span[1] - conn_span[0] != 4 or time_span[1] - time_span[0] != 8:
        return None
    if len(_LAYOUTS) > 16:
        _LAYOUTS.clear()
    _LAYOUTS[size] = (_masked(template, conn_span, time_span), (conn_span, time_span))
    return conn_span, time_span


def _regular_spans(
    chunk: memoryview,
    grid: tuple[int, int, int],
    index: tuple[bytes, list[int]],
    template: bytes,
    value_spans: tuple[tuple[int, int], tuple[int, int]],
) -> tuple[range, range, int] | None:
    """:func:`chunk_spans`' check for messages of one connection at a fixed distance
    (``grid``: the first offset, the distance, the count) that all have the first one's data
    length: every record's header length, header and data length read at once (one
    ``struct`` unpack over the chunk: the bytes before the ``time`` value, that value, the
    bytes after it) and compared with the first record's, which must hold the index's
    ``conn``, and with the index's times (``index``: as ROS 1 times, and the connections) —
    the same check as the walk's.  None when they do not all match (the general check then
    decides)."""
    first, stride, count = grid
    stamps, conns = index
    conn_span, (time_a, time_b) = value_spans
    size = len(template)
    width = size + 8
    (length,) = U32.unpack_from(chunk, first + 4 + size)
    last = first + (count - 1) * stride
    conn = conns[0]
    if (
        last + width + length > len(chunk)
        or stride < width + length
        or conns.count(conn) != count
        or not 0 <= conn < 1 << 32
        or template[conn_span[0] : conn_span[1]] != U32.pack(conn)
    ):
        return None
    values = _record_struct(time_a, size, stride, count).unpack_from(chunk, first)
    # The bytes around the time value must be the first record's (with its header length
    # before and its data length after), the time values the index's.
    if not (
        b"".join(values[1::3]) == stamps
        and values[0::3].count(U32.pack(size) + template[:time_a]) == count
        and values[2::3].count(template[time_b:] + U32.pack(length)) == count
    ):
        return None
    starts = range(first + width, last + width + 1, stride)
    return starts, range(starts.start + length, starts.stop + length, stride), stride


def ros1_times(times: npt.NDArray[np.int64]) -> bytes | None:
    """``times`` (int ns) as ROS 1 times (``uint32`` seconds and nanoseconds, 8 bytes each),
    as a record header holds them; None when one is not a ROS 1 time."""
    secs, nsecs = np.divmod(times, 1_000_000_000)
    if len(times) and (int(secs.min()) < 0 or int(secs.max()) >= 1 << 32):
        return None
    return np.stack((secs, nsecs), axis=1).astype("<u4").tobytes()


@functools.lru_cache(maxsize=64)
def _record_struct(time_at: int, size: int, stride: int, count: int) -> struct.Struct:
    """The ``struct`` that reads ``count`` records of ``size``-byte headers ``stride`` apart
    as three items each: the bytes before the ``time`` value (at ``time_at`` in the header),
    that value, the bytes after it up to the end of the data length (the rest of the record
    is skipped)."""
    record = f"{4 + time_at}s8s{size - time_at - 4}s"
    return struct.Struct("<" + f"{record}{stride - size - 8}x" * (count - 1) + record)


def _spans_one_by_one(
    chunk: memoryview,
    index: tuple[list[int], list[int], list[int]],
    template: bytes,
    *,
    conn_span: tuple[int, int],
    time_span: tuple[int, int],
) -> tuple[list[int], list[int], None] | None:
    """:func:`chunk_spans`' check for a few messages: each header is compared as ``bytes``
    with the first one's, the index's ``conn`` and ``time`` written into it (the same check as
    the array comparison; every offset is already known to leave room for the header and the
    data length).  ``index``: the messages' offsets, times and connections."""
    size = len(template)
    prefix = U32.pack(size)
    # The header as its pieces around the conn and time values, in the order they lie.
    (a, b, first_is), (c, d, _) = sorted(
        ((conn_span[0], conn_span[1], "conn"), (time_span[0], time_span[1], "time"))
    )
    head, middle, tail = prefix + template[:a], template[b:c], template[d:]
    starts: list[int] = []
    stops: list[int] = []
    end = len(chunk)
    offsets, times, conns = index
    for offset, time_ns, conn_id in zip(offsets, times, conns, strict=True):
        try:
            conn = U32.pack(conn_id)
            stamp = TIME.pack(*divmod(time_ns, 1_000_000_000))
        except struct.error:  # not a ROS 1 time or connection id: left to the walk, as before
            return None
        first, second = (conn, stamp) if first_is == "conn" else (stamp, conn)
        if bytes(chunk[offset : offset + 4 + size]) != head + first + middle + second + tail:
            return None
        start = offset + 8 + size
        (length,) = U32.unpack_from(chunk, start - 4)
        if start + length > end:
            return None
        starts.append(start)
        stops.append(start + length)
    return starts, stops, None


def index_contradiction(reader: RosbagsReader) -> str | None:
    """Why the bag's index cannot be right (None when it is consistent): every entry must point
    into a known chunk, within that chunk's time range, and the entries per chunk and connection
    must add up to the chunk's counts.  A damaged index (zeroed, flipped) fails this, and the
    bag is then read sequentially instead of trusting offsets that point at other messages."""
    infos = {info.pos: info for info in reader.chunk_infos}
    if set(infos) != set(reader.chunks):
        return "the chunk infos and the chunks of the index do not match"
    counts: dict[tuple[int, int], int] = {}
    for conn_id, entries in reader.indexes.items():
        for entry in entries:
            info = infos.get(entry.chunk_pos)
            if info is None or not info.start_time <= entry.time <= info.end_time:
                return f"an index entry of connection {conn_id} points outside its chunk"
            key = (entry.chunk_pos, conn_id)
            counts[key] = counts.get(key, 0) + 1
    for info in infos.values():
        for conn_id, count in info.connection_counts.items():
            if counts.get((info.pos, conn_id), 0) != count:
                return f"the index of the chunk at byte {info.pos} does not match its counts"
    return None


def chunk_counts(reader: RosbagsReader | None, chunk_pos: int) -> dict[int, int]:
    if reader is None:
        return {}
    for info in reader.chunk_infos:
        if info.pos == chunk_pos:
            return dict(info.connection_counts)
    return {}
