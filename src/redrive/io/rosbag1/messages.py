"""The messages of one checked chunk of an indexed ROS 1 bag as :class:`~redrive.io.base.LogMessage`
records, those of each connection linked as one :class:`~redrive.io.base.MessageBatch` (what
:class:`~redrive.io.rosbag1.reader.Ros1BagReader` yields chunk by chunk)."""

from __future__ import annotations

from collections.abc import Sequence
from itertools import repeat
from typing import cast

from redrive.io.base import LogMessage, MessageBatch
from redrive.types._drafts import draft_class

__all__ = ["batched_messages"]

#: LogMessage's draft (:mod:`redrive.types._drafts`): its fields stored as a plain object's,
#: then its class set.
_Draft = draft_class(LogMessage)


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

    Every field of every message is set (what the dataclass's ``__init__`` does with these
    values) on a draft that then becomes the message (:func:`~redrive.types._drafts.draft_class`),
    and the messages are returned as a list (the reader yields from it: no generator layer of
    its own).
    """
    start_at, stop_at, time_at = spans
    count = len(conn_ids)
    first = conn_ids[0]
    topics: Sequence[str] | repeat[str]
    msgtypes: Sequence[str] | repeat[str]
    slots: Sequence[tuple[MessageBatch, int]] | zip[tuple[MessageBatch, int]]
    if conn_ids.count(first) == count:  # one topic in the chunk: the common case
        batch = MessageBatch(
            chunk, starts=start_at, stops=stop_at, log_times_ns=time_at, encoding="ros1",
            stride=stride,
        )  # fmt: skip
        topic, msgtype = heads[first]
        topics, msgtypes = repeat(topic, count), repeat(msgtype, count)
        # Both are count long (no strict=: its keyword parse costs ~1.5 k instructions a zip).
        slots = zip(repeat(batch, count), range(count))  # noqa: B905
    else:
        found: list[tuple[MessageBatch, int] | None] = [None] * count
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
                found[i] = (batch, j)
        pairs = list(map(heads.__getitem__, conn_ids))
        topics = [topic for topic, _ in pairs]
        msgtypes = [msgtype for _, msgtype in pairs]
        slots = cast("list[tuple[MessageBatch, int]]", found)
    messages: list[LogMessage] = []
    append = messages.append
    # Every sequence is count long: the reader's checked spans of this chunk (no strict=, as
    # above).
    for start, stop, time_ns, topic, msgtype, slot in zip(  # noqa: B905
        start_at, stop_at, time_at, topics, msgtypes, slots
    ):
        message = _Draft()
        message.topic = topic
        message.msgtype = msgtype
        message.log_time_ns = time_ns
        message.encoding = "ros1"
        message.raw = chunk[start:stop]
        message.payload = None
        message.batch = slot
        message.__class__ = LogMessage
        append(message)
    return messages
