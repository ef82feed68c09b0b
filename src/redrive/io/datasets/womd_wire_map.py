"""The roadgraph's lane numbers and the traffic signals' lane states of a Waymo Open Motion
``Scenario``, read straight from its protobuf bytes.

A scenario's ~200 lanes hold some 2,000 numbers the map reads (speed limits, types, entry and
exit lanes, neighbours, boundary segments) and its 91 steps ~1,100 signal lane states; the
protobuf runtime hands them out one object and one attribute at a time.  The kernels here walk
the record as :mod:`redrive.io.datasets.womd_wire` does (its primitives, its rules: the
runtime's values — a field given twice its last value, a message given twice merged, a
repeated scalar packed or not — and anything unexpected makes the walk give up, the reader then
taking the runtime's objects).  Closed enums and ``int32`` fields are taken only in their
schema's range: proto2 keeps an unknown enum number apart from its field, and the runtime cuts
an ``int32`` to 32 bits.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from redrive.io.datasets.womd_wire import _fixed, _grown_rows, _map_point, _skip, _varint

__all__ = [
    "ENTRY",
    "EXIT",
    "LANE_STATE_COUNT",
    "LEFT_NEIGHBOR",
    "RIGHT_NEIGHBOR",
    "LaneStates",
    "MapLanes",
    "lane_states",
    "map_lanes",
]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: TrafficSignalLaneState.State's values are 0 … LANE_STATE_COUNT - 1 (womd_proto's enum)
LANE_STATE_COUNT = 9


@numba.njit(cache=True, nogil=True)
def _lane_states(buf: npt.NDArray[np.uint8]) -> tuple[I64, F64, bool]:
    # per lane state: (step, lane, state, has stop point) and its stop point's (x, y)
    ints = np.zeros((256, 4), dtype=np.int64)
    xy = np.zeros((256, 2))
    bits = np.zeros(1, dtype=np.uint64)
    n_steps, n = 0, 0
    pos, end = 0, buf.shape[0]
    while pos < end:
        tag, pos = _varint(buf, pos, end)
        if pos < 0:
            return ints, xy, False
        field, wire = tag >> 3, tag & 7
        if field != 7:
            pos = _skip(buf, pos, end, wire)
            if pos < 0:
                return ints, xy, False
            continue
        if wire != 2:
            return ints, xy, False
        size, pos = _varint(buf, pos, end)
        if pos < 0 or size < 0 or pos + size > end:
            return ints, xy, False
        step_end = pos + size
        while pos < step_end:  # a DynamicMapState
            tag, pos = _varint(buf, pos, step_end)
            if pos < 0:
                return ints, xy, False
            field, wire = tag >> 3, tag & 7
            if field != 1:
                pos = _skip(buf, pos, step_end, wire)
                if pos < 0:
                    return ints, xy, False
                continue
            if wire != 2:
                return ints, xy, False
            if n == ints.shape[0]:
                grown = np.zeros((2 * n, 4), dtype=np.int64)
                grown[:n] = ints
                ints = grown
                xy = _grown_rows(xy)
            size, pos = _varint(buf, pos, step_end)
            if pos < 0 or size < 0 or pos + size > step_end:
                return ints, xy, False
            state_end = pos + size
            ints[n, 0] = n_steps
            while pos < state_end:  # a TrafficSignalLaneState
                tag, pos = _varint(buf, pos, state_end)
                if pos < 0:
                    return ints, xy, False
                field, wire = tag >> 3, tag & 7
                if 1 <= field <= 2:  # lane (int64), state (enum)
                    if wire != 0:
                        return ints, xy, False
                    value, pos = _varint(buf, pos, state_end)
                    if pos < 0:
                        return ints, xy, False
                    if field == 2 and not 0 <= value < 9:
                        return ints, xy, False  # proto2 keeps an unknown enum value apart
                    ints[n, field] = value
                elif field == 3:  # stop_point (MapPoint; a second one merges into the first)
                    if wire != 2:
                        return ints, xy, False
                    size, pos = _varint(buf, pos, state_end)
                    if pos < 0 or size < 0 or pos + size > state_end:
                        return ints, xy, False
                    ints[n, 3] = 1
                    pos = _map_point(buf, pos, pos + size, xy[n], 2, bits)  # x, y: z skipped
                    if pos < 0:
                        return ints, xy, False
                else:
                    pos = _skip(buf, pos, state_end, wire)
                    if pos < 0:
                        return ints, xy, False
            n += 1
        n_steps += 1
    out = np.zeros((n, 4), dtype=np.int64)
    out[:, :] = ints[:n]
    out_xy = np.zeros((n, 2))
    out_xy[:, :] = xy[:n]
    # the number of steps rides in a last row (a step may hold no lane state)
    return np.concatenate((out, np.array([[n_steps, 0, 0, 0]], dtype=np.int64))), out_xy, True


#: every lane state of a Scenario's ``dynamic_map_states``: (S,) its step, lane id and state
#: number, whether it has a stop point, its stop point (S, 2) x, y; and the number of steps
LaneStates = tuple[I64, I64, I64, npt.NDArray[np.bool_], F64, int]


def lane_states(data: bytes) -> LaneStates | None:
    """The lane states of the ``Scenario`` ``data``'s ``dynamic_map_states``, step by step in
    order (:data:`LaneStates`); None when the walk gives up (module text; also a state number
    the schema does not know, which proto2 keeps apart from the field)."""
    ints, xy, ok = _lane_states(np.frombuffer(data, dtype=np.uint8))
    if not ok:
        return None
    rows, steps = ints[:-1], int(ints[-1, 0])
    return (
        np.ascontiguousarray(rows[:, 0]),
        np.ascontiguousarray(rows[:, 1]),
        np.ascontiguousarray(rows[:, 2]),
        rows[:, 3] > 0,
        xy,
        steps,
    )


#: LaneCenter.LaneType's values are 0 … 3, RoadLine.RoadLineType's 0 … 8 (womd_proto's enums)
_LANE_TYPES, _LINE_TYPES = 4, 9
#: :func:`map_lanes`' list codes: a lane's entry_lanes, exit_lanes, left and right neighbours'
#: feature ids
ENTRY, EXIT, LEFT_NEIGHBOR, RIGHT_NEIGHBOR = 0, 1, 2, 3


@numba.njit(cache=True, nogil=True)
def _grown_ints(a: I64) -> I64:
    out = np.zeros((2 * a.shape[0], a.shape[1]), dtype=np.int64)
    out[: a.shape[0]] = a
    return out


@numba.njit(cache=True, nogil=True)
def _signed32(value: int) -> bool:
    return -(2**31) <= value < 2**31


@numba.njit(cache=True, nogil=True)
def _lanes(buf: npt.NDArray[np.uint8]) -> tuple[I64, F64, I64, I64, bool]:
    # per feature: (id, feature_data field number or 0, lane type, lane interpolating) and its
    # lane's speed_limit_mph; per id of a lane's lists: (feature, list code, id); per boundary
    # segment: (feature, side 0 left / 1 right, start, end, boundary feature id, type)
    feats = np.zeros((512, 4), dtype=np.int64)
    speeds = np.zeros(512)
    ids = np.zeros((1024, 3), dtype=np.int64)
    segs = np.zeros((1024, 6), dtype=np.int64)
    bits = np.zeros(1, dtype=np.uint64)
    as_double = bits.view(np.float64)
    n_feat, n_ids, n_segs = 0, 0, 0
    pos, end = 0, buf.shape[0]
    while pos < end:
        tag, pos = _varint(buf, pos, end)
        if pos < 0:
            return feats, speeds, ids, segs, False
        field, wire = tag >> 3, tag & 7
        if field != 8:
            pos = _skip(buf, pos, end, wire)
            if pos < 0:
                return feats, speeds, ids, segs, False
            continue
        if wire != 2:
            return feats, speeds, ids, segs, False
        if n_feat == feats.shape[0]:
            feats = _grown_ints(feats)
            grown = np.zeros(2 * n_feat)
            grown[:n_feat] = speeds
            speeds = grown
        size, pos = _varint(buf, pos, end)
        if pos < 0 or size < 0 or pos + size > end:
            return feats, speeds, ids, segs, False
        feature_end = pos + size
        k = n_feat
        n_feat += 1
        while pos < feature_end:  # a MapFeature
            tag, pos = _varint(buf, pos, feature_end)
            if pos < 0:
                return feats, speeds, ids, segs, False
            field, wire = tag >> 3, tag & 7
            if field == 1:  # id
                if wire != 0:
                    return feats, speeds, ids, segs, False
                value, pos = _varint(buf, pos, feature_end)
                if pos < 0:
                    return feats, speeds, ids, segs, False
                feats[k, 0] = value
                continue
            if field in (3, 4, 5, 7, 8, 9, 10):  # feature_data (a oneof): one, once
                if wire != 2 or feats[k, 1] != 0:
                    return feats, speeds, ids, segs, False
                feats[k, 1] = field
            if field != 3:
                pos = _skip(buf, pos, feature_end, wire)
                if pos < 0:
                    return feats, speeds, ids, segs, False
                continue
            size, pos = _varint(buf, pos, feature_end)
            if pos < 0 or size < 0 or pos + size > feature_end:
                return feats, speeds, ids, segs, False
            lane_end = pos + size
            while pos < lane_end:  # a LaneCenter
                tag, pos = _varint(buf, pos, lane_end)
                if pos < 0:
                    return feats, speeds, ids, segs, False
                field, wire = tag >> 3, tag & 7
                if field == 1:  # speed_limit_mph (double)
                    if wire != 1 or pos + 8 > lane_end:
                        return feats, speeds, ids, segs, False
                    bits[0] = _fixed(buf, pos, 8)
                    speeds[k] = as_double[0]
                    pos += 8
                elif 2 <= field <= 3:  # type (enum), interpolating (bool)
                    if wire != 0:
                        return feats, speeds, ids, segs, False
                    value, pos = _varint(buf, pos, lane_end)
                    if pos < 0 or (field == 2 and not 0 <= value < _LANE_TYPES):
                        return feats, speeds, ids, segs, False  # (an unknown enum: the runtime)
                    feats[k, field] = value if field == 2 else (1 if value != 0 else 0)
                elif 9 <= field <= 10:  # entry_lanes, exit_lanes (int64, packed or not)
                    code = field - 9
                    if wire == 0:
                        stop = pos + 1  # one value
                        packed_end = lane_end
                    elif wire == 2:
                        size, pos = _varint(buf, pos, lane_end)
                        if pos < 0 or size < 0 or pos + size > lane_end:
                            return feats, speeds, ids, segs, False
                        packed_end = pos + size
                        stop = packed_end
                    else:
                        return feats, speeds, ids, segs, False
                    while pos < stop:
                        value, pos = _varint(buf, pos, packed_end)
                        if pos < 0:
                            return feats, speeds, ids, segs, False
                        if n_ids == ids.shape[0]:
                            ids = _grown_ints(ids)
                        ids[n_ids, 0], ids[n_ids, 1], ids[n_ids, 2] = k, code, value
                        n_ids += 1
                        if wire == 0:
                            break
                elif 11 <= field <= 14:  # neighbours, boundaries (messages)
                    if wire != 2:
                        return feats, speeds, ids, segs, False
                    size, pos = _varint(buf, pos, lane_end)
                    if pos < 0 or size < 0 or pos + size > lane_end:
                        return feats, speeds, ids, segs, False
                    message_end = pos + size
                    row = np.zeros(4, dtype=np.int64)  # neighbour: [id]; segment: 4 fields
                    while pos < message_end:
                        tag, pos = _varint(buf, pos, message_end)
                        if pos < 0:
                            return feats, speeds, ids, segs, False
                        sub, sub_wire = tag >> 3, tag & 7
                        wanted = 1 if field <= 12 else 4  # LaneNeighbor.feature_id / all four
                        if 1 <= sub <= wanted:
                            if sub_wire != 0:
                                return feats, speeds, ids, segs, False
                            value, pos = _varint(buf, pos, message_end)
                            if pos < 0:
                                return feats, speeds, ids, segs, False
                            if field >= 13 and sub <= 2 and not _signed32(value):
                                return feats, speeds, ids, segs, False
                            if field >= 13 and sub == 4 and not 0 <= value < _LINE_TYPES:
                                return feats, speeds, ids, segs, False
                            row[sub - 1] = value
                        else:
                            pos = _skip(buf, pos, message_end, sub_wire)
                            if pos < 0:
                                return feats, speeds, ids, segs, False
                    if field <= 12:
                        if n_ids == ids.shape[0]:
                            ids = _grown_ints(ids)
                        ids[n_ids, 0], ids[n_ids, 1], ids[n_ids, 2] = k, field - 9, row[0]
                        n_ids += 1
                    else:
                        if n_segs == segs.shape[0]:
                            segs = _grown_ints(segs)
                        segs[n_segs, 0], segs[n_segs, 1] = k, field - 13
                        segs[n_segs, 2:6] = row
                        n_segs += 1
                else:
                    pos = _skip(buf, pos, lane_end, wire)
                    if pos < 0:
                        return feats, speeds, ids, segs, False
    return feats[:n_feat], speeds[:n_feat], ids[:n_ids], segs[:n_segs], True


#: :func:`map_lanes`: per map feature (F, 4) its id, its ``feature_data`` field number (0:
#: none), its lane's type and interpolating (0/1); (F,) its lane's speed_limit_mph; (M, 3) the
#: ids of the lanes' lists (feature, list code, id) and (B, 6) their boundary segments
#: (feature, side 0 left / 1 right, lane_start_index, lane_end_index, boundary_feature_id,
#: boundary_type), each in wire order
MapLanes = tuple[I64, F64, I64, I64]


def map_lanes(data: bytes) -> MapLanes | None:
    """The lane graph's numbers of the ``Scenario`` ``data``'s map features (:data:`MapLanes`);
    None when the walk gives up (module text; an enum number or an int32 the schema does not
    take too)."""
    feats, speeds, ids, segs, ok = _lanes(np.frombuffer(data, dtype=np.uint8))
    if not ok:
        return None
    return (
        np.ascontiguousarray(feats),
        np.ascontiguousarray(speeds),
        np.ascontiguousarray(ids),
        np.ascontiguousarray(segs),
    )
