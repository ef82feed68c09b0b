"""Ouster sensor metadata (the JSON a sensor serves and ``ouster_ros`` publishes) and its XYZ
lookup table.

Both metadata layouts are read, as ouster-sdk reads them (``ouster_core/src/metadata.cpp``):
the current one (``sensor_info``, ``beam_intrinsics``, ``imu_intrinsics``, ``lidar_intrinsics``,
``config_params``, ``lidar_data_format``) and the flat one of firmware before 2.4
(``beam_altitude_angles`` … at the top, ``data_format``), which ouster-sdk converts to the current
one (``convert_legacy_to_nonlegacy``).  Defaults are ouster-sdk's: a missing
``lidar_to_sensor_transform`` is ``DEFAULT_LIDAR_TO_SENSOR`` (x and y flipped, z 36.18 mm), a
missing ``beam_to_lidar_transform`` the identity with x = ``lidar_origin_to_beam_origin_mm``
(itself defaulting by product line, ``default_lidar_origin_to_beam_origin``), a missing
``udp_profile_lidar`` LEGACY.

The lookup table is ouster-sdk's ``make_xyz_lut`` (``ouster_core/src/xyzlut.cpp``): for the
pixel in row ``r`` (beam) and column ``c`` of the measured ("staggered") range image, with
encoder angle ``θe = 2π − 2π c / W``, beam azimuth ``θa = −azimuth_deg[r]`` and altitude
``φ = altitude_deg[r]``::

    direction = (cos(θe + θa) cos φ, sin(θe + θa) cos φ, sin φ)
    offset    = (cos θe · b₀ − direction_x · d, sin θe · b₀ − direction_y · d, −direction_z · d + b₂)

with ``b₀``, ``b₂`` the x and z of ``beam_to_lidar_transform`` (mm) and ``d`` = √(b₀² + b₂²)
(``b₀`` when ``b₂`` = 0); both are rotated by ``lidar_to_sensor_transform`` and the offset
translated by it, then scaled to metres.  A pixel of range ``ρ`` mm lies at
``ρ · direction + offset`` in the sensor frame (``os_sensor``); range 0 is no return.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["OusterSensorInfo", "parse_metadata", "xyz_lut"]

_NEW_FORMAT_KEYS = (
    "sensor_info",
    "beam_intrinsics",
    "imu_intrinsics",
    "lidar_intrinsics",
    "config_params",
)
_DEFAULT_LIDAR_TO_SENSOR = (-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 36.18, 0, 0, 0, 1)
_RANGE_UNIT_M = 0.001


@dataclass(frozen=True, slots=True, kw_only=True)
class OusterSensorInfo:
    """What decoding a sensor's lidar packets needs from its metadata.

    Attributes:
        prod_line: ``OS-0-128`` …
        firmware: ``build_rev`` (``v2.3.0``), "" when absent.
        udp_profile_lidar: the packet profile (``LEGACY``, ``RNG19_RFL8_SIG16_NIR16`` …).
        header_type: ``STANDARD`` or ``FUSA``.
        columns_per_frame, pixels_per_column, columns_per_packet: W, H and columns a packet.
        column_window: the first and last column the sensor sends.
        altitude_deg, azimuth_deg: (H,) each beam's altitude and azimuth offset, degrees.
        beam_to_lidar: (4, 4) mm.
        lidar_to_sensor: (4, 4) mm.
    """

    prod_line: str
    firmware: str
    udp_profile_lidar: str
    header_type: str
    columns_per_frame: int
    pixels_per_column: int
    columns_per_packet: int
    column_window: tuple[int, int]
    altitude_deg: npt.NDArray[np.float64]
    azimuth_deg: npt.NDArray[np.float64]
    beam_to_lidar: npt.NDArray[np.float64]
    lidar_to_sensor: npt.NDArray[np.float64]


def _default_beam_origin_mm(prod_line: str) -> float:
    for prefix, value in (("OS-0-", 27.67), ("OS-1-", 15.806), ("OS-2-", 13.762)):
        if prod_line.startswith(prefix):
            return value
    return 12.163  # ouster-sdk: "default for gen 1"


def _to_new_format(root: Mapping[str, Any]) -> dict[str, Any]:
    """ouster-sdk's ``convert_legacy_to_nonlegacy``: the flat layout regrouped."""
    out: dict[str, Any] = {}
    groups = {
        "config_params": ("udp_port_imu", "udp_port_lidar", "lidar_mode"),
        "beam_intrinsics": (
            "lidar_origin_to_beam_origin_mm",
            "beam_altitude_angles",
            "beam_azimuth_angles",
            "beam_to_lidar_transform",
        ),
        "sensor_info": (
            "prod_line",
            "status",
            "prod_pn",
            "prod_sn",
            "initialization_id",
            "build_rev",
        ),
    }
    taken: set[str] = set()
    if "lidar_to_sensor_transform" in root:
        out["lidar_intrinsics"] = {"lidar_to_sensor_transform": root["lidar_to_sensor_transform"]}
        taken.add("lidar_to_sensor_transform")
    if "data_format" in root:
        out["lidar_data_format"] = root["data_format"]
        taken.add("data_format")
    for group, keys in groups.items():
        for key in keys:
            if key in root:
                out.setdefault(group, {})[key] = root[key]
                taken.add(key)
    for key, value in root.items():
        if key not in taken:
            out.setdefault(key, value)
    return out


