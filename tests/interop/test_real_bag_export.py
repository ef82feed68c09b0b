"""Issue 35 item 6: the MCAP export of a run over a real bag whose header stamps are not its log
times (the Luminar bag: 2020-03-12 stamps, 2020-11-04 log times), read back with the ``mcap``
library — results beside the cloud they were computed from, on one connected transform tree."""

from __future__ import annotations

import logging
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoders
from rosbags.typesys import Stores, get_typestore

from redrive.cli.main import main
from redrive.results import open_run

_CLOUD = "/luminar_pointcloud"
_ROS1 = get_typestore(Stores.ROS1_NOETIC)


def _export(run: Path, out: Path, *extra: str) -> Path:
    assert main(["export", str(run), "--format", "mcap", "-o", str(out), *extra]) == 0
    return out / f"{run.name}.mcap"


def _decoded(path: Path) -> dict[str, list[tuple[int, Any]]]:
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with path.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[ProtobufDecoders()])
        for _, channel, message, value in reader.iter_decoded_messages(
            topics=[t for t in _topics(path) if t != _CLOUD and not _is_ros(path, t)],
            log_time_order=True,
        ):
            out[channel.topic].append((message.log_time, value))
    with path.open("rb") as fh:
        for _, channel, message in make_reader(fh).iter_messages(topics=[_CLOUD]):
            cloud = _ROS1.deserialize_ros1(message.data, "sensor_msgs/msg/PointCloud2")
            out[channel.topic].append((message.log_time, cloud))
    return dict(out)


def _topics(path: Path) -> list[str]:
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
        assert summary is not None
        return [c.topic for c in summary.channels.values()]


def _is_ros(path: Path, topic: str) -> bool:
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
        assert summary is not None
        return any(
            c.topic == topic and c.message_encoding in ("ros1", "cdr")
            for c in summary.channels.values()
        )


