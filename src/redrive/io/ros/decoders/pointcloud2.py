"""``sensor_msgs/msg/PointCloud2`` → :class:`~redrive.types.PointCloud`, without deserialising.

The fast path reads only the small message header (stamp, frame, shape, fields, flags) straight
from the serialised bytes — ROS 1, or ROS 2 CDR in either byte order — builds a numpy structured
dtype from the ``PointField`` list and views the point data in place:

* when x, y, z are adjacent native float32 (what drivers publish), ``xyz`` and every channel
  are read-only strided views of the point bytes: of the immutable ``bytes`` the message lies
  in when its points are at least half of them (its own ``bytes``, or a reader's private chunk
  it fills: nothing copied, the cloud pins at most twice its point bytes; the arrays may then
  be unaligned), else of one copy of its point bytes (a view into a file map, a reusable
  buffer or a chunk mostly of other messages is never kept);
* any other layout: ``xyz`` is copied once into a float32 (N, 3) C-contiguous array (float64 or
  integer x/y/z are cast) and the channels view the message's ``bytes`` or a copy as above;
* ``is_bigendian`` clouds are byte-swapped to native order (channels are then copies);
* nothing is dropped: N = width × height whatever ``is_dense`` says, NaN points stay NaN;
* a field with ``count`` k > 1 becomes k channels ``name_0`` … ``name_{k-1}``; ``count`` 0 is read
  as 1 (some drivers write 0 for scalars).
"""

from __future__ import annotations

import functools
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.io.base import LogMessage
from redrive.io.ros.decoders._common import unsupported
from redrive.io.ros.decoders.base import Decoded, DecodedKind, Deserialize
from redrive.io.ros.decoders.pointcloud2_batch import BatchHeads, decode_batch, views_buffer
from redrive.types import PointCloud, SensorType

__all__ = [
    "CloudField",
    "CloudLayout",
    "LayoutCache",
    "PointCloud2Decoder",
    "read_cloud_layout",
]

#: PointField datatype constant → numpy type code (without byte order).
POINTFIELD_DTYPES: dict[int, str] = {
    1: "i1",  # INT8
    2: "u1",  # UINT8
    3: "i2",  # INT16
    4: "u2",  # UINT16
    5: "i4",  # INT32
    6: "u4",  # UINT32
    7: "f4",  # FLOAT32
    8: "f8",  # FLOAT64
}


@dataclass(frozen=True, slots=True)
class CloudField:
    """One ``sensor_msgs/PointField``: name, byte offset in the point, datatype, count."""

    name: str
    offset: int
    datatype: int
    count: int


@dataclass(frozen=True, slots=True, kw_only=True)
class CloudLayout:
    """The header of a serialised PointCloud2 and where its point bytes lie.

    Attributes:
        stamp_ns: header stamp, int ns (0 when unset).
        data_offset, data_size_bytes: the ``data`` array inside the serialised message.
    """

    stamp_ns: int
    frame_id: str
    height: int
    width: int
    fields: tuple[CloudField, ...]
    is_bigendian: bool
    point_step: int
    row_step: int
    data_offset: int
    data_size_bytes: int
    is_dense: bool


class _Cursor:
    """Reads primitives from serialised bytes; CDR aligns relative to after the 4-byte header."""

    __slots__ = ("buf", "cdr", "order", "pos", "u32")

    def __init__(self, buf: memoryview, *, cdr: bool, big_endian: bool) -> None:
        self.buf = buf
        self.cdr = cdr
        self.order = ">" if big_endian else "<"
        self.u32 = struct.Struct(self.order + "I")
        self.pos = 4 if cdr else 0

    def _align(self, size: int) -> None:
        if self.cdr:
            rel = self.pos - 4
            self.pos += -rel % size

    def uint32(self) -> int:
        self._align(4)
        (value,) = self.u32.unpack_from(self.buf, self.pos)
        self.pos += 4
        return int(value)

    def uint8(self) -> int:
        value = self.buf[self.pos]
        self.pos += 1
        return int(value)

    def string(self) -> str:
        size = self.uint32()
        end = self.pos + size
        if end > len(self.buf):
            raise IndexError(end)
        text = bytes(self.buf[self.pos : end])
        self.pos = end
        if self.cdr and text.endswith(b"\x00"):
            text = text[:-1]
        return text.decode("utf-8", errors="replace")


