"""Adding a payload type from outside redrive (docs/architecture.md, "Adding a payload type"):
a radar point list defined by a plugin distribution in three files — the payload class, its
decoder, and the entry point that declares the decoder — read from a real MCAP file through
open_log and the Sensor Dispatcher, with no change to redrive."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import get_types_from_msg

from redrive.assembly.frames import FrameAssembler
from redrive.io import open_log
from redrive.io.mcap.writer import McapWriter
from redrive.io.ros.decoders import active_decoders, decoder_for, reload_decoders
from redrive.io.ros.typestore import typestore_for
from redrive.types import SensorData, SensorType
from tests.algorithms.test_discovery import site, unique, write_dist  # noqa: F401 (fixture)

MSGTYPE = "radar_msgs/msg/RadarPointList"
MSGDEF = """
std_msgs/Header header
float32[] range
float32[] azimuth
float32[] doppler
"""

# file 1 of 3: the payload class
PAYLOAD = '''
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from redrive.types import SensorType


@dataclass(frozen=True, slots=True, kw_only=True)
class RadarPointList:
    """Radar detections: range (m), azimuth (rad), Doppler speed (m/s), one array each."""

    sensor_types: ClassVar[frozenset[SensorType]] = frozenset({SensorType.RADAR})
    range_m: npt.NDArray[np.float32]
    azimuth_rad: npt.NDArray[np.float32]
    doppler_mps: npt.NDArray[np.float32]
'''

# file 2 of 3: its decoder
DECODER = """
import numpy as np

from redrive.io.ros.decoders import Decoded, DecodedKind
from redrive.types import SensorType

from {pkg}.payload import RadarPointList


class RadarPointListDecoder:
    name = "radar-point-list"
    msgtypes = ("radar_msgs/msg/RadarPointList",)
    kind = DecodedKind.SENSOR
    sensor_type = SensorType.RADAR

    def decode(self, message, deserialize):
        msg = deserialize(message)
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        value = RadarPointList(
            range_m=np.asarray(msg.range, np.float32),
            azimuth_rad=np.asarray(msg.azimuth, np.float32),
            doppler_mps=np.asarray(msg.doppler, np.float32),
        )
        return Decoded(stamp_ns=stamp or message.log_time_ns, frame_id=msg.header.frame_id,
                       value=value)
"""


def _write_radar_log(path: Path, scans: list[np.ndarray]) -> None:
    store = typestore_for(2)[0]
    store.register(get_types_from_msg(MSGDEF, MSGTYPE))
    cls = store.types[MSGTYPE]
    header_t, time_t = (
        store.types["std_msgs/msg/Header"],
        store.types["builtin_interfaces/msg/Time"],
    )
    with McapWriter(path, typestore=store) as out:
        for i, scan in enumerate(scans):
            stamp = 1_700_000_000_000_000_000 + i * 50_000_000
            msg = cls(
                header=header_t(
                    stamp=time_t(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000),
                    frame_id="radar_front",
                ),
                range=scan[:, 0].astype(np.float32),
                azimuth=scan[:, 1].astype(np.float32),
                doppler=scan[:, 2].astype(np.float32),
            )
            out.write_raw("/radar/points", MSGTYPE, stamp, store.serialize_cdr(msg, MSGTYPE))


def test_a_radar_payload_from_a_plugin_reaches_the_frames(
    site: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    reload_decoders()
    assert decoder_for(MSGTYPE) is None  # redrive alone does not know the type
    pkg = unique("radarpkg")
    write_dist(
        site,
        unique("radar-plugin"),
        # file 3 of 3: the entry point ([project.entry-points."redrive.decoders"] in pyproject)
        entry_points={"radar-point-list": f"{pkg}.decoder:RadarPointListDecoder"},
        modules={
            f"{pkg}/payload.py": PAYLOAD,
            f"{pkg}/decoder.py": DECODER.replace("{pkg}", pkg),
        },
        group="redrive.decoders",
    )
    rng = np.random.default_rng(7)
    scans = [rng.uniform(-1, 50, size=(n, 3)) for n in (4, 9, 1, 6)]
    log_path = tmp_path / "radar.mcap"
    _write_radar_log(log_path, scans)

    reload_decoders()
    try:
        assert decoder_for(MSGTYPE) is not None
        assert "sensor_msgs/msg/PointCloud2" in active_decoders()  # the built-ins stay
        with open_log(log_path) as log:
            frames = list(FrameAssembler(log).frames())
    finally:
        reload_decoders()
    assert len(frames) == len(scans)
    for frame, scan in zip(frames, scans, strict=True):
        (data,) = frame.sensors.values()
        assert isinstance(data, SensorData)
        assert data.sensor_type is SensorType.RADAR
        assert type(data.data).__name__ == "RadarPointList"
        assert data.frame_id == "radar_front"
        np.testing.assert_array_equal(data.data.range_m, scan[:, 0].astype(np.float32))
        np.testing.assert_array_equal(data.data.doppler_mps, scan[:, 2].astype(np.float32))


def test_a_plugin_decoder_that_claims_a_builtin_type_is_left_out(
    site: Path,  # noqa: F811
    caplog: pytest.LogCaptureFixture,
) -> None:
    pkg = unique("clashpkg")
    source = DECODER.replace("{pkg}", pkg).replace(
        '("radar_msgs/msg/RadarPointList",)', '("sensor_msgs/msg/PointCloud2",)'
    )
    write_dist(
        site,
        unique("clash-plugin"),
        entry_points={"clash": f"{pkg}.decoder:RadarPointListDecoder"},
        modules={f"{pkg}/payload.py": PAYLOAD, f"{pkg}/decoder.py": source},
        group="redrive.decoders",
    )
    reload_decoders()
    try:
        with caplog.at_level("WARNING", logger="redrive.io.ros.decoders.registry"):
            pc2 = decoder_for("sensor_msgs/msg/PointCloud2")
        assert pc2 is not None
        assert pc2.name != "radar-point-list"
        assert any(
            "both claim sensor_msgs/msg/PointCloud2" in r.getMessage() for r in caplog.records
        )
    finally:
        reload_decoders()
