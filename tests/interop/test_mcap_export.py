"""``redrive export RUN --format mcap``: a valid MCAP whose scene matches the run's results."""

from __future__ import annotations

import math
import struct
import zlib
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap.records import Chunk, Message, MessageIndex
from mcap.stream_reader import StreamReader, breakup_chunk, get_chunk_data_stream
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoders
from mcap_ros2.decoder import DecoderFactory as Ros2Decoders
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from redrive.cli.main import main
from redrive.interop.stream import find_run_log
from redrive.io import open_log
from redrive.results import open_run


def _export(run: Path, out: Path, *extra: str) -> Path:
    assert main(["export", str(run), "--format", "mcap", "-o", str(out), *extra]) == 0
    path = out / f"{run.name}.mcap"
    assert path.is_file()
    return path


@pytest.fixture(scope="module")
def exported(short_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default export: the log's chunks copied, the run's scene beside them."""
    return _export(short_run, tmp_path_factory.mktemp("fg_export"))


@pytest.fixture(scope="module")
def exported_copies(short_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``--sensor-copies``: foxglove.PointCloud / CompressedImage copies of the sensor data too."""
    return _export(short_run, tmp_path_factory.mktemp("fg_copies"), "--sensor-copies")


@pytest.fixture(scope="module", params=["default", "sensor-copies"])
def either(request: pytest.FixtureRequest) -> Path:
    name = "exported" if request.param == "default" else "exported_copies"
    path: Path = request.getfixturevalue(name)
    return path


def _decode(path: Path) -> dict[str, list[tuple[int, Any]]]:
    """topic → [(log_time_ns, decoded message)] of every message (protobuf and ROS 2 CDR)."""
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with path.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[ProtobufDecoders(), Ros2Decoders()])
        for _, channel, message, value in reader.iter_decoded_messages(log_time_order=True):
            out[channel.topic].append((message.log_time, value))
    return dict(out)


@pytest.fixture(scope="module")
def decoded(exported: Path) -> dict[str, list[tuple[int, Any]]]:
    return _decode(exported)


@pytest.fixture(scope="module")
def decoded_either(either: Path) -> dict[str, list[tuple[int, Any]]]:
    return _decode(either)


