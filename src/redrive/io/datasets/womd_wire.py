"""The bulk numbers of a Waymo Open Motion ``Scenario`` read straight from its protobuf bytes.

The protobuf runtime hands a ``Scenario``'s track states and map points out one Python object
and one attribute at a time (a scenario: some 8,000 states of ten numbers, 20,000 map points),
which costs more than decoding the whole record (:mod:`redrive.io.datasets.womd_wire_map`: the
roadgraph's lane numbers and the signals' lane states, alike).  The kernels here walk the record's wire format
(:mod:`redrive.io.datasets.womd_proto`'s field numbers) once, in compiled code, and give those
numbers as arrays — the same doubles the runtime gives (a ``double`` field's eight bytes, a
``float`` field's four widened exactly, an absent field its default 0, a field given twice its
last value, a message field given twice merged, as proto2 reads them).

Anything the walk does not expect (a known field of another wire type, a group, a length past
its message, a map feature with two of its ``feature_data`` fields, an enum number the schema
does not know — proto2 keeps it apart from the field) makes it give up, and the
reader takes the runtime's objects instead: the walk is a shortcut, never another reading.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["STATE_FIELDS", "map_polylines", "track_states"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: the columns of :func:`track_states`: ``ObjectState``'s fields 2 … 11 in number order
STATE_FIELDS = (
    "center_x",
    "center_y",
    "center_z",
    "length",
    "width",
    "height",
    "heading",
    "velocity_x",
    "velocity_y",
    "valid",
)
#: MapFeature's feature_data field → the field of its message that holds its points (lane:
#: LaneCenter.polyline, road_line / road_edge: polyline, crosswalk: polygon; 0: none read)
_POINTS_FIELD = np.zeros(11, dtype=np.int64)
_POINTS_FIELD[3], _POINTS_FIELD[4], _POINTS_FIELD[5], _POINTS_FIELD[8] = 8, 2, 2, 1


@numba.njit(cache=True, nogil=True)
def _varint(buf: npt.NDArray[np.uint8], pos: int, end: int) -> tuple[int, int]:
    """(value, position after it) of the varint at ``pos``; position -1 when it runs past
    ``end`` or is longer than ten bytes."""
    value = np.uint64(0)
    shift = np.uint64(0)
    for _ in range(10):
        if pos >= end:
            return 0, -1
        b = np.uint64(buf[pos])
        pos += 1
        value |= (b & np.uint64(0x7F)) << shift
        if b < np.uint64(0x80):
            return int(np.int64(value)), pos
        shift += np.uint64(7)
    return 0, -1


@numba.njit(cache=True, nogil=True)
def _skip(buf: npt.NDArray[np.uint8], pos: int, end: int, wire: int) -> int:
    """The position after a field of wire type ``wire`` whose value starts at ``pos``; -1 when
    it is a group or runs past ``end``."""
    if wire == 0:
        _, pos = _varint(buf, pos, end)
        return pos
    if wire == 1:
        return pos + 8 if pos + 8 <= end else -1
    if wire == 5:
        return pos + 4 if pos + 4 <= end else -1
    if wire == 2:
        n, pos = _varint(buf, pos, end)
        if pos < 0 or n < 0 or pos + n > end:
            return -1
        return pos + n
    return -1


@numba.njit(cache=True, nogil=True)
def _fixed(buf: npt.NDArray[np.uint8], pos: int, size: int) -> np.uint64:
    """The little-endian unsigned integer of ``size`` bytes at ``pos``."""
    out = np.uint64(0)
    for k in range(size - 1, -1, -1):
        out = (out << np.uint64(8)) | np.uint64(buf[pos + k])
    return out


@numba.njit(cache=True, nogil=True)
def _map_point(  # noqa: PLR0917  (compiled: numba takes no keyword-only arguments)
    buf: npt.NDArray[np.uint8],
    pos: int,
    end: int,
    row: F64,
    n_fields: int,
    bits: npt.NDArray[np.uint64],
) -> int:
    """A MapPoint's doubles from ``pos`` to ``end`` into ``row``: fields 1 … ``n_fields`` (x, y,
    z) as fixed64 doubles, the last of a repeated field winning, any other field skipped; the
    position after it, or -1 for anything unexpected.  ``bits`` is the caller's one-element
    uint64 scratch array (its float64 view gives the double)."""
    as_double = bits.view(np.float64)
    while pos < end:
        tag, pos = _varint(buf, pos, end)
        if pos < 0:
            return -1
        field, wire = tag >> 3, tag & 7
        if 1 <= field <= n_fields:
            if wire != 1 or pos + 8 > end:
                return -1
            bits[0] = _fixed(buf, pos, 8)
            row[field - 1] = as_double[0]
            pos += 8
        else:
            pos = _skip(buf, pos, end, wire)
            if pos < 0:
                return -1
    return pos


@numba.njit(cache=True, nogil=True)
def _grown_rows(a: F64) -> F64:
    out = np.zeros((2 * a.shape[0], a.shape[1]))
    out[: a.shape[0]] = a
    return out


@numba.njit(cache=True, nogil=True)
def _grown(a: I64) -> I64:
    out = np.zeros(2 * a.shape[0], dtype=np.int64)
    out[: a.shape[0]] = a
    return out


@numba.njit(cache=True, nogil=True)
def _states(buf: npt.NDArray[np.uint8]) -> tuple[F64, I64, bool]:
    rows = np.zeros((1024, 10))
    counts = np.zeros(128, dtype=np.int64)
    bits = np.zeros(1, dtype=np.uint64)
    as_double = bits.view(np.float64)
    bits32 = np.zeros(1, dtype=np.uint32)
    as_float = bits32.view(np.float32)
    n_tracks, n_states = 0, 0
    pos, end = 0, buf.shape[0]
    while pos < end:
        tag, pos = _varint(buf, pos, end)
        if pos < 0:
            return rows, counts, False
        field, wire = tag >> 3, tag & 7
        if field != 2:
            pos = _skip(buf, pos, end, wire)
            if pos < 0:
                return rows, counts, False
            continue
        if wire != 2:
            return rows, counts, False
        if n_tracks == counts.shape[0]:
            counts = _grown(counts)
        size, pos = _varint(buf, pos, end)
        if pos < 0 or size < 0 or pos + size > end:
            return rows, counts, False
        track_end = pos + size
        while pos < track_end:  # a Track
            tag, pos = _varint(buf, pos, track_end)
            if pos < 0:
                return rows, counts, False
            field, wire = tag >> 3, tag & 7
            if field != 3:
                pos = _skip(buf, pos, track_end, wire)
                if pos < 0:
                    return rows, counts, False
                continue
            if wire != 2:
                return rows, counts, False
            if n_states == rows.shape[0]:
                rows = _grown_rows(rows)
            size, pos = _varint(buf, pos, track_end)
            if pos < 0 or size < 0 or pos + size > track_end:
                return rows, counts, False
            state_end = pos + size
            while pos < state_end:  # an ObjectState
                tag, pos = _varint(buf, pos, state_end)
                if pos < 0:
                    return rows, counts, False
                field, wire = tag >> 3, tag & 7
                if 2 <= field <= 4:  # double
                    if wire != 1 or pos + 8 > state_end:
                        return rows, counts, False
                    bits[0] = _fixed(buf, pos, 8)
                    rows[n_states, field - 2] = as_double[0]
                    pos += 8
                elif 5 <= field <= 10:  # float
                    if wire != 5 or pos + 4 > state_end:
                        return rows, counts, False
                    bits32[0] = np.uint32(_fixed(buf, pos, 4))
                    rows[n_states, field - 2] = np.float64(as_float[0])
                    pos += 4
                elif field == 11:  # bool
                    if wire != 0:
                        return rows, counts, False
                    value, pos = _varint(buf, pos, state_end)
                    if pos < 0:
                        return rows, counts, False
                    rows[n_states, 9] = 1.0 if value != 0 else 0.0
                else:
                    pos = _skip(buf, pos, state_end, wire)
                    if pos < 0:
                        return rows, counts, False
            n_states += 1
            counts[n_tracks] += 1
        n_tracks += 1
    return rows[:n_states], counts[:n_tracks], True


def track_states(data: bytes) -> tuple[F64, I64] | None:
    """Every track's states of the ``Scenario`` ``data``: (S, 10) the :data:`STATE_FIELDS` of
    each state (``valid`` 1.0 or 0.0), tracks one after the other in order, and (T,) each
    track's number of states; None when the walk gives up (module text)."""
    rows, counts, ok = _states(np.frombuffer(data, dtype=np.uint8))
    return (np.ascontiguousarray(rows), counts) if ok else None