_ROS1_HEAD = struct.Struct("<IIII")  # seq, sec, nanosec, frame_id length
_CDR_HEAD = {False: struct.Struct("<iII"), True: struct.Struct(">iII")}  # sec, nanosec, len
_U32 = {False: struct.Struct("<I"), True: struct.Struct(">I")}
_U32_PAIR = {False: struct.Struct("<II"), True: struct.Struct(">II")}


@dataclass(frozen=True, slots=True)
class _FieldBlock:
    """The bytes from ``fields`` to ``row_step`` of one cloud, and what they parse to."""

    raw: bytes
    fields: tuple[CloudField, ...]
    is_bigendian: bool
    point_step: int
    row_step: int


class LayoutCache:
    """Remembers the field blocks of recent clouds so a stream of clouds is parsed once.

    A sensor publishes the same ``fields`` / ``is_bigendian`` / ``point_step`` / ``row_step`` in
    every message; on a hit only the stamp, frame, shape and data length are read.  The block is
    compared byte for byte, so a changed layout is never missed.  At most ``size`` blocks are kept.
    """

    __slots__ = ("blocks", "size")

    def __init__(self, size: int = 8) -> None:
        self.size = size
        self.blocks: list[_FieldBlock] = []

    def find(self, buf: memoryview, pos: int) -> _FieldBlock | None:
        for block in self.blocks:
            if buf[pos : pos + len(block.raw)] == block.raw:
                return block
        return None

    def add(self, block: _FieldBlock) -> None:
        self.blocks.insert(0, block)
        del self.blocks[self.size :]


#: What :func:`_read_head` finds: the buffer, stamp (ns), frame, height, width, field block,
#: data offset, data size, is_dense.
_Head = tuple[memoryview, int, str, int, int, _FieldBlock, int, int, bool]


def read_cloud_layout(
    raw: bytes | memoryview, encoding: str, *, cache: LayoutCache | None = None
) -> CloudLayout:
    """Parse the header of a serialised PointCloud2 (``encoding`` ``ros1`` or ``cdr``).

    ``cache`` (optional) skips parsing the field list when it is the same as a recent cloud's.

    Raises:
        ValueError: the bytes are truncated or use an unsupported CDR representation.
    """
    _, stamp_ns, frame_id, height, width, block, data_offset, data_size, is_dense = _read_head(
        raw, encoding, cache
    )
    return CloudLayout(
        stamp_ns=stamp_ns,
        frame_id=frame_id,
        height=height,
        width=width,
        fields=block.fields,
        is_bigendian=block.is_bigendian,
        point_step=block.point_step,
        row_step=block.row_step,
        data_offset=data_offset,
        data_size_bytes=data_size,
        is_dense=is_dense,
    )


def _read_head(raw: bytes | memoryview, encoding: str, cache: LayoutCache | None) -> _Head:
    """:func:`read_cloud_layout` as a plain tuple: it runs once per message, so no object is
    built on the way (the decoder reads the fields it needs straight from it)."""
    buf = memoryview(raw).cast("B")
    try:
        if encoding == "ros1":
            big = False
            _seq, sec, nanosec, size = _ROS1_HEAD.unpack_from(buf, 0)
            frame_id = str(buf[16 : 16 + size], "utf-8", "replace")
            pos = 16 + size
            cdr = False
        elif encoding == "cdr":
            if len(buf) < 4 or buf[0] != 0 or buf[1] not in (0, 1):
                head = bytes(buf[:4]).hex()
                msg = f"CDR encapsulation header {head!r} is not plain CDR (00 00 / 00 01)"
                raise ValueError(msg)
            cdr, big = True, buf[1] == 0
            sec, nanosec, size = _CDR_HEAD[big].unpack_from(buf, 4)
            text = bytes(buf[16 : 16 + size]).rstrip(b"\x00")
            frame_id = text.decode("utf-8", errors="replace")
            pos = 16 + size
            pos += -(pos - 4) % 4
        else:
            msg = f"encoding {encoding!r} is not ros1 or cdr"
            raise ValueError(msg)
        if pos > len(buf):
            raise IndexError(pos)
        height, width = _U32_PAIR[big].unpack_from(buf, pos)
        pos += 8
        block = cache.find(buf, pos) if cache is not None else None
        if block is None:
            block = _parse_field_block(buf, pos, cdr=cdr, big_endian=big)
            if cache is not None:
                cache.add(block)
        pos += len(block.raw)
        (data_size,) = _U32[big].unpack_from(buf, pos)
        data_offset = pos + 4
        dense_at = data_offset + data_size
        is_dense = buf[dense_at] != 0 if dense_at < len(buf) else False
    except (struct.error, IndexError) as err:
        msg = f"serialised PointCloud2 is truncated ({len(buf)} bytes)"
        raise ValueError(msg) from err
    if data_offset + data_size > len(buf):
        msg = f"data array of {data_size} bytes overruns the {len(buf)}-byte message"
        raise ValueError(msg)
    stamp_ns = sec * 1_000_000_000 + nanosec
    return buf, stamp_ns, frame_id, height, width, block, data_offset, data_size, is_dense


