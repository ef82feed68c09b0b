"""An Argoverse 2 sensor-dataset log folder read as a log (format ``av2-sensor``).

Written on the layout and conventions of ``argoverse/av2-api`` (the package is not needed):
``path`` is one log folder (``<split>/<log_id>/``)::

    city_SE3_egovehicle.feather       ego poses: timestamp_ns, qw qx qy qz, tx_m ty_m tz_m (city)
    annotations.feather               cuboids: timestamp_ns, track_uuid, category, length_m
                                      width_m height_m, qw qx qy qz, tx_m ty_m tz_m (ego frame),
                                      num_interior_pts
    calibration/egovehicle_SE3_sensor.feather   sensor_name, qw..qz, tx_m..tz_m (ego frame)
    sensors/lidar/<timestamp_ns>.feather        x y z (ego frame), intensity, laser_number,
                                                offset_ns
    map/log_map_archive_*.json        the vector map (lane segments, drivable areas, crossings),
                                      read by :func:`redrive.maps.av2.read_av2_map`

Conventions carried over from av2-api: a cuboid is in the **ego frame at its sweep's
timestamp** (``structures/cuboid.py``, ``CuboidList.from_feather``: ``ego_SE3_object`` from the
row's quaternion and translation; length along the object's x); a sweep's points are in the ego
frame, motion-compensated to the sweep's timestamp, the file's stem (``structures/sweep.py``,
``Sweep.from_feather``); the ego pose of a sweep is the pose row of exactly that timestamp
(``datasets/sensor/av2_sensor_dataloader.py``, ``get_city_SE3_ego``).  The ego frame (origin at
the rear axle's centre, x forward, z up) is redrive's ``base_link``; the city frame is ``map``.

Every annotated sweep (and every sweep file and camera image) is a time step, yielding at its
stamp:

===================  ==========================  ==============================================
topic                msgtype                     payload (:class:`Decoded` value)
===================  ==========================  ==============================================
``/tf_static``       ``redrive/Transforms``      ``base_link`` → every calibrated sensor (first
                                                 step only: AV2's calibration is per log)
``/lidar``           ``redrive/PointCloud``      the sweep (only where its file is present),
                                                 frame ``base_link``, channels ``intensity``,
                                                 ``ring`` (laser_number) and ``t_offset_ns``
``/cameras/C/image``  ``redrive/Image``           each image of camera C present
                                                 (``sensors/cameras/C/<stamp>.jpg``) at its own
                                                 stamp, rgb8, frame ``C`` (the optical frame the
                                                 extrinsics place)
``/cameras/C/camera_  ``redrive/CameraInfo``      C's intrinsics with each image
info``                                           (:mod:`redrive.io.datasets.av2_cameras`)
``/ego_pose``        ``redrive/VehicleState``    the ego pose, frame ``map``; velocity and yaw
                                                 rate by central differences of the steps' poses
``/annotations``     ``redrive/GroundTruth…``    the sweep's cuboids in ``base_link``
===================  ==========================  ==============================================

Ground truth: ``object_id`` numbers the tracks (``track_uuid``) in the order they first appear;
the velocity, which AV2 does not annotate, is redrive's: the central difference of the track's
centres in the city frame over its previous and next annotations (one-sided at its ends, zero for
a lone cuboid or a gap over 1.5 s), turned into the ego frame.  Classes: :data:`CLASS_OF_CATEGORY`.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import LogError, MapError
from redrive.geometry.se3 import transform_from_matrix, yaw_from_rotation_matrix
from redrive.io.base import DecodedKind, ReaderCapabilities
from redrive.io.datasets import av2_cameras as cams
from redrive.io.datasets._feather import read_feather_columns, rotations_from_wxyz
from redrive.io.datasets.native import Loader, NativeLogBase, NativeStep, decoded, native_topics
from redrive.io.datasets.nuscenes_common import velocity_and_yaw_rate
from redrive.types import (
    Box3D,
    DetectedObject,
    ObjectClass,
    PointCloud,
    RoadMap,
    SensorType,
    VehicleState,
)

__all__ = [
    "CLASS_OF_CATEGORY",
    "TOPIC_ANNOTATIONS",
    "TOPIC_EGO_POSE",
    "TOPIC_LIDAR",
    "Av2SensorLogReader",
]

logger = logging.getLogger(__name__)

TOPIC_TF_STATIC = "/tf_static"
TOPIC_LIDAR = "/lidar"
TOPIC_EGO_POSE = "/ego_pose"
TOPIC_ANNOTATIONS = "/annotations"
_POSES = "city_SE3_egovehicle.feather"
_ANNOTATIONS = "annotations.feather"
_EXTRINSICS = Path("calibration") / "egovehicle_SE3_sensor.feather"
_MAX_VELOCITY_GAP_NS = 1_500_000_000
#: an ego pose this close to a sweep's stamp stands for it when none has exactly that stamp
_POSE_TOLERANCE_NS = 20_000_000
_POSE_COLUMNS = ("timestamp_ns", "qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m")
_CUBOID_COLUMNS = (
    "timestamp_ns",
    "track_uuid",
    "category",
    "length_m",
    "width_m",
    "height_m",
    "qw",
    "qx",
    "qy",
    "qz",
    "tx_m",
    "ty_m",
    "tz_m",
)
_LIDAR_COLUMNS = ("x", "y", "z", "intensity", "laser_number", "offset_ns")

_V, _T, _P, _B, _M = (
    ObjectClass.VEHICLE,
    ObjectClass.TRUCK,
    ObjectClass.PEDESTRIAN,
    ObjectClass.BICYCLE,
    ObjectClass.MOTORCYCLE,
)
#: AV2 sensor-dataset category (``datasets/sensor/constants.py``, ``AnnotationCategories``) →
#: ObjectClass; the categories not listed (animals, strollers, wheelchairs, wheeled devices and
#: riders, railed vehicles) are OTHER.
CLASS_OF_CATEGORY: Mapping[str, ObjectClass] = MappingProxyType(
    {
        "REGULAR_VEHICLE": _V,
        "LARGE_VEHICLE": _T,
        "BUS": _T,
        "ARTICULATED_BUS": _T,
        "SCHOOL_BUS": _T,
        "BOX_TRUCK": _T,
        "TRUCK": _T,
        "TRUCK_CAB": _T,
        "VEHICULAR_TRAILER": _T,
        "PEDESTRIAN": _P,
        "OFFICIAL_SIGNALER": _P,
        "BICYCLE": _B,
        "BICYCLIST": _B,
        "MOTORCYCLE": _M,
        "MOTORCYCLIST": _M,
        "BOLLARD": ObjectClass.STATIC,
        "CONSTRUCTION_BARREL": ObjectClass.STATIC,
        "CONSTRUCTION_CONE": ObjectClass.STATIC,
        "SIGN": ObjectClass.STATIC,
        "STOP_SIGN": ObjectClass.STATIC,
        "MESSAGE_BOARD_TRAILER": ObjectClass.STATIC,
        "MOBILE_PEDESTRIAN_CROSSING_SIGN": ObjectClass.STATIC,
        "TRAFFIC_LIGHT_TRAILER": ObjectClass.STATIC,
    }
)


def _map_file(path: Path) -> Path | None:
    found = sorted((path / "map").glob("log_map_archive_*.json"))
    return found[0] if found else None


class Av2SensorLogReader(NativeLogBase):
    """One Argoverse 2 sensor-dataset log folder as a :class:`~redrive.io.base.LogReader`.

    Raises (at open):
        LogError: a required file is missing, is not Arrow IPC (cut off: the message names the
            byte where it ends), lacks a column, or holds a value that is not finite.
    """

    format = "av2-sensor"
    description = (
        "an Argoverse 2 sensor-dataset log folder (city_SE3_egovehicle.feather, "
        "annotations.feather, calibration/, sensors/lidar/, map/)"
    )

    @classmethod
    def recognises(cls, path: Path) -> bool:
        return path.is_dir() and (path / _POSES).is_file() and (path / _EXTRINSICS).is_file()

    def __init__(self, path: str | Path, *, strict: bool = True) -> None:
        """``strict``: see :mod:`redrive.io.datasets.native`; the tables are checked whole at open."""
        self.path = Path(path)
        self.strict = strict
        if not self.recognises(self.path):
            msg = (
                f"{self.path}: not an Argoverse 2 sensor log: it needs {_POSES} and "
                f"{_EXTRINSICS.as_posix()}; pass the log folder (<split>/<log_id>/)"
            )
            raise LogError(msg)
        poses = read_feather_columns(self.path / _POSES, _POSE_COLUMNS)
        order = np.argsort(poses["timestamp_ns"], kind="stable")
        self._pose_stamps = np.asarray(poses["timestamp_ns"], dtype=np.int64)[order]
        self._pose_rot = rotations_from_wxyz(
            np.stack([poses[c] for c in ("qw", "qx", "qy", "qz")], axis=1)[order],
            what=f"{self.path / _POSES} rotation",
        )
        self._pose_xyz = np.stack([poses[c] for c in ("tx_m", "ty_m", "tz_m")], axis=1)[order]
        self._extrinsics = self._read_extrinsics()
        annotations = self.path / _ANNOTATIONS
        cuboids = (
            read_feather_columns(annotations, _CUBOID_COLUMNS) if annotations.is_file() else None
        )
        self._lidar_files = {
            int(p.stem): p
            for p in (self.path / "sensors" / "lidar").glob("*.feather")
            if p.stem.isdigit()
        }
        stamps = set(self._lidar_files)
        if cuboids is not None:
            stamps.update(int(t) for t in np.unique(cuboids["timestamp_ns"]))
        self._stamps = sorted(stamps)
        self._objects = self._ground_truth(cuboids) if cuboids is not None else {}
        self._track_count = 0 if cuboids is None else len(np.unique(cuboids["track_uuid"]))
        self._cuboid_count = 0 if cuboids is None else len(cuboids["timestamp_ns"])
        self._map_path = _map_file(self.path)
        self._road_map: RoadMap | None = None
        self._has_labels = cuboids is not None
        self._camera_files = cams.camera_images(self.path)
        self._camera_infos = cams.camera_infos(self.path, set(self._camera_files))
        self._steps = self._schedule()
        kinds: dict[str, tuple[str, DecodedKind, SensorType | None]] = {
            TOPIC_TF_STATIC: ("redrive/Transforms", DecodedKind.TRANSFORMS, None),
            TOPIC_LIDAR: ("redrive/PointCloud", DecodedKind.SENSOR, SensorType.LIDAR),
            TOPIC_EGO_POSE: (
                "redrive/VehicleState",
                DecodedKind.VEHICLE_STATE,
                SensorType.ODOMETRY,
            ),
            TOPIC_ANNOTATIONS: ("redrive/GroundTruthObjects", DecodedKind.OBJECTS, None),
        }
        for camera in self._camera_files:
            kinds[cams.info_topic(camera)] = ("redrive/CameraInfo", DecodedKind.CAMERA_INFO, None)
            kinds[cams.image_topic(camera)] = (
                "redrive/Image",
                DecodedKind.SENSOR,
                SensorType.CAMERA,
            )
        self._topics = native_topics(self._steps, kinds)
        self.capabilities = ReaderCapabilities(
            message_typed=False,
            has_tf=True,
            has_ground_truth=cuboids is not None,
            has_ego_pose=True,
            road_map=self._map_path is not None,
            contents=True,
        )

    # -- tables ----------------------------------------------------------------------------------

    def _read_extrinsics(self) -> dict[str, npt.NDArray[np.float64]]:
        path = self.path / _EXTRINSICS
        table = read_feather_columns(
            path, ("sensor_name", "qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m")
        )
        rot = rotations_from_wxyz(
            np.stack([table[c] for c in ("qw", "qx", "qy", "qz")], axis=1), what=f"{path} rotation"
        )
        out = {}
        for i, name in enumerate(table["sensor_name"]):
            m = np.eye(4)
            m[:3, :3] = rot[i]
            m[:3, 3] = [table["tx_m"][i], table["ty_m"][i], table["tz_m"][i]]
            out[str(name)] = m
        return out

    def _pose_index(self, stamp_ns: int) -> int | None:
        """The pose row of ``stamp_ns`` (av2's exact match), else the nearest within 20 ms."""
        stamps = self._pose_stamps
        i = int(np.searchsorted(stamps, stamp_ns))
        best = None
        for j in (i - 1, i):
            if 0 <= j < len(stamps):
                dt = abs(int(stamps[j]) - stamp_ns)
                if dt <= _POSE_TOLERANCE_NS and (best is None or dt < best[0]):
                    best = (dt, j)
        return None if best is None else best[1]

    def _city_from_ego(self, j: int) -> npt.NDArray[np.float64]:
        m = np.eye(4)
        m[:3, :3] = self._pose_rot[j]
        m[:3, 3] = self._pose_xyz[j]
        return m

    def _ground_truth(
        self, cuboids: Mapping[str, npt.NDArray[Any]]
    ) -> dict[int, tuple[DetectedObject, ...]]:
        path = self.path / _ANNOTATIONS
        stamps = np.asarray(cuboids["timestamp_ns"], dtype=np.int64)
        uuids = np.asarray(cuboids["track_uuid"]).astype(str)
        rot = rotations_from_wxyz(
            np.stack([cuboids[c] for c in ("qw", "qx", "qy", "qz")], axis=1),
            what=f"{path} rotation",
        )
        centers = np.stack([cuboids[c] for c in ("tx_m", "ty_m", "tz_m")], axis=1).astype(
            np.float64
        )
        sizes = np.stack([cuboids[c] for c in ("length_m", "width_m", "height_m")], axis=1)
        for name, values in (("centre", centers), ("size", sizes)):
            bad = np.flatnonzero(~np.all(np.isfinite(values), axis=1))
            if bad.size:
                msg = (
                    f"{path}: row {int(bad[0])} (track {uuids[bad[0]]}, {int(stamps[bad[0]])} ns) "
                    f"has a cuboid {name} that is not finite; the table is damaged, restore it"
                )
                raise LogError(msg)
        # the ego pose of each row's sweep
        pose_of_stamp: dict[int, int] = {}
        for t in np.unique(stamps):
            j = self._pose_index(int(t))
            if j is None:
                msg = (
                    f"{self.path / _POSES}: no ego pose at {int(t)} ns (within 20 ms), the "
                    "stamp of annotated sweep; the pose table is incomplete, restore it"
                )
                raise LogError(msg)
            pose_of_stamp[int(t)] = j
        rows_pose = np.array([pose_of_stamp[int(t)] for t in stamps], dtype=np.int64)
        ego_rot = self._pose_rot[rows_pose]
        city_centers = np.einsum("nij,nj->ni", ego_rot, centers) + self._pose_xyz[rows_pose]
        velocity_city = _track_velocities(uuids, stamps, city_centers)
        velocity_ego = np.einsum("nji,nj->ni", ego_rot, velocity_city)  # R^T v
        yaws = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
        first_seen: dict[str, int] = {}
        for u in uuids[np.lexsort((uuids, stamps))]:
            first_seen.setdefault(str(u), len(first_seen))
        categories = np.asarray(cuboids["category"]).astype(str)
        points = cuboids.get("num_interior_pts")
        by_stamp: dict[int, list[DetectedObject]] = {}
        for i in np.lexsort((uuids, stamps)):
            yaw = float(yaws[i])
            n_pts = None if points is None else int(points[i])
            by_stamp.setdefault(int(stamps[i]), []).append(
                DetectedObject(
                    object_id=first_seen[str(uuids[i])],
                    object_class=CLASS_OF_CATEGORY.get(str(categories[i]), ObjectClass.OTHER),
                    confidence=1.0,
                    box=Box3D(center=centers[i], size=sizes[i], yaw_rad=yaw),
                    velocity=velocity_ego[i],
                    orientation=np.array([yaw, 0.0, 0.0]),
                    num_lidar_points=n_pts if n_pts is None or n_pts >= 0 else None,
                )
            )
        return {t: tuple(objs) for t, objs in by_stamp.items()}

    # -- the schedule ----------------------------------------------------------------------------

    def _schedule(self) -> list[NativeStep]:
        pose_rows = [self._pose_index(t) for t in self._stamps]
        known = [(t, j) for t, j in zip(self._stamps, pose_rows, strict=True) if j is not None]
        motion = velocity_and_yaw_rate(
            [self._city_from_ego(j) for _, j in known], [t for t, _ in known]
        )
        states = {
            t: VehicleState(
                stamp_ns=t,
                frame_id="map",
                position=self._pose_xyz[j].copy(),
                velocity=velocity,
                heading_rad=yaw_from_rotation_matrix(self._pose_rot[j]),
                yaw_rate_rad_s=yaw_rate,
            )
            for (t, j), (velocity, yaw_rate) in zip(known, motion, strict=True)
        }
        sweeps = set(self._stamps)
        images: dict[int, list[tuple[str, Path]]] = {}
        for camera, files in self._camera_files.items():
            for stamp, path in files.items():
                images.setdefault(stamp, []).append((camera, path))
        steps = []
        for k, t in enumerate(sorted(sweeps | set(images))):
            messages: list[tuple[str, Loader]] = []
            if k == 0:
                messages.append((TOPIC_TF_STATIC, self._tf_loader(t)))
            for camera, path in sorted(images.get(t, ())):
                info = self._camera_infos[camera]
                messages.append((cams.info_topic(camera), _const(t, camera, info)))
                messages.append((cams.image_topic(camera), cams.image_loader(camera, t, path)))
            if t not in sweeps:
                steps.append(NativeStep(stamp_ns=t, messages=tuple(messages)))
                continue
            if t in self._lidar_files:
                messages.append((TOPIC_LIDAR, self._lidar_loader(t)))
            if t in states:
                messages.append((TOPIC_EGO_POSE, _const(t, "map", states[t])))
            if self._has_labels:
                messages.append(
                    (TOPIC_ANNOTATIONS, _const(t, "base_link", self._objects.get(t, ())))
                )
            steps.append(NativeStep(stamp_ns=t, messages=tuple(messages)))
        return steps

    def _tf_loader(self, stamp_ns: int) -> Loader:
        transforms = tuple(
            transform_from_matrix(m, parent_frame="base_link", child_frame=name)
            for name, m in sorted(self._extrinsics.items())
        )
        return _const(stamp_ns, "base_link", transforms)

    def _lidar_loader(self, stamp_ns: int) -> Loader:
        path = self._lidar_files[stamp_ns]

        def load() -> Any:
            cols = read_feather_columns(path, _LIDAR_COLUMNS)
            xyz = np.stack([cols["x"], cols["y"], cols["z"]], axis=1).astype(np.float32)
            cloud = PointCloud(
                xyz=np.ascontiguousarray(xyz),
                channels={
                    "intensity": np.asarray(cols["intensity"], dtype=np.float32),
                    "ring": np.asarray(cols["laser_number"], dtype=np.uint16),
                    "t_offset_ns": np.asarray(cols["offset_ns"], dtype=np.int64),
                },
            )
            return decoded(stamp_ns, "base_link", cloud)

        return load

    # -- content ---------------------------------------------------------------------------------

    def contents(self) -> dict[str, int | str]:
        out: dict[str, int | str] = {
            "annotated sweeps": len(self._objects),
            "tracks": self._track_count,
            "cuboids": self._cuboid_count,
            "LiDAR sweeps present": len(self._lidar_files),
            "camera images present": sum(len(f) for f in self._camera_files.values()),
            "ego poses": len(self._pose_stamps),
            "calibrated sensors": len(self._extrinsics),
        }
        try:
            road_map = self.road_map()
        except MapError as err:  # the log's other content is still worth listing
            out["map"] = f"unreadable ({err})"
            return out
        if road_map is not None:
            out["lane segments"] = len(road_map.lanes)
            out["drivable areas"] = len(road_map.areas)
            out["pedestrian crossings"] = len(road_map.crosswalks)
        return out

    def road_map(self) -> RoadMap | None:
        """The log's vector map in the road-map model (``map`` = AV2's city frame).

        Raises:
            MapError: the map file is cut or an element of it is not valid (named).
        """
        if self._map_path is None:
            return None
        if self._road_map is None:
            from redrive.maps.av2 import read_av2_map

            self._road_map = read_av2_map(self._map_path)
        return self._road_map


def _const(stamp_ns: int, frame_id: str, value: Any) -> Loader:
    return lambda: decoded(stamp_ns, frame_id, value)


def _track_velocities(
    uuids: npt.NDArray[np.str_], stamps: npt.NDArray[np.int64], centers: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """(N, 3) m/s per row: the central difference of its track's centres (one-sided at the
    ends; zero for a lone row or a gap over 1.5 s)."""
    out = np.zeros((len(uuids), 3))
    order = np.lexsort((stamps, uuids))
    start = 0
    n = len(order)
    while start < n:
        stop = start
        while stop < n and uuids[order[stop]] == uuids[order[start]]:
            stop += 1
        rows = order[start:stop]
        for k, row in enumerate(rows):
            lo = rows[max(k - 1, 0)]
            hi = rows[min(k + 1, len(rows) - 1)]
            dt_ns = int(stamps[hi]) - int(stamps[lo])
            limit = _MAX_VELOCITY_GAP_NS * (2 if row not in (lo, hi) else 1)
            if 0 < dt_ns <= limit:
                out[row] = (centers[hi] - centers[lo]) / (dt_ns * 1e-9)
        start = stop
    return out