@pytest.fixture(scope="module")
def luminar_export(luminar_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _export(luminar_run, tmp_path_factory.mktemp("fg_luminar_export"))


@pytest.fixture(scope="module")
def luminar_decoded(luminar_export: Path) -> dict[str, list[tuple[int, Any]]]:
    return _decoded(luminar_export)


def _stamp_ns(ts: Any) -> int:
    return int(ts.seconds) * 1_000_000_000 + int(ts.nanos)


def test_results_sit_within_a_frame_period_of_their_cloud_on_the_log_time_axis(
    luminar_run: Path, luminar_decoded: dict[str, list[tuple[int, Any]]]
) -> None:
    decoded = luminar_decoded
    clouds = [t for t, _ in decoded[_CLOUD]]
    assert len(clouds) == 5
    period_ns = (clouds[-1] - clouds[0]) / (len(clouds) - 1)  # ≈ 90 ms (11 Hz)
    frames = open_run(luminar_run).table("frames").column("stamp_ns").to_pylist()
    cloud_stamps = [
        m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for _, m in decoded[_CLOUD]
    ]
    assert frames == cloud_stamps  # the run's frames are the clouds' header stamps …
    assert (clouds[0] - cloud_stamps[0]) / 86400e9 == pytest.approx(237.8, abs=0.05)  # … 237.8 d
    for topic in ("/redrive/detections/cluster-detector", "/redrive/detections/kalman-tracker"):
        times = [t for t, _ in decoded[topic]]
        assert len(times) == len(clouds), topic
        for t_ns, cloud_ns in zip(times, clouds, strict=True):
            assert abs(t_ns - cloud_ns) < period_ns, topic  # each beside its own cloud
        # the messages keep the frame's header stamp
        for (_, update), stamp in zip(decoded[topic], frames, strict=True):
            assert [_stamp_ns(d.timestamp) for d in update.deletions] == [stamp], topic
            assert {_stamp_ns(e.timestamp) for e in update.entities} <= {stamp}, topic
    stored = open_run(luminar_run).table("detections").column("algorithm").to_pylist()
    updates = decoded["/redrive/detections/cluster-detector"]
    boxes = sum(len(e.cubes) for _, u in updates for e in u.entities)
    assert boxes == stored.count("cluster-detector") > 0
    # every results message lies within the log's span (nothing 237.8 days away)
    start, end = clouds[0], max(t for topic in decoded for t, _ in decoded[topic])
    for topic, messages in decoded.items():
        assert all(start <= t <= end for t, _ in messages), topic
    assert (end - start) / 1e9 < 8.0


def test_the_cloud_frame_is_connected_to_base_link_and_the_identity_is_said(
    luminar_run: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, logger="redrive.interop.sensor_frames"):
        path = _export(luminar_run, tmp_path)
    said = [r.getMessage() for r in caplog.records if "'luminar_lidar'" in r.getMessage()]
    assert len(said) == 1, said
    assert "identity assumed" in said[0]
    decoded = _decoded(path)
    frame_id = decoded[_CLOUD][0][1].header.frame_id
    assert frame_id == "luminar_lidar"
    clouds = [t for t, _ in decoded[_CLOUD]]
    transforms = decoded["/redrive/transforms"]
    assert [t for t, _ in transforms] == clouds  # one FrameTransforms per frame, at its log time
    for _, message in transforms:
        parents = {tf.child_frame_id: tf for tf in message.transforms}
        frame, chain = frame_id, []
        while frame in parents:  # walk the chain up from the cloud's frame
            chain.append(parents[frame])
            frame = parents[frame].parent_frame_id
        assert frame == "base_link", chain
        (tf,) = chain  # the run took the sensor at base_link's origin: the identity
        assert (tf.translation.x, tf.translation.y, tf.translation.z) == (0.0, 0.0, 0.0)
        assert (tf.rotation.x, tf.rotation.y, tf.rotation.z, tf.rotation.w) == (0, 0, 0, 1)
    for topic in ("/redrive/detections/cluster-detector", "/redrive/ground_truth"):
        for _, update in decoded[topic]:
            assert all(e.frame_id == "base_link" for e in update.entities), topic


def test_a_sensor_maps_location_places_the_cloud_frame(
    luminar_run: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    sensor_map = tmp_path / "sensors.toml"
    sensor_map.write_text(
        '[sensors.luminar]\ntopic = "/luminar_pointcloud"\ntype = "lidar"\n'
        "location = [1.5, -0.25, 2.75]\n"
    )
    with caplog.at_level(logging.WARNING, logger="redrive.interop.sensor_frames"):
        path = _export(luminar_run, tmp_path / "out", "--sensor-map", str(sensor_map))
    assert not [r for r in caplog.records if "'luminar_lidar'" in r.getMessage()]
    decoded = _decoded(path)
    for _, message in decoded["/redrive/transforms"]:
        (tf,) = [t for t in message.transforms if t.child_frame_id == "luminar_lidar"]
        assert tf.parent_frame_id == "base_link"
        assert (tf.translation.x, tf.translation.y, tf.translation.z) == (1.5, -0.25, 2.75)
        assert (tf.rotation.x, tf.rotation.y, tf.rotation.z, tf.rotation.w) == (0, 0, 0, 1)
    # the same driver: the results stay beside their clouds
    clouds = [t for t, _ in decoded[_CLOUD]]
    assert [t for t, _ in decoded["/redrive/detections/cluster-detector"]] == clouds


def test_a_frame_without_its_own_sample_takes_the_nearest_found_frames_offset() -> None:
    from redrive.interop.log_time import LogTimeAxis

    axis = LogTimeAxis(stamps_ns=(100, 200, 300), offsets_ns=(10, 20, 30))
    assert [axis.log_time_ns(s) for s in (100, 200, 300)] == [110, 220, 330]
    assert [axis.log_time_ns(s) for s in (0, 140, 160, 251, 1000)] == [10, 150, 180, 281, 1030]
    assert LogTimeAxis().log_time_ns(123) == 123  # nothing found: the stamps are the axis
    assert axis.shifted
    assert not LogTimeAxis(stamps_ns=(1,), offsets_ns=(0,)).shifted
