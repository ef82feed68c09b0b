"""Many PointCloud2 messages of one chunk decoded together (see :class:`~redrive.io.base.MessageBatch`).

A sensor publishes clouds of one layout, so the messages of one connection in a ROS 1 chunk
usually have the same size, the same header but for ``seq`` and the stamp, and lie at a fixed
distance from each other.  Then the point bytes of all of them are the rows of one strided view
of the chunk, and xyz and every channel of every cloud are strided views — the arrays the
one-message path makes, by C-level iteration over the chunk's clouds instead of a Python step
per message.  What they view:

* the chunk itself, when it is a private immutable ``bytes`` (the ROS 1 reader reads a chunk of
  clouds into one; a decompressed chunk is one) and the batch's clouds are at least
  :data:`VIEW_SHARE` of it: nothing is copied, and the clouds kept pin at most
  1 / :data:`VIEW_SHARE` times their own bytes (one cloud kept pins its whole chunk, at most
  :data:`VIEW_MAX_BYTES` unless it fills half of it alone);
* otherwise (a file map, a sparse selection: one small topic in chunks of another) a copy of
  their point bytes, in groups of at most :data:`GROUP_BYTES`.

Messages that do not fit (another size, another layout, a layout the one-message fast path does
not take) are left to that path.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Callable
from itertools import islice, repeat
from operator import getitem
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

from redrive.io._byte_rows import byte_rows
from redrive.io.base import MessageBatch
from redrive.io.ros.decoders._common import buffer_is_immutable
from redrive.io.ros.decoders.base import Decoded
from redrive.types import PointCloud
from redrive.types._drafts import draft_class

if TYPE_CHECKING:
    from redrive.io.ros.decoders.pointcloud2 import LayoutCache, _FieldBlock, _Head, _Plan

#: The member of a plan's view dtype that holds x, y, z as a float32 (3,) subarray.
_XYZ = "xyz"

__all__ = [
    "BATCH_FROM",
    "GROUP_BYTES",
    "VIEW_MAX_BYTES",
    "VIEW_SHARE",
    "BatchHeads",
    "decode_batch",
    "views_buffer",
]

#: Batches of fewer messages are decoded one by one (the batch's few numpy calls cost a
#: fixed few tens of µs, what one message costs alone).
BATCH_FROM = 4

#: The largest copy of point bytes the clouds of a chunk share (see ``decode_batch``).
GROUP_BYTES = 256 << 10

#: Clouds view a reader's private chunk buffer (no copy) when their point bytes are at least
#: this share of it: a chunk kept alive by its clouds is then at most 1 / VIEW_SHARE = 2 times
#: their bytes; a sparse selection is copied instead, so that it never pins a chunk of others'
#: bytes.  (A single cloud kept pins its chunk: a few hundred KiB to a few MiB as recorders cut
#: them, or ≈ its own size for a cloud that fills one; never more than VIEW_MAX_BYTES unless
#: it fills the chunk itself.)
VIEW_SHARE = 0.5

#: Clouds sharing a chunk view it only when it is at most this large (a recorder's chunks are
#: ≈ 1 MiB: rosbag's default is 768 KiB), so one cloud kept never pins more than this or twice
#: its own bytes, whatever chunk size the bag was recorded with.
VIEW_MAX_BYTES = 4 << 20

_U32 = np.dtype("<u4")
_SEC_NS = np.array([1_000_000_000, 1], dtype=np.int64)
#: ROS 1 PointCloud2 bytes: seq (4), stamp sec (4), nsec (4), then the frame id's length.
_STAMP_AT = 4
_SAME_FROM = 12

#: ``points[name]``: a field of a structured array, for ``map``.
_field = cast("Callable[[npt.NDArray[Any], str], npt.NDArray[Any]]", getitem)
#: Decoded's draft (:mod:`redrive.types._drafts`).
_DecodedDraft = draft_class(Decoded)


def _cut(
    rows: npt.NDArray[np.uint8], nbytes: int, view: np.dtype[Any], names: tuple[str, ...]
) -> tuple[list[npt.NDArray[np.float32]], list[list[npt.NDArray[Any]]]]:
    """Each cloud's xyz and channels ``names`` from ``rows``, the (B, ``nbytes``) point bytes
    of B clouds in the reader's buffer, as strided views of copies (``view``: a plan's).

    The bytes are copied in groups of clouds of at most :data:`GROUP_BYTES` together: one or
    two numpy calls a group, a copy small enough to stay in the cache while it is cut, and a
    cloud kept pins its group's copy only, never the reader's chunk or map (the path for
    clouds that may not view their buffer: see :func:`views_buffer`).  A cloud larger
    than that is copied alone into its own ``bytes`` (immutable).  All by C-level iteration:
    no Python step a cloud.
    """
    group = GROUP_BYTES // nbytes
    if group <= 1:
        points = list(map(np.frombuffer, map(bytes, rows), repeat(view)))
        return (
            list(map(_field, points, repeat(_XYZ))),
            [list(map(_field, points, repeat(name))) for name in names],
        )
    xyz: list[npt.NDArray[np.float32]] = []
    values: list[list[npt.NDArray[Any]]] = [[] for _ in names]
    for lo in range(0, len(rows), group):
        block = rows[lo : lo + group].copy().view(view)
        block.flags.writeable = False
        # Iterating in C: one read-only (N, 3) view a cloud.  ``islice`` stops at the last
        # cloud: iterating an array to its end costs numpy a formatted IndexError (≈ 2,400
        # instructions, more than a cloud's view).
        count = len(block)
        xyz.extend(islice(block[_XYZ], count))
        for name, into in zip(names, values, strict=True):
            into.extend(islice(block[name], count))
    return xyz, values


def views_buffer(buf: bytes | memoryview, nbytes: int, *, each: int | None = None) -> bool:
    """True when clouds of ``nbytes`` point bytes (``each``: a cloud's; all of them when
    None) may view ``buf`` instead of a copy: it is immutable and private (a ``bytes``, or a
    view of one; never a file map), the clouds are at least :data:`VIEW_SHARE` of it, and one
    of them kept alone pins at most :data:`VIEW_MAX_BYTES` or 1 / :data:`VIEW_SHARE` times
    its own bytes."""
    owner = buf.obj if isinstance(buf, memoryview) else buf
    if type(owner) is not bytes:
        return False
    size = len(owner)
    return nbytes >= size * VIEW_SHARE and (
        size <= VIEW_MAX_BYTES or (nbytes if each is None else each) >= size * VIEW_SHARE
    )


def _view(
    buf: bytes | memoryview,
    at: tuple[int, int | None, npt.NDArray[np.int64] | None],
    count: int,
    n: int,
    plan: tuple[np.dtype[Any], tuple[str, ...]],
) -> tuple[list[npt.NDArray[np.float32]], list[list[npt.NDArray[Any]]]]:
    """Each of ``count`` clouds' xyz and channels as read-only strided views of ``buf``: ``n``
    points of the plan's view dtype at ``at`` (the first cloud's offset, the clouds' fixed
    distance or None when they are not at one, and then every message's start, to which the
    first cloud's offset from its message's start is added), by C-level iteration."""
    view, names = plan
    offset, stride, starts = at
    if stride is not None:
        # At a fixed distance: one (count, n) array over the buffer, a row a cloud.
        block = np.ndarray((count, n), view, buf, offset, (stride, view.itemsize))
        return (
            list(islice(block[_XYZ], count)),
            [list(islice(block[name], count)) for name in names],
        )
    assert starts is not None
    offsets = (starts + (offset - int(starts[0]))).tolist()
    points = list(map(np.frombuffer, repeat(buf), repeat(view), repeat(n), offsets))
    return (
        list(map(_field, points, repeat(_XYZ))),
        [list(map(_field, points, repeat(name))) for name in names],
    )


class BatchHeads:
    """The header of the last batch a decoder decoded (the bytes from the frame id to the
    point data, its message size, what they parse to), so that the next batch of the same
    sensor, whose first message has the same bytes there, is not parsed again.  Its parse
    depends on no other byte of that message (seq and stamp are read per message), so it is
    the same as parsing it."""

    __slots__ = ("head", "parsed", "size")

    def __init__(self) -> None:
        self.size = -1
        self.head = b""
        self.parsed: tuple[str, int, int, _FieldBlock, int, int, _Plan] | None = None


def decode_batch(
    batch: MessageBatch,
    *,
    read_head: Callable[[memoryview, str, LayoutCache], _Head],
    layouts: LayoutCache,
    plan_of: Callable[[_FieldBlock], _Plan],
    heads: BatchHeads | None = None,
) -> list[Decoded | None]:
    """What :meth:`~redrive.io.ros.decoders.pointcloud2.PointCloud2Decoder.decode` gives each
    message of ``batch`` (equal arrays), for the messages decoded together; None for those the
    caller must decode one by one.  ``read_head``, ``layouts`` and ``plan_of`` are the
    decoder's header parser, layout cache and plan lookup; ``heads`` its last batch header."""
    count = len(batch)
    out: list[Decoded | None] = [None] * count
    buf = batch.buffer
    if count < BATCH_FROM or batch.encoding != "ros1" or not buffer_is_immutable(buf):
        return out
    known = batch.stride  # the reader found them at a fixed distance, of one size
    first = int(batch.starts[0])
    size = int(batch.stops[0]) - first
    starts: npt.NDArray[np.int64] | None = None
    if known is None:
        starts = np.asarray(batch.starts, dtype=np.int64)
        if not (np.asarray(batch.stops, dtype=np.int64) - starts == size).all():
            return out
    parsed = _parse_first(memoryview(buf)[first : first + size], heads, read_head, layouts, plan_of)
    if parsed is None:
        return out
    frame_id, height, width, block, data_offset, data_size, plan = parsed
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
    # Each message's stamp and everything after it up to the point data, in one gather:
    # everything from the frame id on must be the first message's.
    width = data_offset - _STAMP_AT
    if known is not None:
        # At a fixed distance: every message's stamp and the bytes after it in one struct
        # unpack over the chunk (:func:`_heads_struct`), no array.
        found = _heads_struct(width, known, count).unpack_from(buf, first + _STAMP_AT)
        rest = found[2::3]
        if rest.count(rest[0]) != count:
            return out
        # sec · 10⁹ + nsec (Python ints: what the array's sums give); both slices are count
        # long (no strict=, see below)
        secs, nsecs = found[0::3], found[1::3]
        stamps_ns = [sec * 1_000_000_000 + nsec for sec, nsec in zip(secs, nsecs)]  # noqa: B905
    else:
        assert starts is not None
        head_rows = byte_rows(buf, starts + _STAMP_AT, width)
        same = head_rows[:, _SAME_FROM - _STAMP_AT :]
        # One comparison of bytes (a reduction over a small array costs more than the copies).
        if same.tobytes() != same[0].tobytes() * count:
            return out
        # sec · 10⁹ + nsec, exact in int64
        stamps_ns = (head_rows[:, : _SAME_FROM - _STAMP_AT].view(_U32) @ _SEC_NS).tolist()
    nbytes = n * step
    # At a fixed distance (a chunk of one topic), or between other topics' messages.
    if known is not None:
        stride, regular = known, known >= size
    else:
        assert starts is not None
        gaps = starts[1:] - starts[:-1]
        stride = size if count == 1 else int(gaps[0])
        regular = count == 1 or (stride >= size and (gaps == stride).all())
    if views_buffer(buf, count * nbytes, each=nbytes):
        # The clouds are most of a private chunk buffer: views of it, nothing copied.
        xyz, values = _view(
            buf,
            (first + data_offset, stride if regular else None, starts),
            count,
            n,
            (plan.view, plan.channels),
        )
    else:
        if regular:
            # The point bytes of every cloud as rows of one strided view of the chunk, each
            # row copied out below.
            rows: npt.NDArray[np.uint8] = np.ndarray(
                (count, nbytes), np.uint8, buf, first + data_offset, (stride, 1)
            )
        else:
            # Gathered row by row.
            assert starts is not None
            rows = byte_rows(buf, starts + data_offset, nbytes)
        xyz, values = _cut(rows, nbytes, plan.view, plan.channels)
    # values has one list a channel name, each list one array a cloud, clouds and stamps one
    # a message: equal lengths by construction (no strict=: its keyword parse costs ~1.5 k
    # instructions a zip, a chunk's decode makes three).
    channels = list(zip(plan.channels, values))  # noqa: B905
    # A zero stamp means "unset": the message's log time stands in for it.
    if 0 in stamps_ns:  # rare: no reduction over the stamps unless one is unset
        stamps = np.array(stamps_ns, dtype=np.int64)
        stamps_ns = np.where(stamps == 0, batch.log_times_ns, stamps).tolist()
    clouds = PointCloud.many_from_frozen(xyz, channels)
    # Every field of every Decoded set on a draft that then becomes it (what ``__init__`` does).
    decoded: list[Decoded | None] = []
    append = decoded.append
    for stamp_ns, cloud in zip(stamps_ns, clouds):  # noqa: B905
        item = _DecodedDraft()
        item.stamp_ns = stamp_ns
        item.frame_id = frame_id
        item.value = cloud
        item.__class__ = Decoded
        append(item)
    return decoded


