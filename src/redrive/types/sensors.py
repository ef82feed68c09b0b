"""Sensor payloads: point clouds, images, IMU samples, GNSS fixes; camera calibrations."""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from itertools import repeat
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.types._arrays import frozen_array, frozen_vector
from redrive.types._drafts import draft_class
from redrive.types._pickle import reduce_dataclass

__all__ = ["IMAGE_ENCODINGS", "CameraInfo", "GnssFix", "Image", "Imu", "PointCloud"]

_F32 = np.dtype(np.float32)


@dataclass(frozen=True, slots=True, kw_only=True)
class PointCloud:
    """A LiDAR sweep (or a 2D scan with z = 0) as one array per field.

    Attributes:
        xyz: float32 (N, 3), metres, in the frame of the sensor that recorded it; read-only.
            It owns its memory or pins it (never a buffer that can change), but it need not be
            C-contiguous nor aligned: a decoded cloud's xyz is a strided view (row stride = the
            point's size) of the cloud's own copy of the message's point bytes or of the
            immutable chunk the reader read them into.  Code that needs contiguous, aligned
            points (a compiled kernel with a fixed layout, ``.ctypes``, a raw buffer write)
            calls ``np.require(cloud.xyz, np.float32, ("C", "A"))`` (``np.ascontiguousarray`` keeps
            a contiguous unaligned array as it is); numpy code needs nothing.  A cloud viewing
            its chunk keeps the whole chunk alive (at most 4 MiB, or twice its own bytes):
            code that keeps a few clouds out of many for long (every 100th sweep, say) keeps
            ``cloud.xyz.copy()`` instead.
        channels: per-point fields, each an array of shape (N,): ``intensity``, ``ring``,
            ``t_offset_ns`` … in whatever dtype the source used, read-only, strided views like
            xyz when decoded.  Never a structured array.
    """

    xyz: npt.NDArray[np.float32]
    channels: Mapping[str, npt.NDArray[Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        xyz = self.xyz
        if not (
            type(xyz) is np.ndarray
            and xyz.dtype == _F32
            and xyz.ndim == 2
            and xyz.shape[1] == 3
            and not xyz.flags.writeable
        ):
            # Every decoded cloud passes here; the check above lets an already read-only float32
            # (N, 3) array through without the general path's cost.
            xyz = frozen_array(xyz, name="PointCloud.xyz", dtype=np.float32, shape=(None, 3))
            object.__setattr__(self, "xyz", xyz)
        n = xyz.shape[0]
        checked: dict[str, npt.NDArray[Any]] = {}
        for key, given in self.channels.items():
            values = given if isinstance(given, np.ndarray) else np.asarray(given)
            if values.dtype.fields is not None:
                msg = f"PointCloud.channels[{key!r}]: structured arrays are not allowed"
                raise ValueError(msg)
            if values.ndim != 1 or values.shape[0] != n:
                msg = f"PointCloud.channels[{key!r}]: shape {values.shape} does not match ({n},)"
                raise ValueError(msg)
            if values.flags.writeable:
                values = values.view()  # freeze a view, never the caller's array
                values.flags.writeable = False
            checked[key] = values
        object.__setattr__(self, "channels", MappingProxyType(checked))

    @classmethod
    def from_frozen(
        cls, xyz: npt.NDArray[np.float32], channels: Mapping[str, npt.NDArray[Any]]
    ) -> PointCloud:
        """A cloud from arrays that already are what ``__post_init__`` would make of them.

        For decoders, which build the arrays themselves and call this once per message: the
        checks are skipped, so the caller guarantees ``xyz`` is a read-only float32 (N, 3)
        ``ndarray`` (strided or not) over memory that cannot change, and every channel a read-only, non-structured ``ndarray`` of shape (N,).
        ``channels`` is wrapped as it is (not copied): hand over a dict nothing else holds.
        """
        cloud = object.__new__(cls)
        object.__setattr__(cloud, "xyz", xyz)
        object.__setattr__(cloud, "channels", MappingProxyType(channels))
        return cloud

    @classmethod
    def many_from_rows(
        cls,
        xyz: npt.NDArray[np.float32],
        channels: Sequence[tuple[str, npt.NDArray[Any]]],
    ) -> list[PointCloud]:
        """B clouds of N points each, cloud i being ``xyz[i]`` and row i of every channel.

        For decoders that decode many clouds of one layout at once: ``xyz`` must be a read-only
        float32 (B, N, 3) ``ndarray`` and every channel a read-only, non-structured (B, N)
        ``ndarray`` (ValueError otherwise) — checked here once for the B clouds, so the clouds
        are what ``PointCloud(xyz=xyz[i], channels={name: rows[i], …})`` would make (read-only
        row views, shapes (N, 3) and (N,)) without checking each of them again.  The objects
        are built by C-level iteration (``map``), no Python step per cloud.
        """
        if not (
            type(xyz) is np.ndarray
            and xyz.dtype == _F32
            and xyz.ndim == 3
            and xyz.shape[2] == 3
            and not xyz.flags.writeable
        ):
            have = f"{getattr(xyz, 'dtype', type(xyz).__name__)} {getattr(xyz, 'shape', '')}"
            msg = f"PointCloud.many_from_rows: xyz must be read-only float32 (B, N, 3), not {have}"
            raise ValueError(msg)
        shape = xyz.shape[:2]
        names: list[str] = []
        for name, rows in channels:
            if (
                type(rows) is not np.ndarray
                or rows.dtype.fields is not None
                or rows.shape != shape
                or rows.flags.writeable
                or name in names
            ):
                msg = (
                    f"PointCloud.many_from_rows: channel {name!r} must be a read-only, "
                    f"non-structured array of shape {shape}, named once"
                )
                raise ValueError(msg)
            names.append(name)
        # Iterating an array in C yields its rows as views, read-only as the array is.
        return cls.many_from_frozen(list(xyz), [(name, list(rows)) for name, rows in channels])

    @classmethod
    def many_from_frozen(
        cls,
        xyz: Sequence[npt.NDArray[np.float32]],
        channels: Sequence[tuple[str, Sequence[npt.NDArray[Any]]]],
    ) -> list[PointCloud]:
        """B clouds, cloud i being ``xyz[i]`` and element i of every channel's sequence.

        :meth:`from_frozen` for many clouds at once: only the lengths are checked (every
        sequence must have B items: ValueError), so the caller guarantees what
        :meth:`from_frozen` asks of each cloud's arrays and channel names given once.  The objects are built by C-level iteration
        (``map``), no Python step per cloud.
        """
        names = tuple(name for name, _ in channels)
        columns = [values for _, values in channels]
        count = len(xyz)
        for values in columns:
            if len(values) != count:
                msg = f"PointCloud.many_from_frozen: {count} xyz arrays, {len(values)} of a channel"
                raise ValueError(msg)
        if cls is PointCloud and len(names) <= _MAX_LITERAL_CHANNELS:
            return _cloud_builder(len(names))(names, xyz, columns)
        clouds: list[PointCloud] = list(map(object.__new__, repeat(cls, count)))
        any(map(_SET_XYZ, clouds, xyz))
        per_cloud = zip(*columns, strict=True)
        proxies = list(map(MappingProxyType, map(dict, map(zip, repeat(names), per_cloud))))
        any(map(_SET_CHANNELS, clouds, proxies))
        return clouds

    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    @property
    def num_points(self) -> int:
        return int(self.xyz.shape[0])

    def __reduce__(self) -> tuple[Any, ...]:
        return reduce_dataclass(self)


# The slots' own setters: what ``object.__setattr__`` ends in, without its lookup.
_SET_XYZ = PointCloud.__dict__["xyz"].__set__
_SET_CHANNELS = PointCloud.__dict__["channels"].__set__

#: Up to this many channels, :meth:`PointCloud.many_from_frozen` builds the clouds with a
#: function generated for that many (:func:`_cloud_builder`).
_MAX_LITERAL_CHANNELS = 32

#: PointCloud's draft (:mod:`redrive.types._drafts`): what the generated builders fill.
_Draft = draft_class(PointCloud)

_CloudBuilder = Callable[
    [tuple[str, ...], Sequence[npt.NDArray[np.float32]], Sequence[Sequence[npt.NDArray[Any]]]],
    list[PointCloud],
]


@functools.lru_cache(maxsize=_MAX_LITERAL_CHANNELS + 1)
def _cloud_builder(arity: int) -> _CloudBuilder:
    """A function ``(names, xyz, columns)`` → the clouds, cloud i being ``xyz[i]`` with the
    read-only mapping ``{names[k]: columns[k][i]}``: a draft a cloud
    (:func:`~redrive.types._drafts.draft_class`), its mapping a dict display of ``arity`` keys
    (≈ 4× faster than ``dict(zip(…))``, which goes through the generic pair iteration), in one
    loop.  Only the arity is written into the generated code; names and values are its
    arguments (as ``namedtuple`` and ``dataclasses`` generate theirs)."""
    keys = [f"n{k}" for k in range(arity)]
    items = [f"x{k}" for k in range(arity)]
    cols = [f"c{k}" for k in range(arity)]
    display = ", ".join(f"{k}: {x}" for k, x in zip(keys, items, strict=True))
    source = (
        "def build(names, xyz, columns):\n"
        f"    ({''.join(k + ', ' for k in keys)}) = names\n"
        f"    ({''.join(c + ', ' for c in cols)}) = columns\n"
        "    clouds = []\n"
        "    append = clouds.append\n"
        f"    for points, {''.join(x + ', ' for x in items)} in zip(xyz, {''.join(c + ', ' for c in cols)}):\n"
        "        cloud = draft()\n"
        "        cloud.xyz = points\n"
        f"        cloud.channels = proxy({{{display}}})\n"
        "        cloud.__class__ = cloud_class\n"
        "        append(cloud)\n"
        "    return clouds\n"
    )
    scope: dict[str, Any] = {"proxy": MappingProxyType, "draft": _Draft, "cloud_class": PointCloud}
    exec(source, scope)  # the source holds identifiers and the arity only
    build: _CloudBuilder = scope["build"]
    return build


#: Image encodings the data model knows, with (dtype, channels).
IMAGE_ENCODINGS: Mapping[str, tuple[type[np.generic], int]] = MappingProxyType(
    {
        "rgb8": (np.uint8, 3),
        "bgr8": (np.uint8, 3),
        "rgba8": (np.uint8, 4),
        "bgra8": (np.uint8, 4),
        "mono8": (np.uint8, 1),
        "mono16": (np.uint16, 1),
        "16UC1": (np.uint16, 1),
        "32FC1": (np.float32, 1),
    }
)


@dataclass(frozen=True, slots=True, kw_only=True)
class Image:
    """A camera image.

    Attributes:
        pixels: (H, W) for one channel or (H, W, C); dtype follows ``encoding``
            (uint8 for rgb8/bgr8/rgba8/bgra8/mono8, uint16 for mono16/16UC1, float32 for 32FC1).
        encoding: a ROS ``sensor_msgs/Image`` encoding name, see :data:`IMAGE_ENCODINGS`.
    """

    pixels: npt.NDArray[Any]
    encoding: str

    def __post_init__(self) -> None:
        if self.encoding not in IMAGE_ENCODINGS:
            msg = f"Image.encoding {self.encoding!r} is not one of {sorted(IMAGE_ENCODINGS)}"
            raise ValueError(msg)
        dtype, channels = IMAGE_ENCODINGS[self.encoding]
        shape: tuple[int | None, ...] = (None, None) if channels == 1 else (None, None, channels)
        pixels = frozen_array(self.pixels, name="Image.pixels", dtype=dtype, shape=shape)
        object.__setattr__(self, "pixels", pixels)

    @property
    def height(self) -> int:
        return int(self.pixels.shape[0])

    @property
    def width(self) -> int:
        return int(self.pixels.shape[1])


@dataclass(frozen=True, slots=True, kw_only=True)
class Imu:
    """One IMU sample in the IMU's frame.

    Attributes:
        linear_acceleration: (3,) m/s².
        angular_velocity: (3,) rad/s.
        orientation: (4,) quaternion x, y, z, w; all-NaN when the IMU gives no orientation.
    """

    linear_acceleration: npt.NDArray[np.float64]
    angular_velocity: npt.NDArray[np.float64]
    orientation: npt.NDArray[np.float64] = field(
        default_factory=lambda: np.full(4, np.nan, dtype=np.float64)
    )

    def __post_init__(self) -> None:
        for name, size in (("linear_acceleration", 3), ("angular_velocity", 3), ("orientation", 4)):
            vec = frozen_vector(getattr(self, name), name=f"Imu.{name}", size=size)
            object.__setattr__(self, name, vec)


@dataclass(frozen=True, slots=True, kw_only=True)
class GnssFix:
    """A satellite navigation fix (WGS 84).

    Attributes:
        latitude_deg, longitude_deg: degrees, positive north / east.
        altitude_m: metres above the WGS 84 ellipsoid.
        position_covariance_m2: (3, 3) ENU covariance, m²; NaN where unknown.
        status: ROS ``NavSatStatus`` value (-1 no fix, 0 fix, 1 SBAS, 2 GBAS).
    """

    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    position_covariance_m2: npt.NDArray[np.float64] = field(
        default_factory=lambda: np.full((3, 3), np.nan, dtype=np.float64)
    )
    status: int = 0

    def __post_init__(self) -> None:
        cov = frozen_array(
            self.position_covariance_m2,
            name="GnssFix.position_covariance_m2",
            dtype=np.float64,
            shape=(3, 3),
        )
        object.__setattr__(self, "position_covariance_m2", cov)


def _identity3() -> npt.NDArray[np.float64]:
    return np.eye(3)


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraInfo:
    """A camera's calibration, as ROS ``sensor_msgs/CameraInfo`` holds it.

    Coordinates are those of the camera's optical frame (z forward, x right, y down, metres);
    pixel (u, v) = (column, row) with centres at integers.

    Attributes:
        width, height: image size, pixels (0 × 0 when the camera is not calibrated).
        k: (3, 3) float64 intrinsics of the raw (distorted) image, ``[[fx, 0, cx], [0, fy, cy],
            [0, 0, 1]]`` in pixels.
        d: (N,) float64 distortion coefficients of ``distortion_model`` (``plumb_bob``: k1, k2,
            t1, t2, k3); empty when there is no distortion.
        distortion_model: ``plumb_bob``, ``rational_polynomial``, ``equidistant`` …
        r: (3, 3) float64 rectification rotation (stereo cameras), identity otherwise.
        p: (3, 4) float64 projection of the rectified image, ``[[fx', 0, cx', Tx], [0, fy', cy',
            Ty], [0, 0, 1, 0]]``; all zero when the log does not give one.
    """

    width: int
    height: int
    k: npt.NDArray[np.float64]
    d: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    distortion_model: str = "plumb_bob"
    r: npt.NDArray[np.float64] = field(default_factory=_identity3)
    p: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((3, 4)))

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
                msg = f"CameraInfo.{name} must be a non-negative int (pixels), got {value!r}"
                raise ValueError(msg)
            object.__setattr__(self, name, int(value))
        shapes: dict[str, tuple[int | None, ...]] = {
            "k": (3, 3),
            "d": (None,),
            "r": (3, 3),
            "p": (3, 4),
        }
        for name, shape in shapes.items():
            value = getattr(self, name)
            if isinstance(value, np.ndarray) and value.dtype != np.float64:
                value = value.astype(np.float64)
            arr = frozen_array(value, name=f"CameraInfo.{name}", dtype=np.float64, shape=shape)
            object.__setattr__(self, name, arr)

    def __reduce__(self) -> tuple[Any, ...]:
        return reduce_dataclass(self)  # rebuilt through __post_init__: arrays stay read-only

    def _projection(self) -> npt.NDArray[np.float64]:
        if np.any(self.p != 0.0):
            return self.p
        out = np.zeros((3, 4))
        out[:, :3] = self.k
        return out

    @property
    def is_calibrated(self) -> bool:
        """True when the projection has focal lengths (ROS writes all zeros for an uncalibrated
        camera)."""
        proj = self._projection()
        return bool(proj[0, 0] != 0.0 and proj[1, 1] != 0.0)

    def image_from_optical(self) -> npt.NDArray[np.float64]:
        """(3, 4) float64: optical-frame points (m, homogeneous) → pixels (homogeneous).

        ``P`` when the message has one (not all zero), else ``[K | 0]`` — as
        ``image_geometry.PinholeCameraModel.project3dToPixel`` does.  P maps into the rectified
        image; where the distortion is not negligible, projections onto the raw (``image_raw``)
        image are off by it.  ``R`` is not applied (it is the identity for monocular cameras).

        Raises:
            ValueError: the camera is not calibrated (no focal lengths in P nor K).
        """
        if not self.is_calibrated:
            msg = "CameraInfo: the camera is not calibrated (K and P give no focal length)"
            raise ValueError(msg)
        return self._projection().copy()
