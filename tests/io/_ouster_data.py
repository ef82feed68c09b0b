"""The real Ouster data of ../shared/data/ouster as (metadata JSON, lidar packets) per dataset."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import numpy.typing as npt

from redrive.io import open_log

BAG = "512x10_raw.bag"
PCAPS = ("OS-0-128-U1_v2.3.0_1024x10", "OS-1-32-G_v2.1.1_1024x10", "OS-2-32-U0_v2.0.0_1024x10")
LIDAR_PORT = 7502


def pcap_udp_payloads(path: Path, *, port: int) -> list[bytes]:
    """The UDP payloads to ``port`` in a classic little-endian Ethernet pcap (unfragmented IPv4,
    as these captures are)."""
    data = path.read_bytes()
    magic, link = struct.unpack_from("<I", data, 0)[0], struct.unpack_from("<I", data, 20)[0]
    assert magic == 0xA1B2C3D4, hex(magic)
    assert link == 1, link  # Ethernet
    out, pos = [], 24
    while pos + 16 <= len(data):
        _, _, captured, _ = struct.unpack_from("<IIII", data, pos)
        record = data[pos + 16 : pos + 16 + captured]
        pos += 16 + captured
        if struct.unpack_from(">H", record, 12)[0] != 0x0800 or record[23] != 17:
            continue
        ip_header = (record[14] & 0x0F) * 4
        _, dst, length = struct.unpack_from(">HHH", record, 14 + ip_header)
        if dst == port:
            start = 14 + ip_header + 8
            out.append(record[start : start + length - 8])
    return out


def datasets(root: Path) -> dict[str, tuple[str, npt.NDArray[np.uint8]]]:
    """name → (metadata JSON, uint8 (P, size) lidar packets): the bag and the three pcaps."""
    out: dict[str, tuple[str, npt.NDArray[np.uint8]]] = {}
    with open_log(root / BAG, packets="raw") as log:
        meta = [str(log.deserialize(m).data) for m in log.messages(topics=["/os_node0/metadata"])]  # type: ignore[attr-defined]
        packets = [
            np.asarray(log.deserialize(m).buf, np.uint8)  # type: ignore[attr-defined]
            for m in log.messages(topics=["/os_node0/lidar_packets"])
        ]
    out["bag"] = (meta[0], np.stack(packets))
    for stem in PCAPS:
        payloads = pcap_udp_payloads(root / f"{stem}.pcap", port=LIDAR_PORT)
        packets_array = np.stack([np.frombuffer(p, np.uint8) for p in payloads])
        out[stem] = ((root / f"{stem}.json").read_text(encoding="utf-8"), packets_array)
    return out


def write_job(root: Path, path: Path) -> None:
    """The job file of ``ouster_sdk_reference.py``."""
    arrays: dict[str, object] = {}
    for name, (meta, packets) in datasets(root).items():
        arrays[f"{name}/metadata"] = np.array(meta)
        arrays[f"{name}/packets"] = packets
    np.savez(path, **arrays)  # type: ignore[arg-type]