def _parse_field_block(buf: memoryview, pos: int, *, cdr: bool, big_endian: bool) -> _FieldBlock:
    """Parse ``fields`` … ``row_step`` starting at ``pos`` (4-aligned for CDR)."""
    cur = _Cursor(buf, cdr=cdr, big_endian=big_endian)
    cur.pos = pos
    fields = []
    for _ in range(cur.uint32()):
        name = cur.string()
        offset = cur.uint32()
        datatype = cur.uint8()
        count = cur.uint32()
        fields.append(CloudField(name, offset, datatype, count))
    is_bigendian = cur.uint8() != 0
    point_step = cur.uint32()
    row_step = cur.uint32()
    return _FieldBlock(
        raw=bytes(buf[pos : cur.pos]),
        fields=tuple(fields),
        is_bigendian=is_bigendian,
        point_step=point_step,
        row_step=row_step,
    )


@functools.lru_cache(maxsize=64)
def _cached_point_dtype(
    fields: tuple[CloudField, ...], is_bigendian: bool, point_step: int
) -> np.dtype[Any]:
    order = ">" if is_bigendian else "<"
    names: list[str] = []
    formats: list[str] = []
    offsets: list[int] = []
    for field in fields:
        code = POINTFIELD_DTYPES.get(field.datatype)
        if code is None:
            msg = f"field {field.name!r} has unknown PointField datatype {field.datatype}"
            raise ValueError(msg)
        count = max(field.count, 1)
        size = int(code[1])
        if field.offset + size * count > point_step:
            msg = (
                f"field {field.name!r} (offset {field.offset}, {count} × {code}) does not fit "
                f"in point_step {point_step}"
            )
            raise ValueError(msg)
        if count > 1 and field.name in ("x", "y", "z"):
            msg = f"coordinate field {field.name!r} has count {count}; it must be a scalar"
            raise ValueError(msg)
        sub = [field.name] if count == 1 else [f"{field.name}_{i}" for i in range(count)]
        for i, name in enumerate(sub):
            if not name or name in names:
                msg = f"field name {name!r} is empty or repeated"
                raise ValueError(msg)
            names.append(name)
            formats.append(order + code)
            offsets.append(field.offset + i * size)
    return np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step}
    )


def _points_view(
    buf: bytes | memoryview, layout: CloudLayout, dtype: np.dtype[Any], data_offset: int
) -> npt.NDArray[Any]:
    """The points as a flat structured array; a view unless rows carry padding."""
    n = layout.width * layout.height
    if n == 0:
        return np.zeros(0, dtype=dtype)
    row_bytes = layout.width * layout.point_step
    if layout.row_step < row_bytes and layout.height > 1:
        msg = f"row_step {layout.row_step} is smaller than width × point_step = {row_bytes}"
        raise ValueError(msg)
    needed = layout.row_step * (layout.height - 1) + row_bytes
    if layout.data_size_bytes < needed:
        msg = (
            f"data holds {layout.data_size_bytes} bytes, but {layout.height} × {layout.width} "
            f"points of {layout.point_step} bytes (row_step {layout.row_step}) need {needed}"
        )
        raise ValueError(msg)
    if layout.height == 1 or layout.row_step == row_bytes:
        return np.ndarray(
            shape=(n,), dtype=dtype, buffer=buf, offset=data_offset, strides=(layout.point_step,)
        )
    grid = np.ndarray(
        shape=(layout.height, layout.width),
        dtype=dtype,
        buffer=buf,
        offset=data_offset,
        strides=(layout.row_step, layout.point_step),
    )
    return grid.reshape(n)  # padded rows: one copy