def test_the_file_passes_mcap_validation(either: Path) -> None:
    exported = either
    with exported.open("rb") as fh:
        records = list(StreamReader(fh, validate_crcs=True).records)  # chunk + data section CRCs
    assert records
    data = exported.read_bytes()
    summary_start, _, summary_crc = struct.unpack_from("<QQI", data, len(data) - 8 - 20)
    assert summary_crc != 0
    assert zlib.crc32(data[summary_start : len(data) - 8 - 4]) == summary_crc
    with exported.open("rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None
        assert summary.statistics is not None
        assert summary.chunk_indexes
        count = sum(1 for _ in reader.iter_messages())
    assert count == summary.statistics.message_count


def _messages(path: Path, topics: set[str] | None = None) -> list[tuple[str, int, int, int, bytes]]:
    """(topic, log time, publish time, sequence, data) of every message, in log-time order."""
    with path.open("rb") as fh:
        return [
            (c.topic, m.log_time, m.publish_time, m.sequence, m.data)
            for _, c, m in make_reader(fh).iter_messages(log_time_order=True)
            if topics is None or c.topic in topics
        ]


def test_the_logs_messages_are_copied_byte_for_byte(short_log: Path, either: Path) -> None:
    source = _messages(short_log)
    topics = {m[0] for m in source}
    # an open-loop run keeps every log topic, /tf too: its ego is the logged ego
    assert {"/tf", "/lidar_top", "/camera_front/image_raw"} <= topics
    assert _messages(either, topics) == source
    with short_log.open("rb") as a, either.open("rb") as b:
        src, out = make_reader(a).get_summary(), make_reader(b).get_summary()
    assert src is not None
    assert out is not None
    # the log's channels and schemas keep their ids and records (so its chunks need no rewrite)
    for channel in src.channels.values():
        assert out.channels[channel.id] == channel
        assert out.schemas[channel.schema_id] == src.schemas[channel.schema_id]
    with open_log(short_log) as log, open_log(either) as back:
        assert set(log.topics) <= set(back.topics)


def test_the_index_reads_what_a_linear_read_reads(either: Path) -> None:
    """The summary's chunk indexes, message indexes and statistics describe the file: an
    indexed read (log-time order) gives the messages a linear read of every record gives."""
    with either.open("rb") as fh:
        linear = [
            (r.channel_id, r.log_time, r.publish_time, r.sequence, r.data)
            for r in StreamReader(fh, skip_magic=False).records
            if isinstance(r, Message)
        ]
    with either.open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None
        indexed = [
            (c.id, m.log_time, m.publish_time, m.sequence, m.data)
            for _, c, m in reader.iter_messages(log_time_order=True)
        ]
    times = [m[1] for m in indexed]
    assert times == sorted(times)
    assert sorted(indexed) == sorted(linear)
    stats = summary.statistics
    assert stats is not None
    assert stats.message_count == len(linear)
    assert stats.chunk_count == len(summary.chunk_indexes)
    assert (stats.message_start_time, stats.message_end_time) == (times[0], times[-1])
    counts: dict[int, int] = defaultdict(int)
    for m in linear:
        counts[m[0]] += 1
    assert {c: n for c, n in stats.channel_message_counts.items() if n} == dict(counts)
    assert set(stats.channel_message_counts) == set(summary.channels)
    # each chunk: its times are its messages' and every message index entry points at a
    # message of its channel and log time; the summary indexes every chunk once
    chunks: list[tuple[int, int, int, int]] = []
    entries = 0
    with either.open("rb") as fh:
        records = list(StreamReader(fh, emit_chunks=True).records)
    for k, record in enumerate(records):
        if not isinstance(record, Chunk):
            continue
        data = get_chunk_data_stream(record, validate_crc=True)[0].read(record.uncompressed_size)
        inner = [m for m in breakup_chunk(record) if isinstance(m, Message)]
        assert record.message_start_time == min(m.log_time for m in inner)
        assert record.message_end_time == max(m.log_time for m in inner)
        chunks.append(
            (
                record.message_start_time,
                record.message_end_time,
                record.uncompressed_size,
                len(inner),
            )
        )
        indexes = []  # the message indexes right after the chunk
        for r in records[k + 1 :]:
            if not isinstance(r, MessageIndex):
                break
            indexes.append(r)
        assert sum(len(i.records) for i in indexes) == len(inner)
        for index in indexes:
            for log_time, offset in index.records:
                opcode, _, channel_id, _, at_time = struct.unpack_from("<BQHIQ", data, offset)
                assert (opcode, channel_id, at_time) == (0x05, index.channel_id, log_time)
                entries += 1
    assert entries == len(linear)
    assert sorted(chunks) == sorted(
        (c.message_start_time, c.message_end_time, c.uncompressed_size, n)
        for c, n in zip(summary.chunk_indexes, _chunk_counts(either, summary), strict=True)
    )


def _chunk_counts(path: Path, summary: Any) -> list[int]:
    """Messages per chunk, from the message indexes the summary's chunk indexes point at."""
    out = []
    data = path.read_bytes()
    for c in summary.chunk_indexes:
        n = 0
        for offset in c.message_index_offsets.values():
            _, _, _, length = struct.unpack_from("<BQHI", data, offset)
            n += length // 16
        out.append(n)
    return out


def _stamp_ns(ts: Any) -> int:
    return int(ts.seconds) * 1_000_000_000 + int(ts.nanos)


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def test_every_entity_frame_is_in_the_transforms_at_its_stamp(
    short_run: Path, decoded_either: dict[str, list[tuple[int, Any]]]
) -> None:
    decoded = decoded_either
    tree: dict[int, dict[str, str]] = {}  # stamp → child → parent
    for t_ns, msg in decoded["/redrive/transforms"]:
        parents = tree.setdefault(t_ns, {})
        for tf in msg.transforms:
            assert _stamp_ns(tf.timestamp) == t_ns
            parents[tf.child_frame_id] = tf.parent_frame_id
    # the log's /tf (kept: an open-loop run's ego is the logged ego) at or before each stamp
    log_tf = [
        (t, {tf.child_frame_id: tf.header.frame_id for tf in m.transforms})
        for t, m in decoded["/tf"]
    ]
    for t_ns, parents in tree.items():
        for at, found in log_tf:
            if at <= t_ns:
                for child, parent in found.items():
                    assert parents.setdefault(child, parent) == parent

    # one parent per frame over every transform topic of the file (Foxglove merges them)
    parent_of: dict[str, set[str]] = defaultdict(set)
    for parents in tree.values():
        for child, parent in parents.items():
            parent_of[child].add(parent)
    for topic in ("/tf_static", "/tf"):
        for _, msg in decoded.get(topic, []):
            for tf in msg.transforms:
                parent_of[tf.child_frame_id].add(tf.header.frame_id)
    assert all(len(p) == 1 for p in parent_of.values()), dict(parent_of)
    assert parent_of["base_link"] == {"odom"}  # the log's map → odom → base_link
    assert parent_of["odom"] == {"map"}

    def root(frame: str, parents: dict[str, str]) -> str:
        seen = set()
        while frame in parents:
            assert frame not in seen, f"transform loop at {frame}"
            seen.add(frame)
            frame = parents[frame]
        return frame

    frames = open_run(short_run).table("frames").column("stamp_ns").to_pylist()
    scene_topics = [t for t in decoded if t.startswith("/redrive/") and "markers" not in t]
    scene_topics.remove("/redrive/transforms")
    # the road map is static: one update, at the first frame (tests/interop/test_map_export.py)
    assert [t for t, _ in decoded["/redrive/map"]] == frames[:1]
    scene_topics.remove("/redrive/map")
    assert {"/redrive/ground_truth", "/redrive/detections/tracker", "/redrive/ego"} <= set(
        scene_topics
    )
    entities = 0
    for topic in scene_topics:
        assert [t for t, _ in decoded[topic]] == frames, topic  # one update per frame, in order
        for t_ns, update in decoded[topic]:
            parents = tree[t_ns]
            for entity in update.entities:
                entities += 1
                assert _stamp_ns(entity.timestamp) == t_ns
                assert entity.frame_id == "map" or entity.frame_id in parents, (topic, entity.id)
                assert root(entity.frame_id, parents) == "map", (topic, entity.id)
    assert entities > 100
    sensor_frames = {f for p in tree.values() for f in p}
    for topic in ("/lidar_top", "/camera_front/image_raw"):  # the log's own, drawn by Foxglove
        assert decoded[topic], topic
        for _, msg in decoded[topic]:
            assert msg.header.frame_id in sensor_frames
    copies = ("/foxglove/lidar_top", "/foxglove/camera_front/image_raw")
    if "/foxglove/lidar_top" not in decoded:  # the default export: no copies
        assert not set(copies) & set(decoded)
        return
    for topic in copies:
        stamps = [_stamp_ns(msg.timestamp) for _, msg in decoded[topic]]
        assert stamps == [t for t, _ in decoded[topic.removeprefix("/foxglove")]], topic
        for _, msg in decoded[topic]:
            assert msg.frame_id in sensor_frames


def test_boxes_equal_the_stored_results(
    short_run: Path, decoded_either: dict[str, list[tuple[int, Any]]]
) -> None:
    decoded = decoded_either
    run = open_run(short_run)
    stamps = dict(
        zip(
            run.table("frames").column("frame_index").to_pylist(),
            run.table("frames").column("stamp_ns").to_pylist(),
            strict=True,
        )
    )
    for topic, objects, prefix in (
        ("/redrive/ground_truth", run.ground_truth(), "gt"),
        ("/redrive/detections/tracker", run.detections("tracker"), "tracker"),
    ):
        updates = dict(decoded[topic])
        checked = 0
        for frame, objs in objects.items():
            by_id = {e.id: e for e in updates[stamps[frame]].entities}
            for obj in objs:
                entity = by_id[f"{prefix}/{obj.object_id}"]
                cube = entity.cubes[0]
                assert entity.frame_id == "base_link"
                got = (cube.pose.position.x, cube.pose.position.y, cube.pose.position.z)
                assert got == pytest.approx(tuple(obj.box.center), abs=1e-9)
                assert (cube.size.x, cube.size.y, cube.size.z) == pytest.approx(
                    tuple(obj.box.size), abs=1e-9
                )
                d_yaw = _yaw(cube.pose.orientation) - obj.box.yaw_rad
                assert math.remainder(d_yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
                if math.hypot(obj.velocity[0], obj.velocity[1]) > 0.1:
                    assert len(entity.arrows) == 1
                    arrow = entity.arrows[0]
                    assert arrow.shaft_length == pytest.approx(
                        float(math.sqrt(sum(v * v for v in obj.velocity)))
                    )
                checked += 1
        assert checked > 10, topic
    marks = [u for _, u in decoded["/redrive/bookmarks"] if u.entities]
    assert len(marks) == 1
    assert "car 12.3 m ahead not detected" in marks[0].entities[0].texts[0].text


def test_marker_arrays_decode_with_rosbags_and_match_the_scene(
    exported: Path, decoded: dict[str, list[tuple[int, Any]]]
) -> None:
    store = get_typestore(Stores.EMPTY)
    with exported.open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None
        channel = next(
            c for c in summary.channels.values() if c.topic == "/redrive/markers/ground_truth"
        )
        schema = summary.schemas[channel.schema_id]
        assert (schema.encoding, channel.message_encoding) == ("ros2msg", "cdr")
        text = schema.data.decode()
        types: dict[str, Any] = {}
        parts = text.split("=" * 80 + "\n")
        types.update(get_types_from_msg(parts[0], schema.name))
        for part in parts[1:]:
            head, _, body = part.partition("\n")
            types.update(get_types_from_msg(body, head.removeprefix("MSG: ").strip()))
        store.register(types)
        arrays = [
            (m.log_time, store.deserialize_cdr(m.data, schema.name))
            for _, _, m in reader.iter_messages(topics=["/redrive/markers/ground_truth"])
        ]
    scenes = dict(decoded["/redrive/ground_truth"])
    assert len(arrays) == len(scenes)
    for t_ns, array in arrays:
        assert array.markers[0].action == 3  # DELETEALL
        cubes = [m for m in array.markers if m.ns == "boxes"]
        scene_cubes = [e.cubes[0] for e in scenes[t_ns].entities if e.cubes]
        assert len(cubes) == len(scene_cubes)
        for marker, cube in zip(cubes, scene_cubes, strict=True):
            assert marker.header.frame_id == "base_link"
            assert marker.header.stamp.sec * 10**9 + marker.header.stamp.nanosec == t_ns
            assert marker.pose.position.x == pytest.approx(cube.pose.position.x)
            assert marker.scale.x == pytest.approx(cube.size.x)


def test_export_without_the_sdk_says_how_to_install(
    short_run: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "foxglove", None)
    assert main(["export", str(short_run), "--format", "mcap"]) == 1
    assert "pip install 'redrive[foxglove]'" in capsys.readouterr().err


def _layout_topics(node: Any) -> set[str]:
    found: set[str] = set()
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "topics" and isinstance(value, dict):
                found |= set(value)
            elif key == "imageTopic" and isinstance(value, str):
                found.add(value)
            else:
                found |= _layout_topics(value)
    elif isinstance(node, list):
        for item in node:
            found |= _layout_topics(item)
    return found


def test_the_docs_layout_is_the_scripts_and_shows_exported_topics(
    decoded: dict[str, list[tuple[int, Any]]],
) -> None:
    import importlib.util
    import json

    root = Path(__file__).resolve().parents[2]
    spec = importlib.util.spec_from_file_location(
        "foxglove_layout", root / "scripts" / "foxglove_layout.py"
    )
    assert spec is not None
    assert spec.loader is not None
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    committed = (root / "docs" / "foxglove_layout.json").read_text(encoding="utf-8")
    assert committed == script.layout_json(), "run scripts/foxglove_layout.py"
    topics = _layout_topics(json.loads(committed))
    # the ghost exists in closed-loop runs only; everything else is in this open-loop export
    assert topics - {"/redrive/ego_logged"} <= set(decoded)
    assert "/camera_front/image_raw" in topics  # the log's own image, not a copy
    assert not {t for t in topics if t.startswith("/foxglove/")}


def test_a_closed_loop_export_shows_the_ghost_where_the_log_drove(
    short_log: Path, tmp_path: Path
) -> None:
    from redrive.sim.ego import EgoGeometry

    run_dir = tmp_path / "closed"
    argv = ["run", str(short_log), "--closed-loop", "--out", str(run_dir), "--no-progress"]
    assert main(argv) == 0
    assert main(["export", str(run_dir), "--format", "mcap", "-o", str(tmp_path)]) == 0
    run = open_run(run_dir)
    driven, logged = run.ego(), run.logged_ego()
    assert logged
    stamps = dict(
        zip(
            run.table("frames").column("frame_index").to_pylist(),
            run.table("frames").column("stamp_ns").to_pylist(),
            strict=True,
        )
    )
    ghosts: dict[int, Any] = {}
    base_link: dict[int, Any] = {}
    with (tmp_path / "closed.mcap").open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[ProtobufDecoders()])
        topics = {c.topic for c in reader.get_summary().channels.values()}  # type: ignore[union-attr]
        assert "/tf" not in topics  # the log's tf moves the logged ego, not the driven one
        assert not {t for t in topics if t.startswith("/foxglove/")}
        wanted = ["/redrive/ego_logged", "/redrive/transforms"]
        for _, channel, message, value in reader.iter_decoded_messages(topics=wanted):
            if channel.topic == "/redrive/ego_logged":
                ghosts[message.log_time] = value
            else:
                (tf,) = [t for t in value.transforms if t.child_frame_id == "base_link"]
                base_link[message.log_time] = tf
    # the chunks holding /tf were decompressed and written again without it: the other
    # messages are the log's, byte for byte, with their publish times and sequences
    log = find_run_log(run)
    assert log is not None
    source = [m for m in _messages(log) if m[0] != "/tf"]
    assert source
    assert _messages(tmp_path / "closed.mcap", {m[0] for m in source}) == source
    offset = EgoGeometry().center_offset_m
    for frame, state in logged.items():
        (entity,) = ghosts[stamps[frame]].entities
        cube = entity.cubes[0]
        assert entity.frame_id == state.frame_id
        assert cube.pose.position.x == pytest.approx(
            state.position[0] + offset * math.cos(state.heading_rad)
        )
        assert cube.color.a < 0.5  # translucent
    for frame, state in driven.items():
        tf = base_link[stamps[frame]]
        assert tf.parent_frame_id == state.frame_id
        assert (tf.translation.x, tf.translation.y) == pytest.approx(tuple(state.position[:2]))


def test_the_lights_stand_at_their_map_positions_in_their_state_colours(
    short_run: Path, decoded: dict[str, list[tuple[int, Any]]]
) -> None:
    from redrive.interop.light_shapes import LAMP_HEIGHT_M, STATE_COLORS

    run = open_run(short_run)
    road_map = run.road_map()
    assert road_map is not None
    positions = {t.light_id: t.position for t in road_map.traffic_lights}
    states = run.traffic_lights()
    frames = run.table("frames").to_pylist()
    updates = dict(decoded["/redrive/traffic_lights"])
    assert len(updates) == len(frames)
    for row in frames:
        by_id = {e.id: e for e in updates[row["stamp_ns"]].entities}
        shown = {t.id: t.state for t in states[row["frame_index"]]}
        assert set(shown) == set(positions) == {"0", "1", "2", "3"}
        for light_id, state in shown.items():
            entity = by_id[f"light/{light_id}"]
            assert entity.frame_id == "map"
            cube = entity.cubes[0]
            x, y = positions[light_id]
            got = (cube.pose.position.x, cube.pose.position.y, cube.pose.position.z)
            assert got == pytest.approx((x, y, LAMP_HEIGHT_M))
            color = (cube.color.r, cube.color.g, cube.color.b, cube.color.a)
            assert color == pytest.approx(STATE_COLORS[state])
            assert state.value in by_id[f"light/{light_id}/label"].texts[0].text
            line = by_id[f"light/{light_id}/stop_line"].lines[0]  # its stop line, same colour
            assert (line.color.r, line.color.g, line.color.b) == pytest.approx(color[:3])
        # urban, the first second: west/east green, south/north red
        assert (shown["0"].value, shown["1"].value) == ("green", "red")
