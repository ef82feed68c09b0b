"""Many PointCloud2 messages of one chunk decoded together (see :class:`~redrive.io.base.MessageBatch`).

A sensor publishes clouds of one layout, so the messages of one connection in a ROS 1 chunk
usually have the same size, the same header but for ``seq`` and the stamp, and lie at a fixed
distance from each other.  Then all their points are one strided array over the chunk: xyz of
every cloud is copied with one numpy call, each cloud's xyz is its slice of that copy and each
channel its row of a strided view — the arrays the one-message path makes, for a few numpy calls
per chunk instead of per message.  Messages that do not fit (another size, another layout, a
layout the one-message fast path does not take) are left to that path.
"""

from __future__ import annotations

from collections.abc import Callable
from itertools import repeat
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from redrive.io._byte_rows import byte_rows
from redrive.io.base import MessageBatch
from redrive.io.decoders._common import buffer_is_immutable
from redrive.io.decoders.base import Decoded
from redrive.types import PointCloud

if TYPE_CHECKING:
    from redrive.io.decoders.pointcloud2 import LayoutCache, _FieldBlock, _Head, _Plan

__all__ = ["BATCH_FROM", "decode_batch"]

#: Batches of fewer messages are decoded one by one (the batch's few numpy calls cost a
#: fixed few tens of µs, what one message costs alone).
BATCH_FROM = 4

_F32 = np.dtype(np.float32)
_U32 = np.dtype("<u4")
_FOUR = np.arange(4, dtype=np.int64)
#: ROS 1 PointCloud2 bytes: seq (4), stamp sec (4), nsec (4), then the frame id's length.
_SAME_FROM = 12

_new = object.__new__
_SET_DECODED = tuple(Decoded.__dict__[n].__set__ for n in ("stamp_ns", "frame_id", "value"))


def _gather(
    buf: bytes | memoryview, at: npt.NDArray[np.int64], member: tuple[Any, ...]
) -> npt.NDArray[Any]:
    """The values of one point member at byte positions ``at`` (+ its offset), copied."""
    dtype, offset = member[0], int(member[1])
    # Element j of ``every`` is the member's value that would start at byte ``offset + j``.
    every: npt.NDArray[Any] = np.ndarray(
        (len(buf) - offset - dtype.itemsize + 1,), dtype, buf, offset, (1,)
    )
    values = every[at]
    values.flags.writeable = False
    return values


def decode_batch(
    batch: MessageBatch,
    *,
    read_head: Callable[[memoryview, str, LayoutCache], _Head],
    layouts: LayoutCache,
    plan_of: Callable[[_FieldBlock], _Plan],
) -> list[Decoded | None]:
    """What :meth:`~redrive.io.decoders.pointcloud2.PointCloud2Decoder.decode` gives each
    message of ``batch`` (equal arrays), for the messages decoded together; None for those the
    caller must decode one by one.  ``read_head``, ``layouts`` and ``plan_of`` are the
    decoder's header parser, layout cache and plan lookup."""
    count = len(batch)
    out: list[Decoded | None] = [None] * count
    buf = batch.buffer
    if count < BATCH_FROM or batch.encoding != "ros1" or not buffer_is_immutable(buf):
        return out
    starts = np.asarray(batch.starts, dtype=np.int64)
    sizes = np.asarray(batch.stops, dtype=np.int64) - starts
    size = int(sizes[0])
    if not (sizes == size).all():
        return out
    first = int(starts[0])
    view = memoryview(buf)[first : first + size]
    try:
        head = read_head(view, "ros1", layouts)
        plan = plan_of(head[5])
    except ValueError:
        return out
    _, _, frame_id, height, width, block, data_offset, data_size, _ = head
    n = width * height
    step = block.point_step
    if (
        plan.view is None
        or plan.missing
        or n == 0
        or not (height == 1 or block.row_step == width * step)
        or data_size < n * step
    ):
        return out
    # Everything from the frame id to the point data must be the first message's.
    same = byte_rows(buf, starts + _SAME_FROM, data_offset - _SAME_FROM)
    if not (same == same[0]).all():
        return out
    stamp = byte_rows(buf, starts + 4, 8).view(_U32)
    stamps = stamp[:, 0].astype(np.int64) * 1_000_000_000 + stamp[:, 1]
    gaps = np.diff(starts)
    if count == 1 or (int(gaps[0]) >= size and (gaps == gaps[0]).all()):
        # At a fixed distance (a chunk of one topic): one strided view of all their points.
        stride = size if count == 1 else int(gaps[0])
        points: npt.NDArray[Any] = np.ndarray(
            (count, n), plan.view, buf, first + data_offset, (stride, step)
        )
        xyz = points["xyz"].copy()
        channels = [(name, points[name]) for name in plan.channels]
    else:
        # Between other topics' messages: gather each member of every point at once.
        at = (starts + data_offset)[:, None] + np.arange(0, n * step, step, dtype=np.int64)
        members = plan.view.fields
        assert members is not None
        xyz = _gather(buf, at, members["xyz"])
        channels = [(name, _gather(buf, at, members[name])) for name in plan.channels]
    xyz = xyz.view(_F32).reshape(count, n, 3)
    xyz.flags.writeable = False
    # A zero stamp means "unset": the message's log time stands in for it.
    stamps_ns = np.where(stamps == 0, batch.log_times_ns, stamps).tolist()
    clouds = PointCloud.many_from_rows(xyz, channels)
    # The Decoded objects built by C-level iteration too (their slots' setters, as ``__init__``).
    decoded: list[Decoded | None] = list(map(_new, repeat(Decoded, count)))
    set_stamp, set_frame, set_value = _SET_DECODED
    any(map(set_stamp, decoded, stamps_ns))
    any(map(set_frame, decoded, repeat(frame_id, count)))
    any(map(set_value, decoded, clouds))
    return decoded
