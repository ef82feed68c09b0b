"""Ouster lidar packets → clouds, on the real captures of ../shared/data/ouster, against
ouster-sdk's own decoding.

ouster-sdk cannot be installed beside redrive (it pins ``rosbags==0.9.23``), so its decoding of
the four captures is stored: ``data/ouster_sdk_reference.npz``, made by
``ouster_sdk_reference.py --sample 400`` with ouster-sdk 1.0.1 (the SHA-256 of each whole range
image, the number of returns and the xyz of 400 pixels with a return).  With
``REDRIVE_OUSTER_SDK_PYTHON`` naming an interpreter that has ouster-sdk, the full comparison
runs too: every pixel's range and every point.
"""

from __future__ import annotations

import hashlib
import logging
import os
import subprocess
import sys
from collections.abc import Collection, Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from redrive.assembly.frames import iter_frames
from redrive.io import open_log
from redrive.io.base import LogMessage, TopicInfo
from redrive.io.ros.decoders import decode, topic_kind
from redrive.io.ros.decoders.base import DecodedKind
from redrive.io.ros.decoders.ouster_log import PacketCloudsReader, with_packet_clouds
from redrive.io.ros.decoders.ouster_metadata import parse_metadata
from redrive.io.ros.decoders.ouster_packets import OusterPacketFormat
from redrive.types import PointCloud, SensorType

from ._ouster_data import BAG, PCAPS, datasets, write_job

_REFERENCE = Path(__file__).parent / "data" / "ouster_sdk_reference.npz"
_PACKETS = "/os_node0/lidar_packets"
_TOPIC = "/os_node0/points"  # the clouds made of them
_NAMES = ("bag", *PCAPS)
_MM = 1e-3


@pytest.fixture(scope="module")
def ouster(shared_data: Path) -> Path:
    return shared_data / "ouster"


@pytest.fixture(scope="module")
def data(ouster: Path) -> dict[str, tuple[str, np.ndarray]]:
    return datasets(ouster)


def _decode(meta: str, packets: np.ndarray) -> tuple[OusterPacketFormat, np.ndarray, PointCloud]:
    fmt = OusterPacketFormat(parse_metadata(meta))
    frame_ids = [fmt.frame_id(p) for p in packets]
    first = [p for p, f in zip(packets, frame_ids, strict=True) if f == frame_ids[0]]
    frame = fmt.decode(first)
    return fmt, frame.fields["range"].reshape(-1), fmt.cloud(frame)


@pytest.mark.parametrize("name", _NAMES)
def test_frames_equal_ouster_sdk(data: dict[str, tuple[str, np.ndarray]], name: str) -> None:
    """Each capture's frame: the range image equals ouster-sdk's pixel for pixel (its SHA-256),
    the cloud has one point per return and the sampled points are within 1 mm of ouster-sdk's
    (matched by pixel: both are row-major over the measured range image)."""
    ref = np.load(_REFERENCE)
    meta, packets = data[name]
    _, rng, cloud = _decode(meta, packets)
    assert hashlib.sha256(rng.tobytes()).hexdigest() == str(ref[f"{name}/range_sha256"])
    assert cloud.xyz.shape[0] == int(ref[f"{name}/returns"]) == int((rng > 0).sum())
    hits = np.flatnonzero(rng)
    rows = np.searchsorted(hits, ref[f"{name}/index"])
    assert np.array_equal(hits[rows], ref[f"{name}/index"])
    assert np.abs(cloud.xyz[rows] - ref[f"{name}/xyz"]).max() < _MM


def test_profiles_covered(data: dict[str, tuple[str, np.ndarray]]) -> None:
    """The captures span the LEGACY and low-data-rate profiles and both metadata layouts."""
    profiles = {name: parse_metadata(data[name][0]).udp_profile_lidar for name in _NAMES}
    assert profiles == {
        "bag": "RNG15_RFL8_NIR8",
        PCAPS[0]: "RNG15_RFL8_NIR8",
        PCAPS[1]: "LEGACY",
        PCAPS[2]: "LEGACY",
    }
    bag_info = parse_metadata(data["bag"][0])
    assert (bag_info.columns_per_frame, bag_info.pixels_per_column) == (512, 128)
    assert bag_info.prod_line == "OS-0-128"


