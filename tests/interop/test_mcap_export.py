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
from mcap.stream_reader import StreamReader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoders
from mcap_ros2.decoder import DecoderFactory as Ros2Decoders
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from redrive.cli.main import main
from redrive.io import open_log
from redrive.results import open_run


@pytest.fixture(scope="module")
def exported(short_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("fg_export")
    assert main(["export", str(short_run), "--format", "mcap", "-o", str(out)]) == 0
    path = out / "run.mcap"
    assert path.is_file()
    return path


@pytest.fixture(scope="module")
def decoded(exported: Path) -> dict[str, list[tuple[int, Any]]]:
    """topic → [(log_time_ns, decoded message)] of every message (protobuf and ROS 2 CDR)."""
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with exported.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[ProtobufDecoders(), Ros2Decoders()])
        for _, channel, message, value in reader.iter_decoded_messages(log_time_order=True):
            out[channel.topic].append((message.log_time, value))
    return dict(out)


def test_the_file_passes_mcap_validation(exported: Path) -> None:
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


def test_the_log_channels_are_there_byte_for_byte(short_log: Path, exported: Path) -> None:
    with open_log(short_log) as src, open_log(exported) as out:
        # the run's ego places base_link: the log's /tf is left out (one parent per frame)
        assert set(src.topics) - set(out.topics) == {"/tf"}
        for topic in ("/lidar_top", "/tf_static", "/ground_truth/objects"):
            a = [(m.log_time_ns, bytes(m.raw)) for m in src.messages(topics=[topic])]
            b = [(m.log_time_ns, bytes(m.raw)) for m in out.messages(topics=[topic])]
            assert a == b, topic


def _stamp_ns(ts: Any) -> int:
    return int(ts.seconds) * 1_000_000_000 + int(ts.nanos)


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def test_every_entity_frame_is_in_the_transforms_at_its_stamp(
    short_run: Path, decoded: dict[str, list[tuple[int, Any]]]
) -> None:
    tree: dict[int, dict[str, str]] = {}  # stamp → child → parent
    for t_ns, msg in decoded["/redrive/transforms"]:
        parents = tree.setdefault(t_ns, {})
        for tf in msg.transforms:
            assert _stamp_ns(tf.timestamp) == t_ns
            parents[tf.child_frame_id] = tf.parent_frame_id

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
    assert parent_of["base_link"] == {"map"}

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
    for topic in ("/foxglove/lidar_top", "/foxglove/camera_front/image_raw"):
        assert decoded[topic], topic
        for _, msg in decoded[topic]:
            assert msg.frame_id in sensor_frames


def test_boxes_equal_the_stored_results(
    short_run: Path, decoded: dict[str, list[tuple[int, Any]]]
) -> None:
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
    assert "/foxglove/camera_front/image_raw" in topics


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
        wanted = ["/redrive/ego_logged", "/redrive/transforms"]
        for _, channel, message, value in reader.iter_decoded_messages(topics=wanted):
            if channel.topic == "/redrive/ego_logged":
                ghosts[message.log_time] = value
            else:
                (tf,) = [t for t in value.transforms if t.child_frame_id == "base_link"]
                base_link[message.log_time] = tf
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