@functools.lru_cache(maxsize=64)
def _heads_struct(width: int, stride: int, count: int) -> struct.Struct:
    """The ``struct`` that reads, of ``count`` messages ``stride`` bytes apart, each one's
    stamp (seconds, nanoseconds: two ``uint32``) and the ``width - 8`` bytes after it (the
    frame id up to the point data's length) as three items (the rest of each message is
    skipped)."""
    record = f"II{width - 8}s"
    return struct.Struct("<" + f"{record}{stride - width}x" * (count - 1) + record)


def _parse_first(
    view: memoryview,
    heads: BatchHeads | None,
    read_head: Callable[[memoryview, str, LayoutCache], _Head],
    layouts: LayoutCache,
    plan_of: Callable[[_FieldBlock], _Plan],
) -> tuple[str, int, int, _FieldBlock, int, int, _Plan] | None:
    """The first message's frame id, height, width, field block, data offset and size, and
    plan: ``heads``' when the message has its size and its bytes from the frame id to the
    point data, else parsed (and kept in ``heads``); None when it cannot be read."""
    size = len(view)
    if heads is not None and heads.size == size and heads.parsed is not None:
        end = heads.parsed[4]
        if bytes(view[_SAME_FROM:end]) == heads.head:
            return heads.parsed
    try:
        head = read_head(view, "ros1", layouts)
        plan = plan_of(head[5])
    except ValueError:
        return None
    _, _, frame_id, height, width, block, data_offset, data_size, _ = head
    parsed = (frame_id, height, width, block, data_offset, data_size, plan)
    if heads is not None:
        heads.size, heads.head, heads.parsed = size, bytes(view[_SAME_FROM:data_offset]), parsed
    return parsed
