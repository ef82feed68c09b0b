"""The messages of one checked chunk of an indexed ROS 1 bag as :class:`~redrive.io.base.LogMessage`
records, those of each connection linked as one :class:`~redrive.io.base.MessageBatch` (what
:class:`~redrive.io.rosbag1.reader.Ros1BagReader` yields chunk by chunk)."""

from __future__ import annotations

from collections.abc import Sequence
from itertools import repeat
from operator import getitem

from redrive.io.base import LogMessage, MessageBatch

__all__ = ["batched_messages"]

_new_message = object.__new__
_SET = tuple(
    LogMessage.__dict__[name].__set__
    for name in ("topic", "msgtype", "log_time_ns", "encoding", "raw", "payload", "batch")
)


def batched_messages(
    chunk: memoryview,
    spans: tuple[Sequence[int], Sequence[int], list[int]],
    conn_ids: list[int],
    heads: dict[int, tuple[str, str]],
    *,
    stride: int | None = None,
) -> list[LogMessage]:
    """The checked messages of one chunk (``spans``: their starts, stops and log times), those
    of each connection linked as one batch (``stride``: the messages' fixed distance, when
    they lie at one and have one size).

    The messages are built through their slots' setters (what the dataclass's ``__init__``
    does), each setter mapped over the whole chunk, and returned as a list (the reader yields
    from it: no generator layer of its own).
    """
    start_at, stop_at, time_at = spans
    count = len(conn_ids)
    slot_of: list[tuple[MessageBatch, int] | None] | zip[tuple[MessageBatch, int]]
    first = conn_ids[0]
    one_connection = conn_ids.count(first) == count
    if one_connection:  # one topic in the chunk: the common case, no loop in Python
        batch = MessageBatch(
            chunk, starts=start_at, stops=stop_at, log_times_ns=time_at, encoding="ros1",
            stride=stride,
        )  # fmt: skip
        slot_of = zip(repeat(batch, count), range(count), strict=True)
    else:
        slot_of = [None] * count
        members: dict[int, list[int]] = {}
        for i, cid in enumerate(conn_ids):
            members.setdefault(cid, []).append(i)
        for rows in members.values():
            batch = MessageBatch(
                chunk,
                starts=[start_at[i] for i in rows],
                stops=[stop_at[i] for i in rows],
                log_times_ns=[time_at[i] for i in rows],
                encoding="ros1",
            )
            for j, i in enumerate(rows):
                slot_of[i] = (batch, j)
    # Every message of the chunk built by C-level iteration over the chunk's lists (what the
    # dataclass's ``__init__`` does through the slots' setters, at a fraction of the cost of a
    # Python step a message): the reader's ``yield from`` is then the only per-message step.
    raws = map(getitem, repeat(chunk), map(slice, start_at, stop_at))
    messages: list[LogMessage] = list(map(_new_message, repeat(LogMessage, count)))
    set_topic, set_type, set_time, set_encoding, set_raw, set_payload, set_batch = _SET
    if one_connection:
        topic, msgtype = heads[first]
        any(map(set_topic, messages, repeat(topic, count)))
        any(map(set_type, messages, repeat(msgtype, count)))
    else:
        pairs = list(map(heads.__getitem__, conn_ids))
        any(map(set_topic, messages, [topic for topic, _ in pairs]))
        any(map(set_type, messages, [msgtype for _, msgtype in pairs]))
    any(map(set_time, messages, time_at))
    any(map(set_encoding, messages, repeat("ros1", count)))
    any(map(set_raw, messages, raws))
    any(map(set_payload, messages, repeat(None, count)))
    any(map(set_batch, messages, slot_of))
    return messages
