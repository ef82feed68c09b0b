"""Waymo Open Motion Scenario TFRecords without TensorFlow: the framing and its CRCs, the schema
built from the documented field numbers, and the real scenario of ../shared/data as a log."""

from __future__ import annotations

import dataclasses
import math
import shutil
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.errors import LogError
from redrive.io import open_log
from redrive.io.content import log_contents, log_road_map
from redrive.io.datasets.tfrecord import masked_crc32c, read_tfrecords, write_tfrecord
from redrive.io.datasets.womd import TOPIC_OBJECTS, TOPIC_TRAFFIC_LIGHTS, WomdReader, light_state_of
from redrive.io.datasets.womd_proto import scenario_class
from redrive.maps.index import RoadMapIndex
from redrive.types import LightState, ObjectClass, TrafficData


@pytest.fixture(scope="module")
def womd_file(shared_data: Path) -> Path:
    path = shared_data / "womd" / "motion_data_one_scenario.tfrecord"
    if not path.is_file():
        pytest.skip("the WOMD scenario is not in ../shared/data")
    return path


def test_the_masked_crc_is_tensorflows() -> None:
    # crc32c("123456789") = 0xE3069283 (RFC 3720's check value), masked as record_writer does
    crc = 0xE3069283
    assert masked_crc32c(b"123456789") == (((crc >> 15) | (crc << 17)) + 0xA282EAD8) & 0xFFFFFFFF


def test_records_round_trip_and_damage_names_record_and_byte(tmp_path: Path) -> None:
    path = tmp_path / "x.tfrecord"
    write_tfrecord(path, [b"first", b"second record"])
    records = list(read_tfrecords(path))
    assert [r.data for r in records] == [b"first", b"second record"]
    assert [r.offset for r in records] == [0, 12 + 5 + 4]
    raw = bytearray(path.read_bytes())
    raw[21 + 12 + 3] ^= 0xFF  # a byte of the second record's data
    path.write_bytes(bytes(raw))
    with pytest.raises(LogError, match=r"record 1 at byte 21: the CRC of its 13 data bytes"):
        list(read_tfrecords(path))
    path.write_bytes(bytes(raw[:40]))
    with pytest.raises(
        LogError, match=r"record 1 at byte 21: it holds \d+ bytes but the file ends"
    ):
        list(read_tfrecords(path))
    raw[0] ^= 1  # the length field
    path.write_bytes(bytes(raw))
    with pytest.raises(LogError, match=r"record 0 at byte 0: the CRC of its length field"):
        list(read_tfrecords(path))


@pytest.mark.parametrize(
    ("state", "light"),
    [
        (0, LightState.UNKNOWN),
        (1, LightState.RED),
        (2, LightState.YELLOW),
        (3, LightState.GREEN),
        (4, LightState.RED),
        (5, LightState.YELLOW),
        (6, LightState.GREEN),
        (7, LightState.RED),
        (8, LightState.YELLOW),
    ],
)
def test_signal_states(state: int, light: LightState) -> None:
    assert light_state_of(state) is light


def _scenario() -> Any:
    """Two agents over three steps, one lane with a signal, written with the schema."""
    sc = scenario_class()()
    sc.scenario_id = "toy"
    sc.timestamps_seconds.extend([0.0, 0.1, 0.2])
    sc.current_time_index = 1
    sc.sdc_track_index = 1
    for tid, kind, x0, heading in ((7, 3, 10.0, math.pi / 2), (9, 1, 0.0, 0.0)):
        track = sc.tracks.add(id=tid, object_type=kind)
        for k in range(3):
            track.states.add(
                center_x=x0 + k, center_y=0.0, center_z=1.0, length=4.0, width=2.0,
                height=1.5, heading=heading, velocity_x=10.0, velocity_y=0.0, valid=k != 2 or tid == 9,
            )  # fmt: skip
    sc.objects_of_interest.append(7)
    sc.tracks_to_predict.add(track_index=0, difficulty=2)
    lane = sc.map_features.add(id=100)
    for x in (0.0, 20.0, 40.0):
        lane.lane.polyline.add(x=x, y=0.0, z=0.0)
    lane.lane.speed_limit_mph = 25.0
    for fid, y in ((200, 1.8), (201, -1.8)):
        edge = sc.map_features.add(id=fid)
        edge.road_edge.type = 1
        for x in (0.0, 40.0):
            edge.road_edge.polyline.add(x=x, y=y)
    lane.lane.left_boundaries.add(lane_start_index=0, lane_end_index=2, boundary_feature_id=200)
    lane.lane.right_boundaries.add(lane_start_index=0, lane_end_index=2, boundary_feature_id=201)
    sign = sc.map_features.add(id=300)
    sign.stop_sign.lane.append(100)
    sign.stop_sign.position.x, sign.stop_sign.position.y = 21.0, 2.5
    for k in range(3):
        sc.dynamic_map_states.add().lane_states.add(
            lane=100, state=6 if k else 4, stop_point={"x": 40.0, "y": 0.0}
        )
    return sc


