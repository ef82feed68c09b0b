"""The sensor rig of the simulated ego: which sensors, where they sit, how fast and how noisy.

A rig is read from the ``[rig]`` table of a TOML file, one sub-table per sensor::

    [rig.lidar_top]
    kind = "lidar"
    preset = "HDL-32E"
    xyz = [1.2, 0.0, 1.9]        # metres in base_link
    rpy = [0.0, 0.0, 0.0]        # roll, pitch, yaw, radians
    rate_hz = 10
    noise = { range_std_m = 0.02, dropout = 0.01 }

    [rig.camera_front]
    kind = "camera"
    xyz = [1.5, 0.0, 1.6]
    rate_hz = 10
    width = 1280
    height = 720
    fx = 1000.0
    fy = 1000.0                  # cx, cy default to the image centre

A camera's ``rpy`` orients its *body* frame (x forward, y left, z up, like ``camera_link``); its
images live in the optical frame (z forward, x right, y down), see
:meth:`SensorSpec.base_from_optical`.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.config.validate import Table
from redrive.errors import ConfigError
from redrive.geometry import compose, quaternion_from_euler, se3_from_rotation_translation
from redrive.geometry.quaternion import rotation_matrix_from_quaternion
from redrive.sim.lidar_presets import LIDAR_PRESETS
from redrive.types import CameraInfo, SensorType

__all__ = [
    "NOISE_KEYS",
    "CameraIntrinsics",
    "Rig",
    "SensorSpec",
    "default_rig",
    "rig_from_mapping",
]

#: Noise parameters each kind accepts (all ≥ 0; the sensor models document their defaults).
NOISE_KEYS: Mapping[SensorType, frozenset[str]] = MappingProxyType(
    {
        SensorType.LIDAR: frozenset({"range_std_m", "dropout"}),
        SensorType.LIDAR_2D: frozenset({"range_std_m", "dropout"}),
        SensorType.CAMERA: frozenset({"pixel_std"}),
        SensorType.IMU: frozenset(
            {"accel_std_mps2", "gyro_std_rad_s", "accel_bias_walk_mps2", "gyro_bias_walk_rad_s"}
        ),
        SensorType.GNSS: frozenset({"horizontal_std_m", "vertical_std_m"}),
        SensorType.ODOMETRY: frozenset({"speed_std_mps", "yaw_rate_std_rad_s"}),
    }
)

#: camera body (x fwd, y left, z up) from optical (z fwd, x right, y down).
_BODY_FROM_OPTICAL = np.array(
    [[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraIntrinsics:
    """A pinhole camera without distortion; pixel (u, v) = column, row, centres at integers."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def matrix(self) -> npt.NDArray[np.float64]:
        """The 3×3 intrinsic matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def camera_info(self) -> CameraInfo:
        """These intrinsics as a ROS camera info: K, P = [K | 0], R = I, ``plumb_bob`` with five
        zero coefficients (no distortion)."""
        k = self.matrix()
        p = np.zeros((3, 4))
        p[:, :3] = k
        return CameraInfo(width=self.width, height=self.height, k=k, d=np.zeros(5), p=p)


@dataclass(frozen=True, slots=True, kw_only=True)
class SensorSpec:
    """One sensor of the rig.

    Attributes:
        name: the sensor id (``lidar_top``); also its frame id.
        kind: what it is.
        xyz_m: position in base_link, metres.
        rpy_rad: roll, pitch, yaw of the sensor frame in base_link, radians.
        rate_hz: output rate (a LiDAR's rotation rate).
        preset: LiDAR model, a key of :data:`~redrive.sim.lidar_presets.LIDAR_PRESETS`.
        camera: intrinsics, for cameras.
        noise: kind-specific noise parameters, see :data:`NOISE_KEYS`.
    """

    name: str
    kind: SensorType
    xyz_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rate_hz: float
    preset: str | None = None
    camera: CameraIntrinsics | None = None
    noise: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))

    def base_from_sensor(self) -> npt.NDArray[np.float64]:
        """4×4 float64 extrinsics: sensor frame → base_link."""
        q = quaternion_from_euler(*self.rpy_rad)
        return se3_from_rotation_translation(rotation_matrix_from_quaternion(q), self.xyz_m)

    def base_from_optical(self) -> npt.NDArray[np.float64]:
        """For cameras: the optical frame (z forward, x right, y down) → base_link."""
        return compose(self.base_from_sensor(), _BODY_FROM_OPTICAL)


@dataclass(frozen=True, slots=True, kw_only=True)
class Rig:
    """The sensors of one vehicle, by name (in the order they were declared)."""

    sensors: tuple[SensorSpec, ...]

    def __post_init__(self) -> None:
        names = [s.name for s in self.sensors]
        if len(set(names)) != len(names):
            msg = f"Rig: sensor names must be unique, got {names}"
            raise ValueError(msg)

    def __getitem__(self, name: str) -> SensorSpec:
        for spec in self.sensors:
            if spec.name == name:
                return spec
        msg = f"no sensor {name!r} in the rig (have {', '.join(self.names)})"
        raise KeyError(msg)

    def __iter__(self) -> Iterator[SensorSpec]:
        return iter(self.sensors)

    def __len__(self) -> int:
        return len(self.sensors)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.sensors)

    def of_kind(self, kind: SensorType) -> tuple[SensorSpec, ...]:
        return tuple(s for s in self.sensors if s.kind is kind)


_KINDS = {
    "lidar": SensorType.LIDAR,
    "lidar_2d": SensorType.LIDAR_2D,
    "camera": SensorType.CAMERA,
    "imu": SensorType.IMU,
    "gnss": SensorType.GNSS,
    "odometry": SensorType.ODOMETRY,
}
_COMMON_KEYS = frozenset({"kind", "xyz", "rpy", "rate_hz", "noise"})
_EXTRA_KEYS: Mapping[SensorType, frozenset[str]] = {
    SensorType.LIDAR: frozenset({"preset"}),
    SensorType.LIDAR_2D: frozenset({"preset"}),
    SensorType.CAMERA: frozenset({"width", "height", "fx", "fy", "cx", "cy"}),
}


def _sensor_from_table(source: str, name: str, table: Any) -> SensorSpec:
    if not isinstance(table, Mapping):
        msg = f"{source}: rig.{name} is a {type(table).__name__}, not a table; write [rig.{name}] with kind = ..."
        raise ConfigError(msg)

    def style(source: str, path: str, problem: str, fix: str) -> str:
        return f"{source}: [rig.{name}] {path}: {problem}; {fix}"

    r = Table(table, source=source, style=style)
    kind_name = r.text("kind", choices=tuple(_KINDS), fix='use one of them, e.g. kind = "lidar"')
    kind = _KINDS[kind_name]
    allowed = _COMMON_KEYS | _EXTRA_KEYS.get(kind, frozenset())
    r.check_keys(allowed, fix=f"a {kind_name} has the keys {', '.join(sorted(allowed))}")
    noise_t = r.table("noise", {}, fix="write noise = { key = value, ... }")
    noise_t.check_keys(
        NOISE_KEYS[kind],
        fix=f"a {kind_name} has the noise parameters {', '.join(sorted(NOISE_KEYS[kind]))}",
    )
    noise = {key: noise_t.number(key, minimum=0, fix="give a number ≥ 0") for key in noise_t}
    if "dropout" in noise_t:
        noise_t.number("dropout", maximum=1, fix="give a probability in [0, 1]")
    preset = None
    camera = None
    if kind in (SensorType.LIDAR, SensorType.LIDAR_2D):
        preset = r.text(
            "preset",
            "HDL-32E" if kind is SensorType.LIDAR else "UTM-30LX",
            choices=tuple(LIDAR_PRESETS),
            fix=f"use one of {', '.join(LIDAR_PRESETS)}",
        )
        is_2d = LIDAR_PRESETS[preset].is_2d
        if is_2d != (kind is SensorType.LIDAR_2D):
            want = "a 2D preset (UTM-30LX)" if not is_2d else "a 3D preset"
            raise r.fail("preset", f"{preset} does not fit kind {kind_name!r}", f"use {want}")
    if kind is SensorType.CAMERA:
        width = r.integer("width", minimum=1, fix="write width = <pixels>")
        height = r.integer("height", minimum=1, fix="write height = <pixels>")
        camera = CameraIntrinsics(
            width=width,
            height=height,
            fx=r.number("fx", positive=True),
            fy=r.number("fy", positive=True),
            cx=r.number("cx", (width - 1) / 2.0),
            cy=r.number("cy", (height - 1) / 2.0),
        )
    return SensorSpec(
        name=name,
        kind=kind,
        xyz_m=r.numbers("xyz", (0.0, 0.0, 0.0), length=3, fix="write xyz = [x, y, z] in metres"),
        rpy_rad=r.numbers("rpy", (0.0, 0.0, 0.0), length=3, fix="write rpy = [roll, pitch, yaw]"),
        rate_hz=r.number("rate_hz", positive=True),
        preset=preset,
        camera=camera,
        noise=MappingProxyType(noise),
    )


def rig_from_mapping(mapping: Mapping[str, Any], *, source: str) -> Rig:
    """A :class:`Rig` from the ``[rig]`` table of a TOML file (sensor name → sensor table).

    Raises:
        ConfigError: naming ``source`` (the file), the key and what to write instead.
    """
    if not isinstance(mapping, Mapping) or not mapping:
        msg = f"{source}: [rig] must be a table with at least one [rig.<name>] sensor table"
        raise ConfigError(msg)
    sensors = []
    for name, table in mapping.items():
        if not isinstance(name, str) or not name.replace("_", "").isalnum():
            msg = f"{source}: rig sensor name {name!r} must be letters, digits and _; rename it"
            raise ConfigError(msg)
        sensors.append(_sensor_from_table(source, name, table))
    return Rig(sensors=tuple(sensors))


_DEFAULT_RIG: Mapping[str, Any] = {
    "lidar_top": {"kind": "lidar", "preset": "HDL-32E", "xyz": [1.2, 0.0, 1.9], "rate_hz": 10},
    "lidar_2d": {"kind": "lidar_2d", "preset": "UTM-30LX", "xyz": [3.7, 0.0, 0.5], "rate_hz": 20},
    "camera_front": {
        "kind": "camera",
        "xyz": [1.5, 0.0, 1.6],
        "rate_hz": 10,
        "width": 1280,
        "height": 720,
        "fx": 1000.0,
        "fy": 1000.0,
    },
    "imu": {"kind": "imu", "xyz": [0.0, 0.0, 0.5], "rate_hz": 100},
    "gnss": {"kind": "gnss", "xyz": [0.0, 0.0, 1.8], "rate_hz": 10},
    "odom": {"kind": "odometry", "rate_hz": 50},
}


def default_rig() -> Rig:
    """HDL-32E on the roof (10 Hz), 2D LiDAR in the bumper (20 Hz), 1280×720 front camera
    (fx = fy = 1000, 10 Hz), IMU (100 Hz), GNSS (10 Hz), wheel odometry (50 Hz)."""
    return rig_from_mapping(_DEFAULT_RIG, source="<default rig>")
