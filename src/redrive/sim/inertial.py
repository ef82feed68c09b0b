"""IMU, GNSS and wheel odometry measured from the ego's true motion.

The caller gives true :class:`~redrive.types.VehicleState` samples (map frame, rear-axle centre,
REP-103; the ego is upright: its attitude is its heading, unless roll/pitch are passed); every
model draws its noise from the ``numpy.random.Generator`` passed to each call, so a run is
reproducible from one seed.

* :class:`ImuModel` — specific force ``f = R_map_imuᵀ (a_imu − g)`` (g = (0, 0, −9.80665) m/s²,
  ``a_imu`` including the lever-arm terms α × r + ω × (ω × r)), angular velocity in the IMU frame,
  orientation (map_from_imu quaternion); white noise plus a random-walk bias on both.
* :class:`GnssModel` — WGS 84 fixes of the antenna, the map frame being the local East-North-Up
  tangent plane at a reference latitude / longitude / altitude; :func:`geodetic_from_enu` and
  :func:`enu_from_geodetic` convert both ways (exact ellipsoid, no flat-earth shortcut).
* :class:`OdometryModel` — wheel speed and yaw rate with noise, dead-reckoned into an ``odom``
  frame pose (drifts like the real thing).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from redrive.errors import SimulationError
from redrive.geometry import quaternion_from_euler, quaternion_from_rotation_matrix
from redrive.geometry.quaternion import rotation_matrix_from_quaternion
from redrive.sim.rig import SensorSpec
from redrive.types import GnssFix, Imu, SensorType, VehicleState

__all__ = [
    "GRAVITY_MPS2",
    "GnssModel",
    "ImuModel",
    "OdometryModel",
    "enu_from_geodetic",
    "geodetic_from_enu",
]

GRAVITY_MPS2 = 9.80665
_WGS84_A = 6378137.0
_WGS84_F = 1.0 / 298.257223563
_WGS84_E2 = _WGS84_F * (2.0 - _WGS84_F)


def _check_kind(spec: SensorSpec, kind: SensorType) -> None:
    if spec.kind is not kind:
        msg = f"sensor {spec.name!r} is a {spec.kind.value}, not a {kind.value}"
        raise SimulationError(msg)


def _map_from_base_rotation(
    state: VehicleState, roll_rad: float, pitch_rad: float
) -> npt.NDArray[np.float64]:
    q = quaternion_from_euler(roll_rad, pitch_rad, state.heading_rad)
    return rotation_matrix_from_quaternion(q)


def _cross(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``np.cross`` of two 3-vectors by the same products and differences (its general
    machinery costs ≈ 15 µs a call; the IMU takes three a sample)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


class ImuModel:
    """An IMU rigidly mounted at ``base_from_imu``.

    Args:
        base_from_imu: 4×4 extrinsics (identity by default).
        accel_std_mps2, gyro_std_rad_s: 1-σ white noise per sample.
        accel_bias_walk_mps2, gyro_bias_walk_rad_s: random-walk bias, σ per √s.
    """

    def __init__(
        self,
        *,
        base_from_imu: npt.ArrayLike | None = None,
        accel_std_mps2: float = 0.02,
        gyro_std_rad_s: float = 0.002,
        accel_bias_walk_mps2: float = 0.0005,
        gyro_bias_walk_rad_s: float = 0.00002,
    ) -> None:
        self.base_from_imu = np.eye(4) if base_from_imu is None else np.asarray(base_from_imu)
        self.accel_std_mps2 = float(accel_std_mps2)
        self.gyro_std_rad_s = float(gyro_std_rad_s)
        self.accel_bias_walk_mps2 = float(accel_bias_walk_mps2)
        self.gyro_bias_walk_rad_s = float(gyro_bias_walk_rad_s)
        self.accel_bias = np.zeros(3)
        self.gyro_bias = np.zeros(3)
        self._last_ns: int | None = None

    @classmethod
    def from_spec(cls, spec: SensorSpec) -> ImuModel:
        _check_kind(spec, SensorType.IMU)
        return cls(base_from_imu=spec.base_from_sensor(), **spec.noise)

    def reset(self) -> None:
        """Zero the biases (start of a run)."""
        self.accel_bias[:] = 0.0
        self.gyro_bias[:] = 0.0
        self._last_ns = None

    def sample(
        self,
        state: VehicleState,
        rng: np.random.Generator,
        *,
        yaw_accel_rad_s2: float = 0.0,
        roll_rad: float = 0.0,
        pitch_rad: float = 0.0,
    ) -> Imu:
        """The IMU reading at ``state.stamp_ns`` (the bias walks from the previous sample)."""
        if self._last_ns is not None and state.stamp_ns > self._last_ns:
            dt_s = (state.stamp_ns - self._last_ns) * 1e-9
            self.accel_bias += rng.standard_normal(3) * self.accel_bias_walk_mps2 * math.sqrt(dt_s)
            self.gyro_bias += rng.standard_normal(3) * self.gyro_bias_walk_rad_s * math.sqrt(dt_s)
        self._last_ns = state.stamp_ns
        map_from_base = _map_from_base_rotation(state, roll_rad, pitch_rad)
        map_from_imu = map_from_base @ self.base_from_imu[:3, :3]
        lever = map_from_base @ self.base_from_imu[:3, 3]
        omega = np.array([0.0, 0.0, state.yaw_rate_rad_s])
        alpha = np.array([0.0, 0.0, yaw_accel_rad_s2])
        accel = state.acceleration + _cross(alpha, lever) + _cross(omega, _cross(omega, lever))
        specific_force = map_from_imu.T @ (accel - np.array([0.0, 0.0, -GRAVITY_MPS2]))
        gyro = map_from_imu.T @ omega
        specific_force = (
            specific_force + self.accel_bias + rng.standard_normal(3) * self.accel_std_mps2
        )
        gyro = gyro + self.gyro_bias + rng.standard_normal(3) * self.gyro_std_rad_s
        return Imu(
            linear_acceleration=specific_force,
            angular_velocity=gyro,
            orientation=quaternion_from_rotation_matrix(map_from_imu),
        )


def _ecef_from_geodetic(lat_rad: float, lon_rad: float, alt_m: float) -> npt.NDArray[np.float64]:
    n = _WGS84_A / math.sqrt(1.0 - _WGS84_E2 * math.sin(lat_rad) ** 2)
    return np.array(
        [
            (n + alt_m) * math.cos(lat_rad) * math.cos(lon_rad),
            (n + alt_m) * math.cos(lat_rad) * math.sin(lon_rad),
            (n * (1.0 - _WGS84_E2) + alt_m) * math.sin(lat_rad),
        ]
    )


def _enu_from_ecef_rotation(lat_rad: float, lon_rad: float) -> npt.NDArray[np.float64]:
    sl, cl = math.sin(lat_rad), math.cos(lat_rad)
    so, co = math.sin(lon_rad), math.cos(lon_rad)
    return np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])


def enu_from_geodetic(
    lat_deg: float, lon_deg: float, alt_m: float, *, reference: tuple[float, float, float]
) -> npt.NDArray[np.float64]:
    """(3,) East-North-Up metres of a WGS 84 point, in the tangent plane at ``reference``
    (lat_deg, lon_deg, alt_m)."""
    ref_lat, ref_lon = math.radians(reference[0]), math.radians(reference[1])
    ecef = _ecef_from_geodetic(math.radians(lat_deg), math.radians(lon_deg), alt_m)
    ref = _ecef_from_geodetic(ref_lat, ref_lon, reference[2])
    out: npt.NDArray[np.float64] = _enu_from_ecef_rotation(ref_lat, ref_lon) @ (ecef - ref)
    return out


def geodetic_from_enu(
    enu_m: npt.ArrayLike, *, reference: tuple[float, float, float]
) -> tuple[float, float, float]:
    """WGS 84 (lat_deg, lon_deg, alt_m) of an East-North-Up point (3,) around ``reference``."""
    ref_lat, ref_lon = math.radians(reference[0]), math.radians(reference[1])
    enu = np.asarray(enu_m, dtype=np.float64).reshape(3)
    ecef = _ecef_from_geodetic(ref_lat, ref_lon, reference[2]) + (
        _enu_from_ecef_rotation(ref_lat, ref_lon).T @ enu
    )
    x, y, z = (float(v) for v in ecef)
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1.0 - _WGS84_E2))
    alt = 0.0
    for _ in range(6):  # converges to < 1e-12 rad in 3–4 rounds away from the poles
        n = _WGS84_A / math.sqrt(1.0 - _WGS84_E2 * math.sin(lat) ** 2)
        alt = p / math.cos(lat) - n
        lat = math.atan2(z, p * (1.0 - _WGS84_E2 * n / (n + alt)))
    return math.degrees(lat), math.degrees(lon), alt


class GnssModel:
    """A GNSS receiver whose antenna sits at ``base_from_antenna``; map = ENU at ``reference``.

    Args:
        reference: (lat_deg, lon_deg, alt_m) of the map origin.
        horizontal_std_m, vertical_std_m: 1-σ position noise (reported in the covariance).
    """

    def __init__(
        self,
        *,
        reference: tuple[float, float, float] = (48.137, 11.575, 520.0),
        base_from_antenna: npt.ArrayLike | None = None,
        horizontal_std_m: float = 0.5,
        vertical_std_m: float = 1.0,
    ) -> None:
        self.reference = reference
        self.base_from_antenna = (
            np.eye(4) if base_from_antenna is None else np.asarray(base_from_antenna)
        )
        self.horizontal_std_m = float(horizontal_std_m)
        self.vertical_std_m = float(vertical_std_m)

    @classmethod
    def from_spec(
        cls, spec: SensorSpec, *, reference: tuple[float, float, float] = (48.137, 11.575, 520.0)
    ) -> GnssModel:
        _check_kind(spec, SensorType.GNSS)
        return cls(reference=reference, base_from_antenna=spec.base_from_sensor(), **spec.noise)

    def antenna_position(self, state: VehicleState) -> npt.NDArray[np.float64]:
        """(3,) true map position of the antenna."""
        rot = _map_from_base_rotation(state, 0.0, 0.0)
        out: npt.NDArray[np.float64] = state.position + rot @ self.base_from_antenna[:3, 3]
        return out

    def fix(self, state: VehicleState, rng: np.random.Generator) -> GnssFix:
        """A noisy fix of the antenna at ``state``."""
        std = np.array([self.horizontal_std_m, self.horizontal_std_m, self.vertical_std_m])
        enu = self.antenna_position(state) + rng.standard_normal(3) * std
        lat, lon, alt = geodetic_from_enu(enu, reference=self.reference)
        return GnssFix(
            latitude_deg=lat,
            longitude_deg=lon,
            altitude_m=alt,
            position_covariance_m2=np.diag(std**2),
            status=0,
        )

    def map_position(self, fix: GnssFix) -> npt.NDArray[np.float64]:
        """(3,) map (ENU) position of a fix: the inverse of :meth:`fix` without noise."""
        return enu_from_geodetic(
            fix.latitude_deg, fix.longitude_deg, fix.altitude_m, reference=self.reference
        )


class OdometryModel:
    """Wheel odometry: noisy forward speed and yaw rate, dead-reckoned in the ``odom`` frame.

    The first call starts the odom frame at the true pose (``odom`` = ``map`` at start); after
    that the pose drifts with the integrated noise.
    """

    def __init__(self, *, speed_std_mps: float = 0.05, yaw_rate_std_rad_s: float = 0.005) -> None:
        self.speed_std_mps = float(speed_std_mps)
        self.yaw_rate_std_rad_s = float(yaw_rate_std_rad_s)
        self._pose: tuple[float, float, float] | None = None  # x, y, heading
        self._last_ns = 0

    @classmethod
    def from_spec(cls, spec: SensorSpec) -> OdometryModel:
        _check_kind(spec, SensorType.ODOMETRY)
        return cls(**spec.noise)

    def reset(self) -> None:
        self._pose = None

    def odom_from_base(self) -> npt.NDArray[np.float64] | None:
        """The dead-reckoned pose of ``base_link`` in ``odom`` (4×4, z = 0) of the last
        reading; None before the first."""
        if self._pose is None:
            return None
        x, y, yaw = self._pose
        c, s = math.cos(yaw), math.sin(yaw)
        out = np.eye(4)
        out[:2, :2] = [[c, -s], [s, c]]
        out[0, 3], out[1, 3] = x, y
        return out

    def measure(self, state: VehicleState, rng: np.random.Generator) -> VehicleState:
        """The odometry reading at ``state.stamp_ns`` (frame ``odom``)."""
        heading = state.heading_rad
        forward = float(
            state.velocity[0] * math.cos(heading) + state.velocity[1] * math.sin(heading)
        )
        speed = forward + float(rng.standard_normal()) * self.speed_std_mps
        yaw_rate = state.yaw_rate_rad_s + float(rng.standard_normal()) * self.yaw_rate_std_rad_s
        if self._pose is None:
            x, y, yaw = float(state.position[0]), float(state.position[1]), heading
        else:
            x, y, yaw = self._pose
            dt_s = max(state.stamp_ns - self._last_ns, 0) * 1e-9
            mid = yaw + 0.5 * yaw_rate * dt_s
            x += speed * dt_s * math.cos(mid)
            y += speed * dt_s * math.sin(mid)
            yaw += yaw_rate * dt_s
        self._pose = (x, y, yaw)
        self._last_ns = state.stamp_ns
        return VehicleState(
            stamp_ns=state.stamp_ns,
            frame_id="odom",
            position=np.array([x, y, 0.0]),
            velocity=np.array([speed * math.cos(yaw), speed * math.sin(yaw), 0.0]),
            heading_rad=yaw,
            yaw_rate_rad_s=yaw_rate,
        )