@pytest.mark.skipif(
    not os.environ.get("REDRIVE_OUSTER_SDK_PYTHON"),
    reason="REDRIVE_OUSTER_SDK_PYTHON names no interpreter with ouster-sdk",
)
def test_every_point_equals_ouster_sdk(ouster: Path, tmp_path: Path) -> None:
    """With ouster-sdk at hand: every pixel and every point of the four frames."""
    job, out = tmp_path / "job.npz", tmp_path / "out.npz"
    write_job(ouster, job)
    script = Path(__file__).parent / "ouster_sdk_reference.py"
    python = os.environ["REDRIVE_OUSTER_SDK_PYTHON"]
    subprocess.run([python, str(script), str(job), str(out)], check=True, timeout=300)
    ref = np.load(out)
    for name, (meta, packets) in datasets(ouster).items():
        _, rng, cloud = _decode(meta, packets)
        assert np.array_equal(rng, ref[f"{name}/range"]), name
        hits = np.flatnonzero(rng)
        assert np.abs(cloud.xyz - ref[f"{name}/xyz"][hits]).max() < _MM, name


def test_bag_has_a_lidar_cloud_topic_beside_its_packets(ouster: Path) -> None:
    """``open_log``: beside the packet topic, a LiDAR topic of one 512×10 frame; the frame's cloud
    comes through ``decode`` with its channels; the packets stay readable; ``packets="raw"``
    adds nothing."""
    with open_log(ouster / BAG) as log:
        assert isinstance(log, PacketCloudsReader)
        assert log.cloud_topics == {_TOPIC: _PACKETS}
        info = log.topics[_TOPIC]
        assert topic_kind(info) == (DecodedKind.SENSOR, SensorType.LIDAR)
        assert info.count == 1
        assert log.topics[_PACKETS].encoding == "ros1"
        assert log.topics[_PACKETS].count == 32
        messages = list(log.messages(topics=[_TOPIC]))
        assert len(messages) == 1
        decoded = decode(messages[0], log.deserialize)
        cloud = decoded.value
        assert isinstance(cloud, PointCloud)
        assert decoded.frame_id == "os_sensor"
        assert decoded.stamp_ns == log.start_ns  # the frame's first packet
        assert cloud.xyz.shape == (28751, 3)
        assert set(cloud.channels) >= {"intensity", "reflectivity", "near_ir", "ring", "column"}
        assert int(cloud.channels["ring"].max()) == 127
        assert int(cloud.channels["column"].max()) == 511
        assert "/os_node0/imu_points" not in log.topics  # imu_packets: not lidar data
        everything = list(log.messages())
        assert [m.log_time_ns for m in everything] == sorted(m.log_time_ns for m in everything)
        seen = {t: sum(m.topic == t for m in everything) for t in log.topics}
        assert seen == {t: i.count for t, i in log.topics.items()}
        assert len(list(log.messages(topics=[_PACKETS]))) == 32
        assert list(log.messages(topics=[_TOPIC], start_ns=log.end_ns + 1)) == []
        assert len(list(log.messages(topics=[_TOPIC], start_ns=log.start_ns + 1))) == 1
    with open_log(ouster / BAG, packets="raw") as log:
        assert _TOPIC not in log.topics


def test_frames_feed_the_dispatcher(ouster: Path) -> None:
    """The frame assembler drives frames from the Ouster cloud (what `redrive run` does)."""
    with open_log(ouster / BAG) as log:
        frames = list(iter_frames(log))
    assert len(frames) == 1
    (sensor,) = frames[0].sensors.values()
    assert sensor.sensor_type is SensorType.LIDAR
    assert isinstance(sensor.data, PointCloud)
    assert sensor.data.xyz.shape[0] == 28751


class _FakeLog:
    """A reader over given (topic, msgtype, log time, deserialised object) records."""

    def __init__(self, records: list[tuple[str, str, int, Any]]) -> None:
        self.path = Path("fake.bag")
        self.format = "ros1"
        self.records = records
        self.topics = {
            t: TopicInfo(topic=t, msgtype=m, count=sum(r[0] == t for r in records), encoding="ros1")
            for t, m, _, _ in records
        }
        self.start_ns = records[0][2]
        self.end_ns = records[-1][2]

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        for i, (topic, msgtype, t, _) in enumerate(self.records):
            if topics is not None and topic not in topics:
                continue
            if (start_ns is not None and t < start_ns) or (stop_ns is not None and t >= stop_ns):
                continue
            yield LogMessage(
                topic=topic,
                msgtype=msgtype,
                log_time_ns=t,
                encoding="ros1",
                raw=bytes([i % 256]) * 4,
            )

    def deserialize(self, message: LogMessage) -> object:
        return next(
            r[3] for r in self.records if r[0] == message.topic and r[2] == message.log_time_ns
        )

    def close(self) -> None:
        pass


