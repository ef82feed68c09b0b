"""Velodyne packets → clouds, on nebula's real VLP-16 and VLP-32C bags, against nebula's decoded
reference clouds (../shared/data/velodyne_nebula_ros2, from ``tier4/nebula``
``test_resources/decoder_ground_truth``).

nebula's test (``velodyne_ros_decoder_test_vlp{16,32}.cpp``) feeds every packet of the bag to its
driver with the packet's whole seconds (``pkt.stamp.sec``) and its test parameters, and compares a
cloud it emits during the bag message the PCD is named after.  :class:`NebulaScanAssembler`
replays that with the same parameters; the clouds are compared **by order**: nebula's points
come in packet, block, firing, laser order and so do ours, so the i-th point of each is the same
return.  Matching by nearest neighbour would hide errors here — the sensor stood still, so the
points of one revolution lie within millimetres of the next one's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from redrive.assembly.frames import iter_frames
from redrive.errors import UnsupportedMessageError
from redrive.io import open_log
from redrive.io.base import LogMessage
from redrive.io.ros.decoders import VelodyneScanDecoder, decode, decoder_for
from redrive.io.ros.decoders.velodyne import read_scan_packets
from redrive.io.ros.decoders.velodyne_nebula import NebulaScanAssembler
from redrive.io.ros.decoders.velodyne_packets import VelodyneSettings, decode_packets
from redrive.io.ros.typestore import typestore_for
from redrive.types import PointCloud, SensorType

_MM = 1e-3
_VLP16 = "vlp16/1673400471837873222"
_VLP32 = "vlp32/1713492677464078412"
#: nebula's test parameters (velodyne_ros_decoder_test_vlp16.cpp / _vlp32.cpp)
_NEBULA = {
    _VLP16: (
        "vlp16/1673400472138016708.pcd",
        0.0,
        # "Dual" → DUAL_ONLY: nebula builds its single-return timing table (see VelodyneSettings)
        VelodyneSettings(
            min_range_m=0.3,
            max_range_m=300.0,
            cloud_min_angle_deg=0,
            cloud_max_angle_deg=359,
            dual_timing_table=False,
        ),
    ),
    _VLP32: (
        "vlp32/1713492677464078412.pcd",
        180.0,
        VelodyneSettings(
            min_range_m=0.4, max_range_m=50.0, cloud_min_angle_deg=270, cloud_max_angle_deg=90
        ),
    ),
}


def read_pcd(path: Path) -> np.ndarray:
    """A binary PCD v0.7 file as a structured array."""
    raw = path.read_bytes()
    head, _, data = raw.partition(b"DATA binary\n")
    fields = {
        line.split()[0].decode(): [w.decode() for w in line.split()[1:]]
        for line in head.splitlines()
        if line and not line.startswith(b"#")
    }
    kinds = {"F": "f", "U": "u", "I": "i"}
    dtype = np.dtype(
        [
            (name, "<" + kinds[kind] + size)
            for name, size, kind in zip(
                fields["FIELDS"], fields["SIZE"], fields["TYPE"], strict=True
            )
        ]
    )
    n = int(fields["POINTS"][0])
    return np.frombuffer(data[: n * dtype.itemsize], dtype)


@pytest.fixture(scope="module")
def velodyne(shared_data: Path) -> Path:
    return shared_data / "velodyne_nebula_ros2"


@pytest.mark.parametrize("bag", [_VLP16, _VLP32])
def test_nebula_clouds_equal_the_reference(velodyne: Path, bag: str) -> None:
    """The cloud nebula emits during the PCD's message: same point count, every point within
    1 mm in order (≈ 2e-6 m: float32), and the same intensity / ring / return type / time stamp
    where the PCD has them."""
    pcd, phase, settings = _NEBULA[bag]
    ref = read_pcd(velodyne / pcd)
    wanted = int(Path(pcd).stem)
    assembler = NebulaScanAssembler(scan_phase_deg=phase, settings=settings)
    found = []
    with open_log(velodyne / bag) as log:
        for message in log.messages():
            scan = read_scan_packets(message.raw, message.encoding)
            seconds = (scan.stamps_ns // 1_000_000_000).astype(np.float64)  # nebula: pkt.stamp.sec
            for emitted in assembler.feed(np.asarray(scan.data), seconds):
                if message.log_time_ns == wanted:
                    found.append(emitted.cloud)
    assert len(found) == 1
    cloud = found[0]
    ref_xyz = np.stack([ref["x"], ref["y"], ref["z"]], axis=1)
    assert cloud.xyz.shape == ref_xyz.shape
    assert np.abs(cloud.xyz - ref_xyz).max() < _MM
    if "intensity" in ref.dtype.names:
        assert np.array_equal(cloud.channels["intensity"], ref["intensity"])
        assert np.array_equal(cloud.channels["ring"], ref["channel"])
        assert np.array_equal(cloud.channels["return_type"], ref["return_type"])
        assert np.array_equal(cloud.channels["t_offset_ns"], ref["time_stamp"].astype(np.int64))
        assert np.allclose(cloud.channels["azimuth_rad"], ref["azimuth"], atol=0)
        assert np.allclose(cloud.channels["distance_m"], ref["distance"], atol=0)


def test_scan_decoder_on_nebulas_first_vlp32_cloud(velodyne: Path) -> None:
    """The per-message decoder, set as nebula's test: the VLP-32C bag's first VelodyneScan is
    the cloud nebula emits first (its scan phase of 180° lies in the cropped-out rear)."""
    pcd, _, settings = _NEBULA[_VLP32]
    ref = read_pcd(velodyne / pcd)
    decoder = VelodyneScanDecoder(settings)
    with open_log(velodyne / _VLP32) as log:
        first = next(iter(log.messages()))
        decoded = decoder.decode(first, log.deserialize)
    cloud = decoded.value
    assert isinstance(cloud, PointCloud)
    assert cloud.xyz.shape == (len(ref), 3)
    assert np.abs(cloud.xyz - np.stack([ref["x"], ref["y"], ref["z"]], axis=1)).max() < _MM
    assert decoded.frame_id == "velodyne_front"


@pytest.mark.parametrize(
    ("bag", "model", "lasers"), [(_VLP16, "VLP-16", 16), (_VLP32, "VLP-32C", 32)]
)
def test_registered_decoder_reads_every_scan(
    velodyne: Path, bag: str, model: str, lasers: int
) -> None:
    """Through the registry: each VelodyneScan is one LiDAR cloud of its packets' points; the
    model comes from the factory bytes; the stamp is the header's; the points are the packets'
    (the same as decoding the packets directly)."""
    decoder = decoder_for("velodyne_msgs/msg/VelodyneScan")
    assert isinstance(decoder, VelodyneScanDecoder)
    assert decoder.sensor_type is SensorType.LIDAR
    with open_log(velodyne / bag) as log:
        for message in log.messages():
            decoded = decode(message, log.deserialize)
            msg = log.deserialize(message)
            packets = np.stack([np.asarray(p.data, np.uint8) for p in msg.packets])  # type: ignore[attr-defined]
            points = decode_packets(packets)
            assert points.model.name == model
            cloud = decoded.value
            assert isinstance(cloud, PointCloud)
            assert np.array_equal(cloud.xyz, points.xyz)
            assert int(cloud.channels["ring"].max()) == lasers - 1
            header = msg.header  # type: ignore[attr-defined]
            assert decoded.stamp_ns == header.stamp.sec * 10**9 + header.stamp.nanosec
            t = cloud.channels["t_offset_ns"]
            assert t.min() >= 0
            assert t.max() < 110_000_000


def test_frames_feed_the_dispatcher(velodyne: Path) -> None:
    with open_log(velodyne / _VLP16) as log:
        frames = list(iter_frames(log))
    assert len(frames) == 4
    assert all(isinstance(s.data, PointCloud) for f in frames for s in f.sensors.values())


def _first(velodyne: Path, bag: str) -> tuple[LogMessage, object]:
    with open_log(velodyne / bag) as log:
        message = next(iter(log.messages()))
        return message, log.deserialize(message)


def test_ros1_and_big_endian_cdr_read_the_same_packets(velodyne: Path) -> None:
    message, msg = _first(velodyne, _VLP16)
    cdr = read_scan_packets(message.raw, "cdr")
    ros2 = typestore_for(2)[0]
    big = ros2.serialize_cdr(msg, "velodyne_msgs/msg/VelodyneScan", little_endian=False)
    assert np.array_equal(read_scan_packets(big, "cdr").data, cdr.data)
    ros1, _ = typestore_for(1)
    types = ros1.types
    header = msg.header  # type: ignore[attr-defined]
    time = types["builtin_interfaces/msg/Time"]
    ros1_msg = types["velodyne_msgs/msg/VelodyneScan"](
        header=types["std_msgs/msg/Header"](
            seq=7,
            stamp=time(sec=header.stamp.sec, nanosec=header.stamp.nanosec),
            frame_id=header.frame_id,
        ),
        packets=[
            types["velodyne_msgs/msg/VelodynePacket"](
                stamp=time(sec=p.stamp.sec, nanosec=p.stamp.nanosec), data=p.data
            )
            for p in msg.packets  # type: ignore[attr-defined]
        ],
    )
    scan1 = read_scan_packets(
        ros1.serialize_ros1(ros1_msg, "velodyne_msgs/msg/VelodyneScan"), "ros1"
    )
    assert np.array_equal(scan1.data, cdr.data)
    assert np.array_equal(scan1.stamps_ns, cdr.stamps_ns)
    assert (
        (scan1.stamp_ns, scan1.frame_id)
        == (cdr.stamp_ns, cdr.frame_id)
        == (
            header.stamp.sec * 10**9 + header.stamp.nanosec,
            "velodyne",
        )
    )


def test_truncated_scan_is_a_clear_error(velodyne: Path) -> None:
    message, _ = _first(velodyne, _VLP16)
    short = LogMessage(
        topic=message.topic,
        msgtype=message.msgtype,
        log_time_ns=message.log_time_ns,
        encoding="cdr",
        raw=bytes(message.raw)[:50_000],
    )
    with pytest.raises(
        UnsupportedMessageError, match=r"151 packets need .* bytes, the message has 50000"
    ):
        VelodyneScanDecoder().decode(short, lambda m: None)
    with pytest.raises(UnsupportedMessageError, match="truncated"):
        VelodyneScanDecoder().decode(
            LogMessage(
                topic="/v",
                msgtype=message.msgtype,
                log_time_ns=1,
                encoding="cdr",
                raw=bytes(message.raw)[:10],
            ),
            lambda m: None,
        )


def test_damaged_packets(velodyne: Path) -> None:
    """A bad block flag ends a VLP-16 packet (nebula: "skip the rest"), an azimuth ≥ 36000 skips
    its block, a product id of no known model is refused with the ids redrive knows."""
    _, msg = _first(velodyne, _VLP16)
    packets = np.stack([np.asarray(p.data, np.uint8) for p in msg.packets])  # type: ignore[attr-defined]
    whole = decode_packets(packets)
    bad = packets.copy()
    bad[5, 6 * 100] = 0x00  # block 6 of packet 5: flag 0xFF → 0x00
    bad[9, 3 * 100 + 2 : 3 * 100 + 4] = 0xFF  # block 3 of packet 9: azimuth 65535
    points = decode_packets(bad)
    in_packet = np.bincount(points.packet, minlength=len(packets))
    full = np.bincount(whole.packet, minlength=len(packets))
    assert in_packet[5] < full[5]
    assert in_packet[9] < full[9]
    others = np.ones(len(packets), bool)
    others[[5, 9]] = False
    assert np.array_equal(in_packet[others], full[others])
    unknown = packets.copy()
    unknown[:, 1205] = 0x99
    with pytest.raises(ValueError, match=r"0x99 .*0x22 VLP-16"):
        decode_packets(unknown)
    mixed = packets.copy()
    mixed[3, 1204] = 0x37
    with pytest.raises(ValueError, match="disagree"):
        decode_packets(mixed)
    with pytest.raises(ValueError, match="1206 bytes"):
        decode_packets(packets[:, :1200])


def test_geometry_of_a_hand_made_vlp16_packet() -> None:
    """The documented layout by hand: block b at azimuth 0.20°·b, every return 1000 × 2 mm; laser
    0 (−15°) of the first firing lies at (r cos ω, 0, r sin ω); the second firing is half a block
    step (0.10°) later; the last block has no step (nebula), x forward, y left."""
    packet = bytearray()
    for block in range(12):
        packet += bytes([0xFF, 0xEE, block * 20, 0]) + bytes([0xE8, 0x03, 9]) * 32
    packet += bytes([0, 0, 0, 0, 0x37, 0x22])
    points = decode_packets(np.frombuffer(bytes(packet), np.uint8).reshape(1, -1))
    assert points.model.name == "VLP-16"
    assert points.xyz.shape == (12 * 32, 3)
    omega = np.radians(-15.0)
    assert np.allclose(points.xyz[0], [2 * np.cos(omega), 0.0, 2 * np.sin(omega)], atol=1e-6)
    # block 0, firing 1, laser 0: 20 · 55.296 / 110.592 = 10 hundredths of a degree
    assert points.azimuth_centideg[16] == 10
    alpha = np.radians(0.10)
    expected = [
        2 * np.cos(omega) * np.cos(alpha),
        -2 * np.cos(omega) * np.sin(alpha),
        2 * np.sin(omega),
    ]
    assert np.allclose(points.xyz[16], expected, atol=1e-6)
    assert np.all(points.azimuth_centideg[11 * 32 :] == 220)  # the last block: no step
    assert np.array_equal(points.ring[:16], [0, 8, 1, 9, 2, 10, 3, 11, 4, 12, 5, 13, 6, 14, 7, 15])
    assert np.all(points.distance_m == np.float32(2.0))


def test_the_odd_vli16_packet_is_refused_clearly(shared_data: Path) -> None:
    """ouster-sdk's non-Ouster test packet (../shared/data/ouster/VLI-16-one-packet.pcap): a
    Velodyne-style payload of 1212 bytes, not the VLP-16's 1206, with unusual factory bytes."""
    from ._ouster_data import pcap_udp_payloads

    (payload,) = pcap_udp_payloads(shared_data / "ouster" / "VLI-16-one-packet.pcap", port=2368)
    packet = np.frombuffer(payload, np.uint8)
    assert bytes(packet[:2]) == b"\xff\xee"
    with pytest.raises(ValueError, match=r"1206 bytes, got an array of shape \(1, 1212\)"):
        decode_packets(packet.reshape(1, -1))
    with pytest.raises(ValueError, match="product id 0x1e"):
        decode_packets(packet[:1206].reshape(1, -1))
