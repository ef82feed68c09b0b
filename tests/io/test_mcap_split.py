"""Split MCAP files (redrive.io.mcap.split) and reading them back as one log (redrive.io.mcap.fileset),
without ROS: real ROS 1 messages serialised with rosbags, written by the writer redrive live uses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from redrive.errors import LogError
from redrive.io import open_log
from redrive.io.mcap.split import Ros1Schema, SplitMcapWriter
from redrive.io.ros.typestore import typestore_for


def _imu_messages(n: int) -> tuple[Ros1Schema, list[bytes]]:
    store = typestore_for(1, needed=["sensor_msgs/msg/Imu"])[0]
    text, md5 = store.generate_msgdef("sensor_msgs/msg/Imu", ros_version=1)
    imu_t = store.types["sensor_msgs/msg/Imu"]
    header_t = store.types["std_msgs/msg/Header"]
    time_t = store.types["builtin_interfaces/msg/Time"]
    vec_t = store.types["geometry_msgs/msg/Vector3"]
    quat_t = store.types["geometry_msgs/msg/Quaternion"]
    rng = np.random.default_rng(1)
    out = []
    for i in range(n):
        cov = rng.random(9)
        msg = imu_t(
            header=header_t(seq=i, stamp=time_t(sec=i, nanosec=0), frame_id="imu"),
            orientation=quat_t(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=cov,
            angular_velocity=vec_t(x=float(i), y=0.0, z=0.0),
            angular_velocity_covariance=cov,
            linear_acceleration=vec_t(x=0.0, y=0.0, z=9.81),
            linear_acceleration_covariance=cov,
        )
        out.append(bytes(store.serialize_ros1(msg, "sensor_msgs/msg/Imu")))
    schema = Ros1Schema(msg_type="sensor_msgs/Imu", md5sum=md5, text=text)
    return schema, out


def _write(path: Path, messages: list[bytes], schema: Ros1Schema, **split: float) -> list[Path]:
    writer = SplitMcapWriter(path, **split)  # type: ignore[arg-type]
    for i, data in enumerate(messages):
        topic = "/imu" if i % 3 else "/imu2"
        writer.write(topic, schema, log_ns=1_000 + i, publish_ns=1_000 + i, data=data)
    return writer.close()


def _read(path: Path) -> list[tuple[str, int, bytes]]:
    with open_log(path) as log:
        return [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages()]


def test_split_files_are_valid_alone_and_equal_the_unsplit_file(tmp_path: Path) -> None:
    schema, messages = _imu_messages(300)
    whole = _write(tmp_path / "whole.mcap", messages, schema)
    (tmp_path / "split").mkdir()
    parts = _write(tmp_path / "split" / "rec.mcap", messages, schema, split_size_bytes=16 << 10)
    assert whole == [tmp_path / "whole.mcap"]
    assert len(parts) >= 3
    assert [p.name for p in parts] == [f"rec_{i:04d}.mcap" for i in range(len(parts))]
    assert sorted((tmp_path / "split").iterdir()) == parts  # no part left behind
    alone = [m for p in parts for m in _read(p)]  # each file opens by itself
    want = _read(whole[0])
    assert alone == want
    assert _read(tmp_path / "split") == want  # the folder as one log
    assert _read(tmp_path / "split" / "rec_*.mcap") == want  # a glob
    with open_log(tmp_path / "split") as log:
        assert log.format == "mcap-set"
        assert log.topics["/imu"].count == 200
        assert log.message_count == 300
        first = log.deserialize(next(log.messages(topics=["/imu"])))
        assert first.angular_velocity.x == 1.0  # type: ignore[attr-defined]


def test_split_duration_starts_new_files(tmp_path: Path) -> None:
    schema, messages = _imu_messages(4)
    parts = _write(tmp_path / "r.mcap", messages, schema, split_duration_s=0.0)
    assert len(parts) == 4  # a file is never empty: each gets one message before it is full
    assert [len(_read(p)) for p in parts] == [1, 1, 1, 1]


def test_a_glob_that_names_nothing(tmp_path: Path) -> None:
    with pytest.raises(LogError, match="names none"):
        open_log(tmp_path / "nothing_*.mcap")


def test_the_recorder_stops_at_max_size_and_takes_streams_added_later(tmp_path: Path) -> None:
    """DataLogger on real shared-memory streams, in process: a stream added while it records is
    recorded, definitions come from the callback, and ``full`` is set at --max-size."""
    import os

    from redrive.live.recorder import DataLogger
    from redrive.live.scraper_state import Ros1Definition
    from redrive.live.streams import StreamSpec
    from redrive.transport import Policy, Writer
    from redrive.transport.codec import KIND_ROS1, encode_ros1_meta

    schema, messages = _imu_messages(40)
    specs = [
        StreamSpec(topic=t, msgtype="sensor_msgs/msg/Imu", stream=f"t{os.getpid()}.{n}",
                   payload="ros1", capacity_bytes=1 << 16)
        for n, t in (("a", "/a"), ("b", "/b"))
    ]  # fmt: skip
    writers = [Writer(s.stream, capacity_bytes=1 << 16, slots=4, policy=Policy.LOSSLESS)
               for s in specs]  # fmt: skip
    definition = Ros1Definition(msg_type="sensor_msgs/Imu", md5sum=schema.md5sum, text=schema.text)
    size = sum(len(m) for m in messages[:30])
    recorder = DataLogger(
        specs[:1], tmp_path / "r.mcap", definitions=lambda _topic: definition, max_size_bytes=size
    )
    try:
        recorder.add(specs[1])
        meta = {s.topic: encode_ros1_meta(s.topic, "sensor_msgs/Imu", schema.md5sum) for s in specs}
        for i, data in enumerate(messages[:30]):
            spec, writer = (specs[i % 2], writers[i % 2])
            writer.publish(data, stamp_ns=i + 1, kind=KIND_ROS1, meta=meta[spec.topic])
        assert recorder.full.wait(20)
    finally:
        for writer in writers:
            writer.close()
        recorder.stop()
    assert recorder.recorded == {"/a": 15, "/b": 15}
    assert len(_read(tmp_path / "r.mcap")) == 30
    assert recorder.chunks[0] >= 1  # (chunks, written uncompressed) of the finished file
    assert not list(tmp_path.glob(".*.part"))


def test_chunks_are_counted_over_every_file(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    schema, messages = _imu_messages(300)
    writer = SplitMcapWriter(tmp_path / "r.mcap", split_size_bytes=16 << 10, compression="none")
    for i, data in enumerate(messages):
        writer.write("/imu", schema, log_ns=i, publish_ns=i, data=data)
    parts = writer.close()
    in_files = 0
    for part in parts:
        with part.open("rb") as fh:
            summary = make_reader(fh).get_summary()
            assert summary is not None
            in_files += len(summary.chunk_indexes)
    assert len(parts) >= 3
    assert writer.chunks == (in_files, 0)