def _matrix(values: object, what: str) -> npt.NDArray[np.float64]:
    array = np.asarray(values, dtype=np.float64)
    if array.size != 16:
        msg = f"{what} has {array.size} values, a 4×4 transform has 16"
        raise ValueError(msg)
    return array.reshape(4, 4)


def parse_metadata(text: str | bytes) -> OusterSensorInfo:
    """The sensor info in an Ouster metadata JSON (either layout).

    Raises:
        ValueError: not JSON, or a field packets cannot be decoded without is missing or
            malformed (the text names it).
    """
    try:
        root = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        msg = f"Ouster metadata is not JSON: {err}"
        raise ValueError(msg) from err
    if not isinstance(root, dict):
        msg = "Ouster metadata is not a JSON object"
        raise ValueError(msg)
    if not all(key in root for key in _NEW_FORMAT_KEYS):
        root = _to_new_format(root)
    try:
        sensor = root.get("sensor_info", {})
        fmt = root["lidar_data_format"]
        beams = root["beam_intrinsics"]
        width = int(fmt["columns_per_frame"])
        height = int(fmt["pixels_per_column"])
        per_packet = int(fmt["columns_per_packet"])
        window = fmt.get("column_window", [0, width - 1])
        altitude = np.asarray(beams["beam_altitude_angles"], dtype=np.float64)
        azimuth = np.asarray(beams["beam_azimuth_angles"], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as err:
        msg = f"Ouster metadata lacks or mangles {err}: lidar_data_format and beam_intrinsics are needed"
        raise ValueError(msg) from err
    if altitude.shape != (height,) or azimuth.shape != (height,):
        msg = (
            f"Ouster metadata has {altitude.size} altitude and {azimuth.size} azimuth angles for "
            f"{height} pixels per column (redrive reads OS sensors, one angle pair per beam)"
        )
        raise ValueError(msg)
    if width <= 0 or height <= 0 or per_packet <= 0 or width % per_packet:
        msg = (
            f"Ouster metadata gives {width} columns, {height} pixels, {per_packet} columns a packet"
        )
        raise ValueError(msg)
    prod_line = str(sensor.get("prod_line", ""))
    if "beam_to_lidar_transform" in beams:
        beam_to_lidar = _matrix(beams["beam_to_lidar_transform"], "beam_to_lidar_transform")
    else:
        beam_to_lidar = np.eye(4)
        beam_to_lidar[0, 3] = float(
            beams.get("lidar_origin_to_beam_origin_mm", _default_beam_origin_mm(prod_line))
        )
    intrinsics = root.get("lidar_intrinsics", {})
    lidar_to_sensor = _matrix(
        intrinsics.get("lidar_to_sensor_transform", _DEFAULT_LIDAR_TO_SENSOR),
        "lidar_to_sensor_transform",
    )
    profile = str(fmt.get("udp_profile_lidar") or "LEGACY")
    header_type = str(
        fmt.get("header_type") or ("FUSA" if profile == "FUSA_RNG15_RFL8_NIR8_DUAL" else "STANDARD")
    )
    for array in (altitude, azimuth, beam_to_lidar, lidar_to_sensor):
        array.flags.writeable = False
    return OusterSensorInfo(
        prod_line=prod_line,
        firmware=str(sensor.get("build_rev", "")),
        udp_profile_lidar=profile,
        header_type=header_type,
        columns_per_frame=width,
        pixels_per_column=height,
        columns_per_packet=per_packet,
        column_window=(int(window[0]), int(window[1])),
        altitude_deg=altitude,
        azimuth_deg=azimuth,
        beam_to_lidar=beam_to_lidar,
        lidar_to_sensor=lidar_to_sensor,
    )


def xyz_lut(info: OusterSensorInfo) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """ouster-sdk's ``make_xyz_lut``: (direction, offset), each (H·W, 3) float64, row-major over
    the (H, W) range image; a pixel of range ρ mm lies at ``ρ · direction + offset`` metres."""
    w, h = info.columns_per_frame, info.pixels_per_column
    encoder = 2.0 * math.pi - np.arange(w, dtype=np.float64) * (2.0 * math.pi / w)
    encoder = np.broadcast_to(encoder[None, :], (h, w)).reshape(-1)
    azimuth = np.repeat(-info.azimuth_deg * math.pi / 180.0, w)
    altitude = np.repeat(info.altitude_deg * math.pi / 180.0, w)
    direction = np.empty((h * w, 3))
    direction[:, 0] = np.cos(encoder + azimuth) * np.cos(altitude)
    direction[:, 1] = np.sin(encoder + azimuth) * np.cos(altitude)
    direction[:, 2] = np.sin(altitude)
    b2l = info.beam_to_lidar
    distance_mm = float(b2l[0, 3])
    if b2l[2, 3] != 0:
        distance_mm = math.sqrt(b2l[0, 3] ** 2 + b2l[2, 3] ** 2)
    offset = np.empty((h * w, 3))
    offset[:, 0] = np.cos(encoder) * b2l[0, 3] - direction[:, 0] * distance_mm
    offset[:, 1] = np.sin(encoder) * b2l[0, 3] - direction[:, 1] * distance_mm
    offset[:, 2] = -direction[:, 2] * distance_mm + b2l[2, 3]
    rot = info.lidar_to_sensor[:3, :3]
    trans = info.lidar_to_sensor[:3, 3]
    direction = (direction @ rot.T) * _RANGE_UNIT_M
    offset = (offset @ rot.T + trans) * _RANGE_UNIT_M
    return direction, offset