def test_a_written_scenario_reads_back_as_a_log(tmp_path: Path) -> None:
    path = tmp_path / "toy.tfrecord"
    write_tfrecord(path, [_scenario().SerializeToString()])
    with open_log(path) as log:
        assert isinstance(log, WomdReader)
        assert log.info.sdc_track_id == 9
        assert log.info.tracks_to_predict == ((7, 2),)
        assert log.info.objects_of_interest == (7,)
        messages = list(log.messages())
        road = log_road_map(log)
    assert [m.log_time_ns for m in messages if m.topic == "/ego_pose"] == [
        0,
        100_000_000,
        200_000_000,
    ]
    objects = [m.payload.value for m in messages if m.topic == TOPIC_OBJECTS]  # type: ignore[attr-defined]
    assert [len(o) for o in objects] == [1, 1, 0]  # the cyclist is invalid at the last step
    cyclist = objects[0][0]
    assert cyclist.object_id == 7
    assert cyclist.object_class is ObjectClass.BICYCLE
    np.testing.assert_allclose(cyclist.box.center, [10.0, 0.0, 0.0])  # SDC at x=0 heading +x
    assert cyclist.box.yaw_rad == pytest.approx(math.pi / 2)
    np.testing.assert_allclose(cyclist.velocity, [10.0, 0.0, 0.0])
    lights = [m.payload.value for m in messages if m.topic == TOPIC_TRAFFIC_LIGHTS]  # type: ignore[attr-defined]
    assert [tl.traffic_lights[0].state for tl in lights] == [
        LightState.RED,
        LightState.GREEN,
        LightState.GREEN,
    ]
    assert road is not None
    (lane,) = road.lanes
    assert lane.width_m == pytest.approx(3.6)
    assert lane.speed_limit_mps == pytest.approx(25 * 0.44704)
    assert (lane.left_boundary_type, lane.right_boundary_type) == ("road_edge", "road_edge")
    (light,) = road.traffic_lights
    assert light.light_id == "100" == lights[0].traffic_lights[0].id
    assert light.lane_ids == ("100",)
    stops = {stop.stop_line_id: stop for stop in road.stop_lines}
    assert light.stop_line_id == "signal:100"
    np.testing.assert_allclose(stops["signal:100"].line, [[40.0, 1.8], [40.0, -1.8]])
    np.testing.assert_allclose(stops["stop_sign:300:100"].line, [[20.0, 1.8], [20.0, -1.8]])


def test_a_track_with_missing_states_is_damage(tmp_path: Path) -> None:
    sc = _scenario()
    del sc.tracks[0].states[-1]
    path = tmp_path / "bad.tfrecord"
    write_tfrecord(path, [sc.SerializeToString()])
    with pytest.raises(LogError, match=r"record 0 at byte 0: track 0 \(id 7\) has 2 states for 3"):
        open_log(path)


@pytest.mark.parametrize("field", ["center_x", "length", "heading", "velocity_y"])
def test_a_valid_state_that_is_not_finite_is_damage(tmp_path: Path, field: str) -> None:
    """Every number of a valid state is checked at open (the objects are built trusted)."""
    sc = _scenario()
    setattr(sc.tracks[0].states[1], field, math.nan)
    path = tmp_path / "bad.tfrecord"
    write_tfrecord(path, [sc.SerializeToString()])
    with pytest.raises(LogError, match="track 0 step 1 is valid but holds a value that is not"):
        open_log(path)
    setattr(sc.tracks[0].states[2], field, math.nan)  # an invalid state may hold anything
    sc.tracks[0].states[1].CopyFrom(sc.tracks[0].states[0])
    write_tfrecord(path, [sc.SerializeToString()])
    with open_log(path) as log:
        assert log.objects_at(1)[0].object_id == 7