def _xyz(points: npt.NDArray[Any], dtype: np.dtype[Any]) -> npt.NDArray[np.float32]:
    """x, y, z copied once into a float32 (N, 3) C-contiguous array (cast when not float32)."""
    packed = _packed_xyz(dtype)
    if packed is not None:
        # Copy the 12 bytes as opaque records (a plain memcpy each, fast even when unaligned),
        # then reinterpret them as three native float32.
        records = points.view(packed)["xyz"].copy()
        xyz: npt.NDArray[np.float32] = records.view(np.float32).reshape(points.shape[0], 3)
    else:
        xyz = np.empty((points.shape[0], 3), dtype=np.float32)
        with np.errstate(over="ignore", invalid="ignore"):
            for i, axis in enumerate("xyz"):
                xyz[:, i] = points[axis]
    xyz.flags.writeable = False  # PointCloud takes it as it is
    return xyz


@functools.lru_cache(maxsize=64)
def _packed_xyz(dtype: np.dtype[Any]) -> np.dtype[Any] | None:
    """A one-member ``V12`` dtype over x, y, z when they are adjacent native float32, else None."""
    fields = dtype.fields
    assert fields is not None
    (tx, ox), (ty, oy), (tz, oz) = ((fields[a][0], int(fields[a][1])) for a in "xyz")
    if not (tx == ty == tz == np.dtype(np.float32) and oy == ox + 4 and oz == ox + 8):
        return None
    return np.dtype(
        {"names": ["xyz"], "formats": ["V12"], "offsets": [ox], "itemsize": dtype.itemsize}
    )


_F32 = np.dtype(np.float32)


#: The member of a plan's view dtype that holds x, y, z as a float32 (3,) subarray: the field
#: of a point array is then the (N, 3) strided xyz itself.
_XYZ = "xyz"
_XYZ_MEMBER = np.dtype((np.float32, (3,)))


@dataclass(frozen=True, slots=True)
class _Plan:
    """How the points of one field block are cut into xyz and channels.

    Attributes:
        block: the cached field block this plan is for (kept so its id is not reused).
        dtype: the structured point dtype (the general path's).
        missing: coordinate fields the layout lacks (empty when it has x, y and z).
        view: for the fast path, a dtype of itemsize ``point_step`` with x, y, z as one
            float32 (3,) member ``xyz`` and every other member as it is; None when the general
            path must be taken (a member not in native byte order, x/y/z not adjacent float32,
            a channel called ``xyz``).
        channels: the names of the other members, in order.
        xyz_offset: the byte offset of x in a point.
    """

    block: _FieldBlock
    dtype: np.dtype[Any]
    missing: tuple[str, ...]
    view: np.dtype[Any] | None
    channels: tuple[str, ...]
    xyz_offset: int


def _make_plan(block: _FieldBlock) -> _Plan:
    dtype = _cached_point_dtype(block.fields, block.is_bigendian, block.point_step)
    members = dtype.fields
    assert members is not None
    missing = tuple(a for a in "xyz" if a not in members)
    channels = tuple(name for name in dtype.names or () if name not in ("x", "y", "z"))
    view: np.dtype[Any] | None = None
    fast = (
        not missing
        and _XYZ not in channels
        and all(member[0].isnative for member in members.values())
        and _packed_xyz(dtype) is not None
    )
    if fast:
        view = np.dtype(
            {
                "names": [_XYZ, *channels],
                "formats": [_XYZ_MEMBER, *(members[name][0] for name in channels)],
                "offsets": [members["x"][1], *(members[name][1] for name in channels)],
                "itemsize": dtype.itemsize,
            }
        )
    xyz_offset = int(members["x"][1]) if not missing else 0
    return _Plan(block, dtype, missing, view, channels, xyz_offset)


