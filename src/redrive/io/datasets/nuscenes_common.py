"""What the nuScenes readers share: a keyframe as redrive sees it, and how it becomes messages.

Both nuScenes readers — the table layout (:mod:`redrive.io.datasets.nuscenes`) and mmdetection3d info files
(:mod:`redrive.io.datasets.mmdet3d_info`) — turn their source into a list of :class:`NuScenesSample`
(already in redrive's frames) and stream it through :class:`NuScenesReaderBase`.

Frames (nuScenes: the ego frame is the midpoint of the rear axle, x forward, y left, z up — the
same as redrive's ``base_link``; cameras are optical frames, z forward, x right, y down):

==========================  ========================  =============================================
topic                       msgtype                   payload (:class:`Decoded` value)
==========================  ========================  =============================================
``/tf_static``              ``redrive/Transforms``    ``base_link`` → ``LIDAR_TOP`` and every
                                                      ``CAM_*`` (the calibrated sensors, static),
                                                      and ``base_link`` → ``LIDAR_TOP_base_axes``;
                                                      sent with every sample (calibrations differ
                                                      between logs)
``/LIDAR_TOP``              ``redrive/PointCloud``    the sweep, frame ``LIDAR_TOP_base_axes``,
                                                      channels ``intensity`` (0–255) and ``ring``
``/CAM_*/image``            ``redrive/Image``         rgb8 JPEG, frame ``CAM_*``, the camera's own
                                                      stamp
``/CAM_*/camera_info``      ``redrive/CameraInfo``    K = ``camera_intrinsic``, P = [K | 0], no
                                                      distortion (nuScenes images are undistorted)
``/ego_pose``               ``redrive/VehicleState``  the ego pose of the LiDAR sweep, frame ``map``
                                                      (nuScenes' global frame)
``/annotations``            ``redrive/GroundTruth…``  the sample's boxes in ``base_link`` at the
                                                      LiDAR's stamp
==========================  ========================  =============================================

Every message of a sample has the sample's (its LiDAR sweep's) stamp as its log time, the
calibration first; header stamps (``Decoded.stamp_ns``) are each sensor's own — the cameras are
exposed up to ~45 ms before the sweep's stamp — and frames pair sensors by those.

The points are *rotated* from the sensor's axes into base_link's, around the sensor's origin
(frame ``LIDAR_TOP_base_axes``: ``LIDAR_TOP``'s origin, base_link's axes).  redrive's data model
places a sensor by ``sensor_location`` only (no mount rotation), and nuScenes' LIDAR_TOP is turned
90° about z: points left in its own axes would come out turned in everything that moves them by
``sensor_location`` (the reference detector, templates).

Classes: a nuScenes category (``vehicle.car``) or detection name (``car``) → :class:`ObjectClass`
through the devkit's detection classes (:data:`DETECTION_NAME_OF_CATEGORY`): car → VEHICLE;
truck, bus, trailer, construction_vehicle → TRUCK; pedestrian, bicycle, motorcycle; barrier and
traffic_cone → STATIC; the categories the devkit ignores (animals, strollers, emergency vehicles,
debris …) → OTHER.  ``redrive evaluate``'s ``nuscenes_detection`` scores car, truck, pedestrian,
bicycle and motorcycle by default.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType, TracebackType
from typing import Self

import numpy as np
import numpy.typing as npt
from PIL import Image as PilImage

from redrive.errors import LogError, UnsupportedMessageError
from redrive.geometry.se3 import (
    transform_from_matrix,
    transform_points,
    yaw_from_rotation_matrix,
    yaw_pitch_roll_from_rotation_matrices,
)
from redrive.io.base import DecodedKind, LogMessage, ReaderCapabilities, TopicInfo
from redrive.io.ros.decoders.base import Decoded, DecodedValue
from redrive.types import (
    Box3D,
    CameraInfo,
    DetectedObject,
    Image,
    ObjectClass,
    PointCloud,
    SensorType,
    Transform,
    VehicleState,
)

__all__ = [
    "CAMERA_CHANNELS",
    "DETECTION_NAME_OF_CATEGORY",
    "LIDAR_AXES_FRAME",
    "LIDAR_CHANNEL",
    "TOPIC_ANNOTATIONS",
    "TOPIC_EGO_POSE",
    "TOPIC_LIDAR",
    "TOPIC_TF_STATIC",
    "NuScenesCamera",
    "NuScenesReaderBase",
    "NuScenesSample",
    "boxes_to_base",
    "gravity_aligned_rotations",
    "object_class_of",
    "read_lidar_bin",
    "velocity_and_yaw_rate",
    "yaw_rotations",
]

logger = logging.getLogger(__name__)

LIDAR_CHANNEL = "LIDAR_TOP"
#: the point cloud's frame: LIDAR_TOP's origin with base_link's axes (see the module docstring).
LIDAR_AXES_FRAME = "LIDAR_TOP_base_axes"
CAMERA_CHANNELS = (
    "CAM_FRONT",
    "CAM_FRONT_RIGHT",
    "CAM_BACK_RIGHT",
    "CAM_BACK",
    "CAM_BACK_LEFT",
    "CAM_FRONT_LEFT",
)
TOPIC_TF_STATIC = "/tf_static"
TOPIC_LIDAR = "/LIDAR_TOP"
TOPIC_EGO_POSE = "/ego_pose"
TOPIC_ANNOTATIONS = "/annotations"
_POINT_FLOATS = 5  # x, y, z, intensity, ring

#: nuScenes category → detection name (devkit ``eval/detection/utils.py``,
#: ``category_to_detection_name``); categories not listed are ignored by the benchmark.
DETECTION_NAME_OF_CATEGORY: Mapping[str, str] = MappingProxyType(
    {
        "movable_object.barrier": "barrier",
        "vehicle.bicycle": "bicycle",
        "vehicle.bus.bendy": "bus",
        "vehicle.bus.rigid": "bus",
        "vehicle.car": "car",
        "vehicle.construction": "construction_vehicle",
        "vehicle.motorcycle": "motorcycle",
        "human.pedestrian.adult": "pedestrian",
        "human.pedestrian.child": "pedestrian",
        "human.pedestrian.construction_worker": "pedestrian",
        "human.pedestrian.police_officer": "pedestrian",
        "movable_object.trafficcone": "traffic_cone",
        "vehicle.trailer": "trailer",
        "vehicle.truck": "truck",
    }
)
_CLASS_OF_DETECTION_NAME: Mapping[str, ObjectClass] = MappingProxyType(
    {
        "car": ObjectClass.VEHICLE,
        "truck": ObjectClass.TRUCK,
        "bus": ObjectClass.TRUCK,
        "trailer": ObjectClass.TRUCK,
        "construction_vehicle": ObjectClass.TRUCK,
        "pedestrian": ObjectClass.PEDESTRIAN,
        "bicycle": ObjectClass.BICYCLE,
        "motorcycle": ObjectClass.MOTORCYCLE,
        "barrier": ObjectClass.STATIC,
        "traffic_cone": ObjectClass.STATIC,
    }
)


def object_class_of(name: str) -> ObjectClass:
    """The ObjectClass of a nuScenes category (``vehicle.car``) or detection name (``car``);
    OTHER for what the detection benchmark ignores."""
    detection = DETECTION_NAME_OF_CATEGORY.get(name, name)
    return _CLASS_OF_DETECTION_NAME.get(detection, ObjectClass.OTHER)


@dataclass(frozen=True, slots=True, kw_only=True)
class NuScenesCamera:
    """One camera image of a sample.

    Attributes:
        channel: ``CAM_FRONT`` …
        path: the JPEG.
        stamp_ns: the image's own timestamp, int ns.
        intrinsic: (3, 3) float64 K, pixels.
        ego_from_camera: (4, 4) float64, optical frame → ego frame (calibrated sensor).
    """

    channel: str
    path: Path
    stamp_ns: int
    intrinsic: npt.NDArray[np.float64]
    ego_from_camera: npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True, kw_only=True)
class NuScenesSample:
    """One keyframe, in redrive's frames.

    Attributes:
        token: the nuScenes sample token ("" when the source has none).
        stamp_ns: the LiDAR sweep's timestamp (the sample's), int ns.
        lidar_path: the ``.pcd.bin`` (5 float32 per point).
        ego_from_lidar: (4, 4) float64, LIDAR_TOP → ego frame.
        global_from_ego: (4, 4) float64, the ego pose at the sweep.
        ego_velocity_mps: (3,) float64 in the global frame (zeros when unknown).
        ego_yaw_rate_rad_s: heading rate (0 when unknown).
        cameras: the camera images, in :data:`CAMERA_CHANNELS` order.
        objects: ground truth in base_link at ``stamp_ns``.
    """

    token: str
    stamp_ns: int
    lidar_path: Path
    ego_from_lidar: npt.NDArray[np.float64]
    global_from_ego: npt.NDArray[np.float64]
    ego_velocity_mps: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    ego_yaw_rate_rad_s: float = 0.0
    cameras: tuple[NuScenesCamera, ...] = ()
    objects: tuple[DetectedObject, ...] = ()


def read_lidar_bin(path: Path) -> PointCloud:
    """A nuScenes ``.pcd.bin``: float32 x, y, z, intensity, ring per point (sensor frame).

    Raises:
        LogError: unreadable, or its size is not a multiple of 20 bytes.
    """
    try:
        raw = np.fromfile(path, dtype="<f4")
    except OSError as err:
        msg = f"{path}: cannot read the LiDAR sweep ({err.strerror}); check the file"
        raise LogError(msg) from err
    if raw.size % _POINT_FLOATS:
        msg = (
            f"{path}: {raw.nbytes} bytes is not a multiple of 20 (float32 x, y, z, intensity, "
            "ring per point); the sweep is truncated or not a nuScenes .pcd.bin, restore it"
        )
        raise LogError(msg)
    points = raw.reshape(-1, _POINT_FLOATS)
    return PointCloud(
        xyz=np.ascontiguousarray(points[:, :3]),
        channels={
            "intensity": np.ascontiguousarray(points[:, 3]),
            "ring": points[:, 4].astype(np.uint16),
        },
    )


def _camera_topic(channel: str, what: str) -> str:
    return f"/{channel}/{what}"


class NuScenesReaderBase:
    """Streams :class:`NuScenesSample` values as a native log; subclasses fill ``_samples``
    (stamp order) and set ``path``, ``format`` and ``description``."""

    format: str
    description: str
    path: Path
    _samples: Sequence[NuScenesSample]

    def _init_topics(self) -> None:
        present = {cam.channel for s in self._samples for cam in s.cameras}
        channels = [c for c in CAMERA_CHANNELS if c in present]
        count = len(self._samples)
        kinds: dict[str, tuple[str, DecodedKind, SensorType | None, int]] = {
            TOPIC_TF_STATIC: ("redrive/Transforms", DecodedKind.TRANSFORMS, None, count),
            TOPIC_LIDAR: ("redrive/PointCloud", DecodedKind.SENSOR, SensorType.LIDAR, count),
        }
        for channel in channels:
            n = sum(1 for s in self._samples for cam in s.cameras if cam.channel == channel)
            kinds[_camera_topic(channel, "image")] = (
                "redrive/Image",
                DecodedKind.SENSOR,
                SensorType.CAMERA,
                n,
            )
            kinds[_camera_topic(channel, "camera_info")] = (
                "redrive/CameraInfo",
                DecodedKind.CAMERA_INFO,
                None,
                n,
            )
        kinds[TOPIC_EGO_POSE] = (
            "redrive/VehicleState",
            DecodedKind.VEHICLE_STATE,
            SensorType.ODOMETRY,
            count,
        )
        kinds[TOPIC_ANNOTATIONS] = ("redrive/GroundTruthObjects", DecodedKind.OBJECTS, None, count)
        self._topics = MappingProxyType(
            {
                t: TopicInfo(topic=t, msgtype=m, count=n, encoding="native", kind=k, sensor_type=st)
                for t, (m, k, st, n) in kinds.items()
            }
        )

    # -- summary -------------------------------------------------------------------------------

    @property
    def capabilities(self) -> ReaderCapabilities:
        """Native values; transforms from the calibrated sensors, ground truth, ego poses; a
        calibration per sample (the sensors' calibration differs between logs)."""
        return ReaderCapabilities(
            message_typed=False,
            has_tf=True,
            has_ground_truth=True,
            has_ego_pose=True,
            calibration_per_frame=True,
        )

    @property
    def topics(self) -> Mapping[str, TopicInfo]:
        return self._topics

    @property
    def samples(self) -> tuple[NuScenesSample, ...]:
        """The keyframes, in stamp order."""
        return tuple(self._samples)

    @property
    def start_ns(self) -> int:
        return self._samples[0].stamp_ns if self._samples else 0

    @property
    def end_ns(self) -> int:
        return self._samples[-1].stamp_ns if self._samples else 0

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    # -- reading -------------------------------------------------------------------------------

    def _messages_of(self, sample: NuScenesSample) -> list[tuple[str, Callable[[], Decoded]]]:
        """(topic, loader) of one sample's messages, in the order they are yielded: the
        calibration before the sensors it places."""
        t = sample.stamp_ns
        out: list[tuple[str, Callable[[], Decoded]]] = [
            (TOPIC_TF_STATIC, lambda: self._load_tf(sample))
        ]
        for cam in sample.cameras:
            out.append((_camera_topic(cam.channel, "camera_info"), _info_loader(cam)))
        for cam in sample.cameras:
            out.append((_camera_topic(cam.channel, "image"), _image_loader(cam)))
        out += [
            (TOPIC_LIDAR, lambda: self._load_lidar(sample)),
            (TOPIC_EGO_POSE, lambda: self._load_ego(sample)),
            (TOPIC_ANNOTATIONS, lambda: _decoded(t, "base_link", sample.objects)),
        ]
        return out

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        for sample in self._samples:
            stamp_ns = sample.stamp_ns
            if (start_ns is not None and stamp_ns < start_ns) or (
                stop_ns is not None and stamp_ns >= stop_ns
            ):
                continue
            logger.debug("nuScenes sample %s at %d ns", sample.token, stamp_ns)
            for topic, load in self._messages_of(sample):
                if topics is not None and topic not in topics:
                    continue
                yield LogMessage(
                    topic=topic,
                    msgtype=self._topics[topic].msgtype,
                    log_time_ns=stamp_ns,
                    encoding="native",
                    payload=load(),
                )

    def _load_tf(self, sample: NuScenesSample) -> Decoded:
        transforms: list[Transform] = [
            transform_from_matrix(
                sample.ego_from_lidar, parent_frame="base_link", child_frame=LIDAR_CHANNEL
            ),
            Transform(
                parent_frame="base_link",
                child_frame=LIDAR_AXES_FRAME,
                translation=sample.ego_from_lidar[:3, 3].copy(),
            ),
        ]
        transforms += [
            transform_from_matrix(
                cam.ego_from_camera, parent_frame="base_link", child_frame=cam.channel
            )
            for cam in sample.cameras
        ]
        return _decoded(sample.stamp_ns, "base_link", tuple(transforms))

    def _load_ego(self, sample: NuScenesSample) -> Decoded:
        pose = sample.global_from_ego
        state = VehicleState(
            stamp_ns=sample.stamp_ns,
            frame_id="map",
            position=pose[:3, 3].copy(),
            velocity=sample.ego_velocity_mps,
            heading_rad=yaw_from_rotation_matrix(pose[:3, :3]),
            yaw_rate_rad_s=sample.ego_yaw_rate_rad_s,
        )
        return _decoded(sample.stamp_ns, "map", state)

    def _load_lidar(self, sample: NuScenesSample) -> Decoded:
        cloud = read_lidar_bin(sample.lidar_path)
        rotation = sample.ego_from_lidar[:3, :3]
        xyz = (cloud.xyz.astype(np.float64) @ rotation.T).astype(np.float32)
        turned = PointCloud(xyz=np.ascontiguousarray(xyz), channels=dict(cloud.channels))
        return _decoded(sample.stamp_ns, LIDAR_AXES_FRAME, turned)

    def deserialize(self, message: LogMessage) -> object:
        """nuScenes messages are already decoded (``message.payload``); there are no ROS bytes.

        Raises:
            UnsupportedMessageError: always.
        """
        msg = (
            f"{self.path}: topic {message.topic} at {message.log_time_ns} ns is a native nuScenes "
            "message; use message.payload (a Decoded) instead of deserialize()"
        )
        raise UnsupportedMessageError(msg)

    def close(self) -> None:
        """Nothing is held open: files are read one at a time while streaming."""

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _decoded(stamp_ns: int, frame_id: str, value: DecodedValue) -> Decoded:
    return Decoded(stamp_ns=stamp_ns, frame_id=frame_id, value=value)


def _info_loader(cam: NuScenesCamera) -> Callable[[], Decoded]:
    def load() -> Decoded:
        try:
            with PilImage.open(cam.path) as img:  # reads the header only
                width, height = img.size
        except OSError as err:
            msg = f"{cam.path}: cannot read the {cam.channel} image ({err}); restore the JPEG"
            raise LogError(msg) from err
        p = np.zeros((3, 4))
        p[:, :3] = cam.intrinsic
        info = CameraInfo(width=width, height=height, k=cam.intrinsic.copy(), d=np.zeros(0), p=p)
        return _decoded(cam.stamp_ns, cam.channel, info)

    return load


def _image_loader(cam: NuScenesCamera) -> Callable[[], Decoded]:
    def load() -> Decoded:
        try:
            with PilImage.open(cam.path) as img:
                pixels = np.asarray(img.convert("RGB"), dtype=np.uint8)
        except (OSError, ValueError) as err:
            msg = f"{cam.path}: cannot read the {cam.channel} image ({err}); restore the JPEG"
            raise LogError(msg) from err
        return _decoded(cam.stamp_ns, cam.channel, Image(pixels=pixels, encoding="rgb8"))

    return load


def boxes_to_base(
    *,
    centers: npt.NDArray[np.float64],
    sizes_lwh: npt.NDArray[np.float64],
    rotations: npt.NDArray[np.float64],
    velocities: npt.NDArray[np.float64],
    base_from_src: npt.NDArray[np.float64],
    classes: Sequence[ObjectClass],
    num_lidar_points: Sequence[int | None],
    object_ids: Sequence[int] | None = None,
) -> tuple[DetectedObject, ...]:
    """Boxes given in a source frame (centres (N, 3), l w h (N, 3), rotations (N, 3, 3) of the
    box axes — x along its length —, velocities (N, 3) with NaN for unknown) as ground truth in
    base_link.  The yaw is that of the whole rotation moved into base_link, as the devkit's
    ``Box.rotate`` then ``quaternion_yaw``; the object's ``orientation`` keeps the whole
    rotation as yaw, pitch and roll (``Rz Ry Rx``): a box upright in the global frame is tilted
    in a tilted ego's base_link, and the devkit counts its points that way."""
    n = len(classes)
    if n == 0:
        return ()
    rot = base_from_src[:3, :3]
    out_centers = transform_points(base_from_src, np.asarray(centers, dtype=np.float64))
    turned = rot @ np.asarray(rotations, dtype=np.float64)
    angles = yaw_pitch_roll_from_rotation_matrices(turned)
    out_yaws = angles[:, 0]
    vel = np.nan_to_num(np.asarray(velocities, dtype=np.float64), nan=0.0) @ rot.T
    ids = object_ids if object_ids is not None else [-1] * n
    out = []
    for i in range(n):
        yaw = float(out_yaws[i])
        out.append(
            DetectedObject(
                object_id=int(ids[i]),
                object_class=classes[i],
                confidence=1.0,
                box=Box3D(center=out_centers[i], size=sizes_lwh[i], yaw_rad=yaw),
                velocity=vel[i],
                orientation=angles[i],
                num_lidar_points=num_lidar_points[i],
            )
        )
    return tuple(out)


def gravity_aligned_rotations(
    yaws_rad: npt.NDArray[np.float64], global_from_src: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """(N, 3, 3) rotations in a source frame of boxes that are upright in the *global* frame
    (a nuScenes ``sample_annotation``'s rotation turns about the global z only) and whose heading
    in the source frame is ``yaws_rad`` (N,) — the heading that mmdet3d's info converter keeps of
    the devkit's box after ``Box.rotate`` into the LiDAR frame.  The global
    heading θ solves ``yaw(src_from_global · Rz(θ)) = yaw``; a few Newton-free fixed-point steps
    reach float64 precision, since a tilt of a few degrees changes the heading's slope by
    far less than one."""
    yaws = np.asarray(yaws_rad, dtype=np.float64)
    src_from_global = np.asarray(global_from_src, dtype=np.float64)[:3, :3].T
    theta = yaws + yaw_from_rotation_matrix(src_from_global.T)
    for _ in range(8):
        turned = src_from_global @ yaw_rotations(theta)
        error = np.arctan2(
            np.sin(yaws - np.arctan2(turned[:, 1, 0], turned[:, 0, 0])),
            np.cos(yaws - np.arctan2(turned[:, 1, 0], turned[:, 0, 0])),
        )
        theta = theta + error
        if np.all(np.abs(error) < 1e-12):
            break
    out: npt.NDArray[np.float64] = src_from_global @ yaw_rotations(theta)
    return out


def yaw_rotations(yaws_rad: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(N, 3, 3) rotations about +z by ``yaws_rad`` (N,)."""
    c, s = np.cos(yaws_rad), np.sin(yaws_rad)
    out = np.zeros((len(yaws_rad), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = c, -s, s, c
    out[:, 2, 2] = 1.0
    return out


def velocity_and_yaw_rate(
    poses: Sequence[npt.NDArray[np.float64]], stamps_ns: Sequence[int]
) -> list[tuple[npt.NDArray[np.float64], float]]:
    """Per pose, (velocity (3,) m/s in the global frame, yaw rate rad/s) from its neighbours
    (central differences; one-sided at the ends; zeros for a lone pose)."""
    n = len(poses)
    out: list[tuple[npt.NDArray[np.float64], float]] = []
    for i in range(n):
        lo, hi = max(i - 1, 0), min(i + 1, n - 1)
        dt = (stamps_ns[hi] - stamps_ns[lo]) * 1e-9
        if hi == lo or dt <= 0:
            out.append((np.zeros(3), 0.0))
            continue
        velocity = (poses[hi][:3, 3] - poses[lo][:3, 3]) / dt
        dyaw = math.remainder(
            yaw_from_rotation_matrix(poses[hi][:3, :3])
            - yaw_from_rotation_matrix(poses[lo][:3, :3]),
            math.tau,
        )
        out.append((velocity, dyaw / dt))
    return out