def test_a_lane_showing_one_state_at_several_steps_shares_its_light(tmp_path: Path) -> None:
    path = tmp_path / "toy.tfrecord"
    write_tfrecord(path, [_scenario().SerializeToString()])
    with open_log(path) as log:
        lights = [
            m.payload.value.traffic_lights for m in log.messages(topics=[TOPIC_TRAFFIC_LIGHTS])
        ]  # type: ignore[attr-defined]
    assert [tl[0].state for tl in lights] == [LightState.RED, LightState.GREEN, LightState.GREEN]
    assert lights[1][0] is lights[2][0]
    assert lights[0][0] is not lights[1][0]


def test_the_roadgraph_lanes_are_the_ones_the_constructor_makes(tmp_path: Path) -> None:
    """The lanes built without MapLane's checks equal what MapLane(...) makes of their fields
    (read-only centreline views included); a speed limit the checks refuse is still refused."""
    path = tmp_path / "toy.tfrecord"
    write_tfrecord(path, [_scenario().SerializeToString()])
    with open_log(path) as log:
        road = log_road_map(log)
    assert road is not None
    for lane in road.lanes:
        made = dataclasses.replace(lane)  # through __init__ and its checks
        for f in dataclasses.fields(lane):
            got, want = getattr(lane, f.name), getattr(made, f.name)
            if isinstance(got, np.ndarray):
                assert got.tobytes() == want.tobytes()
                assert not got.flags.writeable
            else:
                assert got == want
                assert type(got) is type(want)
    sc = _scenario()
    sc.map_features[0].lane.speed_limit_mph = math.inf
    write_tfrecord(path, [sc.SerializeToString()])
    with open_log(path) as log, pytest.raises(ValueError, match="speed_limit_mps must be > 0"):
        log_road_map(log)


@pytest.mark.shared_data
def test_the_real_scenario_has_its_agents_91_steps_and_the_sdc(womd_file: Path) -> None:
    with open_log(womd_file) as log:
        assert log.format == "womd"
        contents = log_contents(log)
        assert contents["agents"] == 83
        assert contents["steps"] == 91
        assert contents["SDC"] == "track 2406 (index 82)"
        assert contents["tracks to predict"] == 3
        assert contents["lanes"] == 199
        messages = list(log.messages())
        tracks = log.tracks
    states = [m.payload.value for m in messages if m.topic == "/ego_pose"]  # type: ignore[attr-defined]
    assert len(states) == 91
    np.testing.assert_allclose([s.position for s in states], tracks.xyz[82])
    objects = [m.payload.value for m in messages if m.topic == TOPIC_OBJECTS]  # type: ignore[attr-defined]
    assert all(2406 not in {o.object_id for o in objs} for objs in objects)
    assert [len(o) for o in objects] == [int(v) - 1 for v in tracks.valid.sum(axis=0)]
    # an agent's map position back from base_link
    k, state = 10, states[10]
    c, s = math.cos(state.heading_rad), math.sin(state.heading_rad)
    for o in objects[k][:5]:
        i = int(np.flatnonzero(tracks.ids == o.object_id)[0])
        x, y = o.box.center[:2]
        np.testing.assert_allclose(
            state.position[:2] + np.array([c * x - s * y, s * x + c * y]), tracks.xyz[i, k, :2]
        )
    lights = [m.payload.value for m in messages if m.topic == TOPIC_TRAFFIC_LIGHTS]  # type: ignore[attr-defined]
    assert len(lights) == 91
    assert all(isinstance(tl, TrafficData) for tl in lights)
    assert {tl.state for tl in lights[0].traffic_lights} >= {LightState.RED, LightState.UNKNOWN}


@pytest.mark.shared_data
def test_the_sdc_drives_in_lanes_of_the_roadgraph(womd_file: Path) -> None:
    with open_log(womd_file) as log:
        road = log_road_map(log)
        tracks = log.tracks
    assert road is not None
    assert len(road.lanes) >= 190
    assert len(road.crosswalks) == 4
    assert {light.light_id for light in road.traffic_lights} <= {
        lane.lane_id for lane in road.lanes
    }
    index = RoadMapIndex(road)
    assert index.on_drivable_area(tracks.xyz[82, :, :2]).all()
    lanes = index.lane_of_pose(tracks.xyz[82, :, :2], tracks.heading_rad[82])
    assert all(lane is not None for lane in lanes)