class PointCloud2Decoder:
    """``sensor_msgs/msg/PointCloud2`` → PointCloud (any field layout, both encodings).

    Every message pays only for its header (the field list is cached, see :class:`LayoutCache`),
    at most one copy of its point bytes and one strided view for xyz and each channel: a cloud
    whose members are in native byte order, whose x, y, z are adjacent float32 and whose rows
    carry no padding (what drivers publish) is cut that way; any other layout takes the general
    path through a structured view of the points, with xyz copied C-contiguous.  Both give equal
    values.
    """

    name = "pointcloud2"
    msgtypes: tuple[str, ...] = ("sensor_msgs/msg/PointCloud2",)
    kind = DecodedKind.SENSOR
    sensor_type: SensorType | None = SensorType.LIDAR

    def __init__(self) -> None:
        self._layouts = LayoutCache()
        # id(cached field block) → its plan; the plan keeps the block so its id cannot be
        # reused.  Hashing the field list per message costs more than the lookup.
        self._plans: dict[int, _Plan] = {}
        self._batch_heads = BatchHeads()

    def _plan(self, block: _FieldBlock) -> _Plan:
        plan = self._plans.get(id(block))
        if plan is not None and plan.block is block:
            return plan
        plan = _make_plan(block)
        if len(self._plans) > 64:
            self._plans.clear()
        self._plans[id(block)] = plan
        return plan

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        del deserialize  # the fast path never deserialises
        if message.batch is not None:
            # Read with others (a ROS 1 chunk's clouds): decode them all at the first one.
            batch, index = message.batch
            done = batch.memo.get(self)
            if done is None:
                done = decode_batch(
                    batch,
                    read_head=_read_head,
                    layouts=self._layouts,
                    plan_of=self._plan,
                    heads=self._batch_heads,
                )
                batch.memo[self] = done
            found = done[index]
            if found is not None:
                return found
        raw = message.raw
        try:
            head = _read_head(raw, message.encoding, self._layouts)
            plan = self._plan(head[5])
        except ValueError as err:
            raise unsupported(message, f"PointCloud2 cannot be read: {err}", _WHAT_TO_DO) from err
        _, stamp_ns, frame_id, height, width, block, data_offset, data_size, is_dense = head
        if plan.missing:
            have = ", ".join(f.name for f in block.fields) or "none"
            raise unsupported(
                message,
                f"PointCloud2 has no {'/'.join(plan.missing)} field (fields: {have})",
                "redrive needs x, y, z; decode this topic with a custom decoder or skip it",
            )
        stamp_ns = stamp_ns or message.log_time_ns
        n = width * height
        step = block.point_step
        view = plan.view
        if (
            view is not None
            and n > 0
            and (height == 1 or block.row_step == width * step)
            and data_size >= n * step
        ):
            # The fast path: one view of the points, no layout object (see the class docstring).
            if views_buffer(raw, n * step):
                # Most of immutable bytes (the message's own, or a reader's private chunk it
                # fills): viewed as they are (the cloud pins them).
                points = np.ndarray((n,), view, raw, data_offset)
            else:
                # A small part of a reader's chunk, or a map or buffer: the points copied once.
                own = bytes(head[0][data_offset : data_offset + n * step])
                points = np.ndarray((n,), view, own)
            channels = {name: points[name] for name in plan.channels}
            # The arrays are what PointCloud's checks would make of them (read-only strided
            # views of immutable bytes, shapes (N, 3) and (N,)), so they are not checked again.
            cloud = PointCloud.from_frozen(points[_XYZ], channels)
            return Decoded(stamp_ns=stamp_ns, frame_id=frame_id, value=cloud)
        layout = CloudLayout(
            stamp_ns=stamp_ns,
            frame_id=frame_id,
            height=height,
            width=width,
            fields=block.fields,
            is_bigendian=block.is_bigendian,
            point_step=step,
            row_step=block.row_step,
            data_offset=data_offset,
            data_size_bytes=data_size,
            is_dense=is_dense,
        )
        return Decoded(
            stamp_ns=stamp_ns, frame_id=frame_id, value=self._general(message, layout, plan.dtype)
        )

    @staticmethod
    def _general(message: LogMessage, layout: CloudLayout, dtype: np.dtype[Any]) -> PointCloud:
        """Any layout: a structured view of the points (their bytes copied first unless the
        message is its own ``bytes``: a reader's buffer may change, a chunk must not be pinned)."""
        buf: bytes | memoryview = message.raw
        data_offset = layout.data_offset
        if type(buf) is not bytes:
            end = data_offset + layout.data_size_bytes
            buf = bytes(memoryview(message.raw).cast("B")[data_offset:end])
            data_offset = 0
        try:
            points = _points_view(buf, layout, dtype, data_offset)
        except ValueError as err:
            raise unsupported(message, f"PointCloud2 cannot be read: {err}", _WHAT_TO_DO) from err
        xyz = _xyz(points, dtype)
        channels: dict[str, npt.NDArray[Any]] = {}
        for name in dtype.names or ():
            if name in ("x", "y", "z"):
                continue
            values = points[name]
            if not values.dtype.isnative:
                values = values.astype(values.dtype.newbyteorder("="))
            channels[name] = values
        return PointCloud(xyz=xyz, channels=channels)


_WHAT_TO_DO = "check the publisher's PointField list, or report the bag to the redrive developers"