def _fake(meta: str | None, packets: list[bytes]) -> _FakeLog:
    records: list[tuple[str, str, int, Any]] = []
    if meta is not None:
        records.append(("/os/metadata", "std_msgs/msg/String", 1, SimpleNamespace(data=meta)))
    for k, buf in enumerate(packets):
        records.append(
            (
                "/os/lidar_packets",
                "ouster_ros/msg/PacketMsg",
                10 + k,
                SimpleNamespace(buf=np.frombuffer(buf, np.uint8)),
            )
        )
    return _FakeLog(records)


def test_damaged_packets_are_left_out_with_a_warning(
    data: dict[str, tuple[str, np.ndarray]], caplog: pytest.LogCaptureFixture
) -> None:
    """A truncated and an over-long packet: left out, named in one warning, counted; the frame
    still comes from the intact packets, with the damaged packets' columns empty."""
    meta, packets = data["bag"]
    raw = [bytes(p) for p in packets]
    damaged = list(raw)
    damaged[3] = raw[3][:1000]
    damaged[7] = raw[7] + b"\0"
    log = with_packet_clouds(_fake(meta, damaged))  # type: ignore[arg-type]
    assert isinstance(log, PacketCloudsReader)
    with caplog.at_level(logging.WARNING):
        (message,) = list(log.messages(topics=["/os/points"]))
    assert log.packet_damage == {"/os/lidar_packets": 2}
    text = caplog.text
    assert "1000 bytes" in text
    assert "8448" in text
    assert "left out" in text
    cloud = message.payload.value  # type: ignore[union-attr]
    _, _rng, whole = _decode(meta, packets)
    columns = set(np.unique(cloud.channels["column"]).tolist())
    assert not columns & set(range(3 * 16, 4 * 16))
    assert not columns & set(range(7 * 16, 8 * 16))
    assert 0 < cloud.xyz.shape[0] < whole.xyz.shape[0]


def test_without_usable_metadata_the_topic_stays_raw(
    data: dict[str, tuple[str, np.ndarray]], caplog: pytest.LogCaptureFixture
) -> None:
    meta, packets = data["bag"]
    raw = [bytes(p) for p in packets[:2]]
    with caplog.at_level(logging.WARNING):
        no_meta = _fake(None, raw)
        assert with_packet_clouds(no_meta) is no_meta  # type: ignore[arg-type, comparison-overlap]
        garbled = _fake(meta[:100], raw)
        assert with_packet_clouds(garbled) is garbled  # type: ignore[arg-type, comparison-overlap]
    assert "no metadata topic" in caplog.text
    assert "not JSON" in caplog.text


def test_frames_split_by_frame_id(data: dict[str, tuple[str, np.ndarray]]) -> None:
    """Two frames' packets (the frame id rewritten in the second copy) make two clouds; a frame
    cut short by the next frame id is yielded when that id comes."""
    meta, packets = data["bag"]
    first = [bytes(p) for p in packets]
    second = []
    for p in first:
        b = bytearray(p)
        b[2:4] = (int.from_bytes(p[2:4], "little") + 1).to_bytes(2, "little")
        second.append(bytes(b))
    log = with_packet_clouds(_fake(meta, first[:20] + second))  # type: ignore[arg-type]
    messages = list(log.messages(topics=["/os/points"]))
    assert len(messages) == 2
    counts = [m.payload.value.xyz.shape[0] for m in messages]  # type: ignore[union-attr]
    assert counts[1] == 28751
    assert 0 < counts[0] < counts[1]
    assert messages[0].log_time_ns == 10 + 20  # when the second frame's first packet came


def test_unknown_profile_is_refused(data: dict[str, tuple[str, np.ndarray]]) -> None:
    meta, _ = data["bag"]
    text = meta.replace('"RNG15_RFL8_NIR8"', '"RNG19_RFL8_SIG16_NIR16_RGB16"')
    with pytest.raises(ValueError, match="not one redrive decodes"):
        OusterPacketFormat(parse_metadata(text))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__]))