@pytest.mark.shared_data
def test_a_damaged_byte_of_the_real_file_names_the_record(womd_file: Path, tmp_path: Path) -> None:
    damaged = tmp_path / "damaged.tfrecord"
    shutil.copyfile(womd_file, damaged)
    raw = bytearray(damaged.read_bytes())
    raw[500_000] ^= 0x40
    damaged.write_bytes(bytes(raw))
    with pytest.raises(
        LogError, match=r"damaged\.tfrecord: record 0 at byte 0: the CRC of its 952947 data bytes"
    ):
        open_log(damaged)
    damaged.write_bytes(bytes(raw[:400_000]))
    with pytest.raises(
        LogError, match=r"record 0 at byte 0: it holds 952947 bytes but the file ends"
    ):
        open_log(damaged)
    assert struct.unpack("<Q", raw[:8])[0] == 952947


def test_a_log_without_sensors_makes_a_frame_per_step(tmp_path: Path) -> None:
    from redrive.assembly.frames import FrameAssembler

    path = tmp_path / "toy.tfrecord"
    write_tfrecord(path, [_scenario().SerializeToString()])
    with open_log(path) as log:
        frames = list(FrameAssembler(log).frames())
    assert [f.stamp_ns for f in frames] == [0, 100_000_000, 200_000_000]
    assert [len(f.ground_truth or ()) for f in frames] == [1, 1, 0]
    assert all(f.vehicle_state is not None for f in frames)
    # the signal states reach the frames
    assert [[(t.id, t.state) for t in f.traffic.traffic_lights] for f in frames] == [
        [("100", LightState.RED)],
        [("100", LightState.GREEN)],
        [("100", LightState.GREEN)],
    ]


def test_a_shard_of_several_scenarios_reads_its_first(tmp_path: Path) -> None:
    first, second = _scenario(), _scenario()
    second.scenario_id = "other"
    path = tmp_path / "shard.tfrecord"
    write_tfrecord(path, [first.SerializeToString(), second.SerializeToString()])
    with open_log(path) as log:
        contents = log_contents(log)
    assert contents["scenario"] == "toy"
    assert contents["scenarios in the file (the first is read)"] == 2


def test_convert_writes_the_scenario_with_its_light_states(tmp_path: Path) -> None:
    from redrive.io.convert import convert_log

    path = tmp_path / "toy.tfrecord"
    write_tfrecord(path, [_scenario().SerializeToString()])
    stats = convert_log(path, tmp_path / "toy.mcap")
    assert set(stats.topics) == {"/ego_pose", TOPIC_OBJECTS, TOPIC_TRAFFIC_LIGHTS}
    assert not stats.skipped_topics
    assert stats.messages_written == 9  # an empty objects message keeps the objects' type
    with open_log(tmp_path / "toy.mcap") as log:
        lights = list(log.messages(topics=[TOPIC_TRAFFIC_LIGHTS]))
    assert len(lights) == 3


def test_open_log_decodes_the_first_record_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Recognising the file decodes its first record; open_log hands that Scenario to the reader
    (no module-level slot), and a hand-off of other bytes is not trusted."""
    from redrive.io.datasets import womd

    path = tmp_path / "toy.tfrecord"
    write_tfrecord(path, [_scenario().SerializeToString()])
    decoded: list[bytes] = []
    parse = womd._parse

    def counting(data: bytes) -> Any:
        decoded.append(data)
        return parse(data)

    monkeypatch.setattr(womd, "_parse", counting)
    with open_log(path) as log:
        assert log.info.sdc_track_id == 9
    assert len(decoded) == 1
    other = _scenario()
    other.scenario_id = "other"
    stale = WomdReader.recognised(path)
    assert stale is not None
    write_tfrecord(path, [other.SerializeToString()])  # the file changed after it was recognised
    decoded.clear()
    with WomdReader(path, recognised=stale) as log:
        assert log.info.scenario_id == "other"
    assert len(decoded) == 1