@numba.njit(cache=True, nogil=True)
def _polylines(buf: npt.NDArray[np.uint8], points_field: I64) -> tuple[F64, I64, bool]:
    xyz = np.zeros((4096, 3))
    offsets = np.zeros(512, dtype=np.int64)
    bits = np.zeros(1, dtype=np.uint64)
    n_features, n_points = 0, 0
    pos, end = 0, buf.shape[0]
    while pos < end:
        tag, pos = _varint(buf, pos, end)
        if pos < 0:
            return xyz, offsets, False
        field, wire = tag >> 3, tag & 7
        if field != 8:
            pos = _skip(buf, pos, end, wire)
            if pos < 0:
                return xyz, offsets, False
            continue
        if wire != 2:
            return xyz, offsets, False
        if n_features + 1 == offsets.shape[0]:
            offsets = _grown(offsets)
        size, pos = _varint(buf, pos, end)
        if pos < 0 or size < 0 or pos + size > end:
            return xyz, offsets, False
        feature_end = pos + size
        data_fields = 0
        while pos < feature_end:  # a MapFeature
            tag, pos = _varint(buf, pos, feature_end)
            if pos < 0:
                return xyz, offsets, False
            field, wire = tag >> 3, tag & 7
            if field in (3, 4, 5, 7, 8, 9, 10):  # feature_data (a oneof)
                data_fields += 1
                if wire != 2 or data_fields > 1:
                    return xyz, offsets, False
            wanted = points_field[field] if field < points_field.shape[0] else 0
            if wire != 2 or wanted == 0:
                pos = _skip(buf, pos, feature_end, wire)
                if pos < 0:
                    return xyz, offsets, False
                continue
            size, pos = _varint(buf, pos, feature_end)
            if pos < 0 or size < 0 or pos + size > feature_end:
                return xyz, offsets, False
            data_end = pos + size
            while pos < data_end:  # the feature's message
                tag, pos = _varint(buf, pos, data_end)
                if pos < 0:
                    return xyz, offsets, False
                field, wire = tag >> 3, tag & 7
                if field != wanted:
                    pos = _skip(buf, pos, data_end, wire)
                    if pos < 0:
                        return xyz, offsets, False
                    continue
                if wire != 2:
                    return xyz, offsets, False
                if n_points == xyz.shape[0]:
                    xyz = _grown_rows(xyz)
                size, pos = _varint(buf, pos, data_end)
                if pos < 0 or size < 0 or pos + size > data_end:
                    return xyz, offsets, False
                pos = _map_point(buf, pos, pos + size, xyz[n_points], 3, bits)
                if pos < 0:
                    return xyz, offsets, False
                n_points += 1
        n_features += 1
        offsets[n_features] = n_points
    return xyz[:n_points], offsets[: n_features + 1], True


def map_polylines(data: bytes) -> tuple[F64, I64] | None:
    """The points of each map feature of the ``Scenario`` ``data``: (P, 2) x, y and (F + 1,)
    offsets — feature ``k``'s (in ``map_features`` order) are ``xy[offsets[k]:offsets[k + 1]]``:
    a lane's ``polyline``, a road line's or edge's ``polyline``, a crosswalk's ``polygon``, none
    for the other kinds; None when the walk gives up."""
    xyz, offsets, ok = _polylines(np.frombuffer(data, dtype=np.uint8), _POINTS_FIELD)
    return (np.ascontiguousarray(xyz[:, :2]), offsets) if ok else None
