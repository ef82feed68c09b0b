"""Sensor rig: TOML parsing, defaults, errors that say where and what to do."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from redrive.errors import ConfigError
from redrive.sim.rig import default_rig, rig_from_mapping
from redrive.types import SensorType

RIG_TOML = """
[rig.lidar_top]
kind = "lidar"
preset = "HDL-32E"
xyz = [1.2, 0, 1.9]
rpy = [0, 0, 0]
rate_hz = 10
noise = { range_std_m = 0.02, dropout = 0.01 }

[rig.camera_front]
kind = "camera"
xyz = [1.5, 0, 1.6]
rpy = [0, 0.1, 0]
rate_hz = 10
width = 1280
height = 720
fx = 1000
fy = 1000
"""


def test_parse_toml_table() -> None:
    rig = rig_from_mapping(tomllib.loads(RIG_TOML)["rig"], source="rig.toml")
    assert rig.names == ("lidar_top", "camera_front")
    lidar = rig["lidar_top"]
    assert lidar.kind is SensorType.LIDAR
    assert lidar.preset == "HDL-32E"
    assert lidar.noise["range_std_m"] == 0.02
    assert np.allclose(lidar.base_from_sensor()[:3, 3], [1.2, 0.0, 1.9])
    cam = rig["camera_front"]
    assert cam.camera is not None
    assert (cam.camera.width, cam.camera.height, cam.camera.fx) == (1280, 720, 1000.0)
    assert cam.camera.cx == pytest.approx(639.5)
    # pitched down 0.1 rad: the optical axis (z) points forward and down
    optical_z = cam.base_from_optical()[:3, 2]
    assert optical_z[0] == pytest.approx(math.cos(0.1))
    assert optical_z[2] == pytest.approx(-math.sin(0.1))


def test_default_rig() -> None:
    rig = default_rig()
    kinds = {s.name: (s.kind, s.rate_hz) for s in rig}
    assert kinds == {
        "lidar_top": (SensorType.LIDAR, 10.0),
        "lidar_2d": (SensorType.LIDAR_2D, 20.0),
        "camera_front": (SensorType.CAMERA, 10.0),
        "imu": (SensorType.IMU, 100.0),
        "gnss": (SensorType.GNSS, 10.0),
        "odom": (SensorType.ODOMETRY, 50.0),
    }
    assert rig["lidar_top"].preset == "HDL-32E"
    assert rig.of_kind(SensorType.CAMERA)[0].camera is not None
    with pytest.raises(KeyError, match="lidar_top"):
        rig["radar"]


@pytest.mark.parametrize(
    ("table", "words"),
    [
        ({"s": {"kind": "sonar", "rate_hz": 1}}, ["rig.toml", "[rig.s] kind", "use one of"]),
        ({"s": {"kind": "lidar", "rate_hz": 0}}, ["rate_hz", "> 0"]),
        ({"s": {"kind": "lidar", "rate_hz": 10, "preset": "X"}}, ["preset", "HDL-32E"]),
        ({"s": {"kind": "lidar_2d", "rate_hz": 10, "preset": "VLP-16"}}, ["preset", "UTM-30LX"]),
        ({"s": {"kind": "lidar", "rate_hz": 10, "xyz": [1, 2]}}, ["xyz", "[x, y, z]"]),
        ({"s": {"kind": "imu", "rate_hz": 10, "colour": 1}}, ["colour", "unknown key"]),
        ({"s": {"kind": "imu", "rate_hz": 10, "noise": {"x": 1}}}, ["noise.x", "gyro_std_rad_s"]),
        ({"s": {"kind": "lidar", "rate_hz": 10, "noise": {"dropout": 2}}}, ["dropout", "[0, 1]"]),
        ({"s": {"kind": "camera", "rate_hz": 10, "height": 4, "fx": 1, "fy": 1}}, ["width"]),
        ({"s": 3}, ["not a table"]),
        ({}, ["at least one"]),
    ],
)
def test_bad_input_names_source_key_and_fix(table: dict[str, object], words: list[str]) -> None:
    with pytest.raises(ConfigError) as err:
        rig_from_mapping(table, source="rig.toml")
    for word in words:
        assert word in str(err.value)
    assert "rig.toml" in str(err.value)
