"""The WOMD record's track states and map points read from its wire format: the protobuf
runtime's numbers, bit for bit, and a walk that gives up (the reader then takes the runtime's
objects) on what it does not expect."""

from __future__ import annotations

import itertools
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.io.datasets.tfrecord import read_tfrecords
from redrive.io.datasets.womd_map import _roadgraph
from redrive.io.datasets.womd_proto import scenario_class
from redrive.io.datasets.womd_wire import STATE_FIELDS, map_polylines, track_states
from redrive.io.datasets.womd_wire_map import lane_states, map_lanes

_POINTS = {"lane": "polyline", "road_line": "polyline", "road_edge": "polyline"}


def _runtime_states(sc: Any) -> tuple[bytes, list[int]]:
    rows = [[getattr(s, f) for f in STATE_FIELDS] for t in sc.tracks for s in t.states]
    return np.array(rows, dtype=np.float64).reshape(-1, 10).tobytes(), [
        len(t.states) for t in sc.tracks
    ]


def _runtime_points(sc: Any) -> list[bytes]:
    out = []
    for f in sc.map_features:
        kind = f.WhichOneof("feature_data")
        if kind == "crosswalk":
            pts = f.crosswalk.polygon
        elif kind in _POINTS:
            pts = getattr(f, kind).polyline
        else:
            pts = []
        out.append(np.array([[p.x, p.y] for p in pts], dtype=np.float64).reshape(-1, 2).tobytes())
    return out


def _runtime_lane_states(sc: Any) -> list[tuple[int, int, int, bool, float, float]]:
    return [
        (k, s.lane, s.state, s.HasField("stop_point"), s.stop_point.x, s.stop_point.y)
        for k, step in enumerate(sc.dynamic_map_states)
        for s in step.lane_states
    ]


def _walked_lane_states(data: bytes) -> tuple[list[tuple[int, int, int, bool, float, float]], int]:
    walked = lane_states(data)
    assert walked is not None
    step, lane, state, has_stop, xy, steps = walked
    columns = (step.tolist(), lane.tolist(), state.tolist(), has_stop.tolist(), xy.tolist())
    rows = zip(*columns, strict=True)
    return [(k, i, n, h, x if h else 0.0, y if h else 0.0) for k, i, n, h, (x, y) in rows], steps


def _assert_as_runtime(data: bytes) -> None:
    sc = scenario_class()()
    sc.ParseFromString(data)
    assert _walked_lane_states(data) == (_runtime_lane_states(sc), len(sc.dynamic_map_states))
    lanes = map_lanes(data)
    assert lanes is not None
    assert _roadgraph(sc, lanes) == _roadgraph(sc, None)  # kinds, ids, lanes' numbers
    walked = track_states(data)
    assert walked is not None
    assert (walked[0].tobytes(), walked[1].tolist()) == _runtime_states(sc)
    points = map_polylines(data)
    assert points is not None
    xy, offsets = points
    assert [xy[a:b].tobytes() for a, b in itertools.pairwise(offsets)] == _runtime_points(sc)


def _toy() -> Any:
    sc = scenario_class()()
    sc.timestamps_seconds.extend([0.0, 0.1])
    for tid in (3, 4):
        track = sc.tracks.add(id=tid, object_type=1)
        track.states.add(center_x=1.0 / 3.0, center_y=-2.5e7, length=4.1, heading=-3.1, valid=True)
        track.states.add()  # every field absent: the defaults
    lane = sc.map_features.add(id=10)
    for x in (0.1, 20.2, 40.3):
        lane.lane.polyline.add(x=x, y=x / 7.0, z=1.0)
    lane.lane.entry_lanes.extend([1, 2])
    lane.lane.exit_lanes.append(-7)
    lane.lane.speed_limit_mph = 1.0 / 3.0
    lane.lane.type = 2
    lane.lane.interpolating = True
    lane.lane.left_neighbors.add(feature_id=2**40, self_start_index=3).boundaries.add(
        boundary_feature_id=11
    )
    lane.lane.right_neighbors.add()  # feature_id absent: 0
    lane.lane.left_boundaries.add(lane_start_index=-2, lane_end_index=5, boundary_feature_id=11)
    lane.lane.right_boundaries.add(boundary_feature_id=11, boundary_type=7)
    line = sc.map_features.add(id=11)
    line.road_line.polyline.add(x=5.0)  # y absent
    sc.map_features.add(id=12).stop_sign.position.x = 3.0
    walk = sc.map_features.add(id=13)
    for x, y in ((0.0, 0.0), (1.0, 0.0), (1.0, 1.0)):
        walk.crosswalk.polygon.add(x=x, y=y)
    sc.map_features.add(id=14)  # no feature data
    sc.dynamic_map_states.add().lane_states.add(lane=-(2**40), state=6, stop_point={"x": 0.5})
    sc.dynamic_map_states.add()  # a step without lane states
    step = sc.dynamic_map_states.add()
    step.lane_states.add(lane=10)  # state and stop point absent
    step.lane_states.add(lane=11, state=8, stop_point={"x": -1.0, "y": 2.0})
    return sc


