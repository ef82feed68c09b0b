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
from redrive.io.datasets.womd_proto import scenario_class
from redrive.io.datasets.womd_wire import STATE_FIELDS, map_polylines, track_states

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


def _assert_as_runtime(data: bytes) -> None:
    sc = scenario_class()()
    sc.ParseFromString(data)
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
    line = sc.map_features.add(id=11)
    line.road_line.polyline.add(x=5.0)  # y absent
    sc.map_features.add(id=12).stop_sign.position.x = 3.0
    walk = sc.map_features.add(id=13)
    for x, y in ((0.0, 0.0), (1.0, 0.0), (1.0, 1.0)):
        walk.crosswalk.polygon.add(x=x, y=y)
    sc.map_features.add(id=14)  # no feature data
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


def test_a_cut_record_gives_up_or_reads_what_it_holds() -> None:
    data = _toy().SerializeToString()
    for cut in range(len(data)):
        track_states(data[:cut])  # never reads past the bytes
        map_polylines(data[:cut])


def test_the_real_scenario(shared_data: Path) -> None:
    path = shared_data / "womd" / "motion_data_one_scenario.tfrecord"
    if not path.is_file():
        pytest.skip("the WOMD scenario is not in ../shared/data")
    _assert_as_runtime(next(read_tfrecords(path)).data)