def test_the_numbers_are_the_runtimes() -> None:
    _assert_as_runtime(_toy().SerializeToString())


def test_a_field_given_twice_keeps_its_last_value_and_unknown_fields_are_skipped() -> None:
    sc = _toy()
    state = sc.tracks[0].states[0].SerializeToString()
    again = state + b"\x11" + struct.pack("<d", 9.5) + b"\x68\x05" + b"\x7a\x02ab"  # x, f13, f15
    track = b"\x08\x05" + b"\x1a" + bytes([len(again)]) + again
    data = sc.SerializeToString() + b"\x12" + bytes([len(track)]) + track + b"\x49" + bytes(8)
    _assert_as_runtime(data)
    walked = track_states(data)
    assert walked is not None
    assert walked[0][-1, 0] == 9.5


@pytest.mark.parametrize(
    "tail",
    [
        b"\x12\x04\x1a\x02\x10\x01",  # center_x as a varint: a known field of another wire type
        b"\x12\x03\x1a\x05\x11",  # a state longer than its track
        b"\x42\x04\x1a\x00\x22\x00",  # a map feature with a lane and a road line
        b"\x13\x14",  # a group
    ],
)
def test_what_the_walk_does_not_expect_gives_up(tail: bytes) -> None:
    data = _toy().SerializeToString() + tail
    assert track_states(data) is None or map_polylines(data) is None


def test_a_lane_state_the_schema_does_not_know_gives_up() -> None:
    """proto2 keeps an unknown enum value apart (the field keeps its earlier value): the walk
    leaves it to the runtime."""
    for state in (b"\x10\x63", b"\x10\x04\x10\x63"):  # 99; 4 then 99 (the runtime: 4)
        inner = b"\x08\x05" + state
        message = b"\x0a" + bytes([len(inner)]) + inner
        data = _toy().SerializeToString() + b"\x3a" + bytes([len(message)]) + message
        assert lane_states(data) is None
        assert track_states(data) is not None


def _varint(value: int) -> bytes:
    value &= (1 << 64) - 1
    out = bytearray()
    while True:
        low, value = value & 0x7F, value >> 7
        out.append(low | (0x80 if value else 0))
        if not value:
            return bytes(out)


def _lane_feature(lane: bytes, fid: int = 99) -> bytes:
    feature = b"\x08" + _varint(fid) + b"\x1a" + _varint(len(lane)) + lane
    return b"\x42" + _varint(len(feature)) + feature


def test_packed_lane_lists_read_as_the_runtime_reads_them() -> None:
    packed = b"".join(_varint(v) for v in (4, -1, 2**40))
    lane = b"\x48\x05" + b"\x4a" + _varint(len(packed)) + packed + b"\x50\x03"  # 9, 9, 10
    data = _toy().SerializeToString() + _lane_feature(lane)
    _assert_as_runtime(data)
    lanes = map_lanes(data)
    assert lanes is not None
    assert _roadgraph(scenario_class()(), lanes)[1][5].entry_lanes == [5, 4, -1, 2**40]


@pytest.mark.parametrize(
    "lane",
    [
        b"\x10\x04",  # a lane type the schema does not know
        b"\x6a\x02\x20\x09",  # a boundary type the schema does not know
        b"\x6a\x06\x08" + _varint(2**33),  # a lane_start_index beyond int32
        b"\x08\x00",  # speed_limit_mph as a varint
    ],
)
def test_what_the_lane_walk_does_not_take_gives_up(lane: bytes) -> None:
    data = _toy().SerializeToString() + _lane_feature(lane)
    assert map_lanes(data) is None
    assert map_polylines(data) is not None


def test_a_stop_point_given_twice_merges() -> None:
    sc = _toy()
    inner = b"\x08\x07" + b"\x1a\x09\x09" + struct.pack("<d", 1.5) + b"\x1a\x09\x11"
    inner += struct.pack("<d", -2.5)  # x in the first stop point, y in the second
    message = b"\x0a" + bytes([len(inner)]) + inner
    data = sc.SerializeToString() + b"\x3a" + bytes([len(message)]) + message
    _assert_as_runtime(data)
    rows, _ = _walked_lane_states(data)
    assert rows[-1][3:] == (True, 1.5, -2.5)


def test_a_cut_record_gives_up_or_reads_what_it_holds() -> None:
    data = _toy().SerializeToString()
    for cut in range(len(data)):
        track_states(data[:cut])  # never reads past the bytes
        map_polylines(data[:cut])
        lane_states(data[:cut])
        map_lanes(data[:cut])


def test_the_real_scenario(shared_data: Path) -> None:
    path = shared_data / "womd" / "motion_data_one_scenario.tfrecord"
    if not path.is_file():
        pytest.skip("the WOMD scenario is not in ../shared/data")
    _assert_as_runtime(next(read_tfrecords(path)).data)
