"""A KITTI 3D-object folder read as a log.

Layout (``path`` is the folder that holds ``training/`` or ``testing/``, or one of those)::

    velodyne/NNNNNN.bin   float32 x, y, z, reflectance per point (required)
    calib/NNNNNN.txt      P0..P3, R0_rect, Tr_velo_to_cam, Tr_imu_to_velo (required)
    image_2/NNNNNN.png    left colour camera (optional folder)
    label_2/NNNNNN.txt    ground truth (optional folder; ``testing`` has none)

KITTI object frames are independent snapshots with **no time**: frame ``NNNNNN`` gets the
synthetic stamp ``NNNNNN * 100 ms`` (10 Hz, the HDL-64E rate), used as both log time and header
stamp.  Every frame yields, in this order and with that stamp:

=================  ====================================  =========================================
topic              msgtype                               payload (:class:`Decoded` value)
=================  ====================================  =========================================
``/tf_static``     ``redrive/Transforms``                the calibration chain, rooted at
                                                         ``base_link`` (≡ ``velodyne``: identity),
                                                         transforms static (stamp 0); sent every
                                                         frame (calibrations differ)
``/kitti/velodyne``  ``redrive/PointCloud``               PointCloud, channel ``intensity``, frame
                                                         ``velodyne``
``/kitti/image_2``   ``redrive/Image``                   Image rgb8, frame ``cam2``
``/kitti/camera_info``  ``redrive/CameraInfo``           CameraInfo of image_2 in frame ``cam2``
                                                         (rectified): K = P2[:, :3], P = [K | 0]
                                                         (cam2's offset is in the tf chain), R = I,
                                                         no distortion; only with ``image_2/``
``/kitti/label_2``   ``redrive/GroundTruthObjects``        ground truth in the **velodyne** frame
=================  ====================================  =========================================

KITTI has no vehicle frame: the ground truth and the points are in the velodyne frame, so it is
made ``base_link`` as well (an identity transform ``base_link`` → ``velodyne``), and
:func:`redrive.assembly.calibration.camera_calibrations` (``image_from_base``) projects them into
``image_2`` as ``calibration(frame).image_from_velodyne(2)`` does.

Messages are ``native`` (already decoded); files are read one at a time while streaming.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection, Iterator, Mapping
from pathlib import Path
from types import MappingProxyType, TracebackType
from typing import Self

import numpy as np
from PIL import Image as PilImage

from redrive.errors import LogError, UnsupportedMessageError
from redrive.io.base import DecodedKind, LogMessage, ReaderCapabilities, TopicInfo
from redrive.io.datasets.kitti_calib import KittiCalibration, parse_calibration, parse_labels
from redrive.io.ros.decoders.base import Decoded, DecodedValue
from redrive.types import CameraInfo, Image, PointCloud, SensorType, Transform

__all__ = [
    "KITTI_FRAME_PERIOD_NS",
    "TOPIC_CAMERA_INFO",
    "TOPIC_IMAGE_2",
    "TOPIC_LABEL_2",
    "TOPIC_TF_STATIC",
    "TOPIC_VELODYNE",
    "KittiReader",
]

logger = logging.getLogger(__name__)

#: Synthetic time between KITTI frames: frame N is stamped N * 100 ms.
KITTI_FRAME_PERIOD_NS = 100_000_000

TOPIC_TF_STATIC = "/tf_static"
TOPIC_VELODYNE = "/kitti/velodyne"
TOPIC_IMAGE_2 = "/kitti/image_2"
TOPIC_CAMERA_INFO = "/kitti/camera_info"
TOPIC_LABEL_2 = "/kitti/label_2"

#: what each topic carries: its native type name (the data-model value its messages hold — KITTI has
#: no ROS types), and how the value is used.
_MSGTYPES: Mapping[str, str] = {
    TOPIC_TF_STATIC: "redrive/Transforms",
    TOPIC_VELODYNE: "redrive/PointCloud",
    TOPIC_IMAGE_2: "redrive/Image",
    TOPIC_CAMERA_INFO: "redrive/CameraInfo",
    TOPIC_LABEL_2: "redrive/GroundTruthObjects",
}
_KINDS: Mapping[str, tuple[DecodedKind, SensorType | None]] = {
    TOPIC_TF_STATIC: (DecodedKind.TRANSFORMS, None),
    TOPIC_VELODYNE: (DecodedKind.SENSOR, SensorType.LIDAR),
    TOPIC_IMAGE_2: (DecodedKind.SENSOR, SensorType.CAMERA),
    TOPIC_CAMERA_INFO: (DecodedKind.CAMERA_INFO, None),
    TOPIC_LABEL_2: (DecodedKind.OBJECTS, None),
}
# topic → (sub-folder, file suffix)
_FILES: Mapping[str, tuple[str, str]] = {
    TOPIC_TF_STATIC: ("calib", ".txt"),
    TOPIC_VELODYNE: ("velodyne", ".bin"),
    TOPIC_IMAGE_2: ("image_2", ".png"),
    TOPIC_CAMERA_INFO: ("image_2", ".png"),
    TOPIC_LABEL_2: ("label_2", ".txt"),
}
_POINT_BYTES = 16  # float32 x, y, z, reflectance
#: KITTI's vehicle frame is its LiDAR's: ``base_link`` → ``velodyne`` is the identity.
_BASE_FROM_VELODYNE = Transform(parent_frame="base_link", child_frame="velodyne")


def _find_root(path: Path) -> Path:
    for cand in (path, path / "training", path / "testing"):
        if (cand / "velodyne").is_dir():
            return cand
    msg = (
        f"{path}: not a KITTI object folder: no velodyne/ in it or in training/ or testing/; "
        "pass the folder that holds training/ (or training/ itself)"
    )
    raise LogError(msg)


class KittiReader:
    """A KITTI 3D-object folder as a :class:`~redrive.io.base.LogReader` (format ``kitti``).

    Raises (at open):
        LogError: no ``velodyne/``; a frame has files in calib/image_2/label_2 but no velodyne
            scan, or lacks a calib (or an image / label while the folder exists); a ``.bin``
            whose size is not a multiple of 16 bytes; a frame name that is not a number.
    """

    format = "kitti"
    description = (
        "a KITTI 3D-object folder (velodyne/ and calib/, optionally under training/ or testing/)"
    )

    @classmethod
    def recognises(cls, path: Path) -> bool:
        roots = [path, path / "training", path / "testing"]
        return path.is_dir() and any(
            (r / "velodyne").is_dir() and (r / "calib").is_dir() for r in roots
        )

    def __init__(self, path: str | Path, *, strict: bool = True) -> None:
        """``strict`` is accepted like every reader's; a KITTI folder is checked whole at open."""
        self.path = Path(path)
        if not self.path.is_dir():
            msg = f"{self.path}: not a directory; pass a KITTI object folder"
            raise LogError(msg)
        self.root = _find_root(self.path)
        self._topics_present = [
            t
            for t, (sub, _) in _FILES.items()
            if (self.root / sub).is_dir() or t == TOPIC_TF_STATIC
        ]
        stems: dict[str, set[str]] = {}
        for topic in self._topics_present:
            sub, suffix = _FILES[topic]
            folder = self.root / sub
            stems[topic] = {p.stem for p in folder.glob(f"*{suffix}")} if folder.is_dir() else set()
        self._frames = self._check_frames(stems)
        self._calib_cache: tuple[str, KittiCalibration] | None = None
        self._topics = self._topic_infos()

    def _topic_infos(self) -> Mapping[str, TopicInfo]:
        """The topics present, one message per frame each."""
        count = len(self._frames)
        return MappingProxyType(
            {
                t: TopicInfo(
                    topic=t,
                    msgtype=_MSGTYPES[t],
                    count=count,
                    encoding="native",
                    kind=_KINDS[t][0],
                    sensor_type=_KINDS[t][1],
                )
                for t in self._topics_present
            }
        )

    def _check_frames(self, stems: Mapping[str, set[str]]) -> list[str]:
        scans = stems[TOPIC_VELODYNE]
        every = set().union(*stems.values())
        orphans = sorted(every - scans)
        if orphans:
            folders = [_FILES[t][0] for t, s in stems.items() if orphans[0] in s]
            msg = (
                f"{self.root}: frame {orphans[0]} has {'/'.join(folders)} files but no "
                f"velodyne/{orphans[0]}.bin ({len(orphans)} frame(s) like this); restore the scan "
                "or remove the frame's other files"
            )
            raise LogError(msg)
        for topic in self._topics_present:
            if topic in (TOPIC_VELODYNE, TOPIC_CAMERA_INFO):  # camera info: image_2's files
                continue
            sub, suffix = _FILES[topic]
            missing = sorted(scans - stems[topic])
            if missing:
                msg = (
                    f"{self.root / sub}: frame {missing[0]} has no {sub}/{missing[0]}{suffix} "
                    f"({len(missing)} frame(s) lack one); restore it or remove the frame's "
                    "velodyne scan"
                )
                raise LogError(msg)
        bad_names = [s for s in scans if not s.isdigit()]
        if bad_names:
            msg = (
                f"{self.root / 'velodyne'}: {bad_names[0]}.bin is not named by a frame number "
                "(NNNNNN.bin); rename or remove it"
            )
            raise LogError(msg)
        frames = sorted(scans, key=int)
        for stem in frames:
            path = self.root / "velodyne" / f"{stem}.bin"
            size = path.stat().st_size
            if size % _POINT_BYTES:
                msg = (
                    f"{path}: {size} bytes is not a multiple of 16 (float32 x, y, z, reflectance "
                    "per point); the file is truncated or not a KITTI scan, restore it"
                )
                raise LogError(msg)
        return frames

    # -- summary -------------------------------------------------------------------------------

    @property
    def capabilities(self) -> ReaderCapabilities:
        """Native values; transforms from calib/, ground truth when label_2/ is there, no ego
        motion (frames are independent snapshots); a calibration per frame."""
        return ReaderCapabilities(
            message_typed=False,
            has_tf=True,
            has_ground_truth=TOPIC_LABEL_2 in self._topics,
            has_ego_pose=False,
            calibration_per_frame=True,
        )

    @property
    def topics(self) -> Mapping[str, TopicInfo]:
        return self._topics

    @property
    def frame_names(self) -> tuple[str, ...]:
        """The frame names (``000000`` …) in stamp order."""
        return tuple(self._frames)

    @staticmethod
    def stamp_ns_of(frame: str | int) -> int:
        """The synthetic stamp of a frame: its number × 100 ms."""
        return int(frame) * KITTI_FRAME_PERIOD_NS

    @property
    def start_ns(self) -> int:
        return self.stamp_ns_of(self._frames[0]) if self._frames else 0

    @property
    def end_ns(self) -> int:
        return self.stamp_ns_of(self._frames[-1]) if self._frames else 0

    @property
    def message_count(self) -> int:
        return len(self._frames) * len(self._topics_present)

    def _stem(self, frame: str | int) -> str:
        stem = (
            frame
            if isinstance(frame, str)
            else next((s for s in self._frames if int(s) == frame), str(frame))
        )
        if stem not in self._frames:
            msg = f"{self.root}: there is no frame {frame!r} (it has {len(self._frames)} frames)"
            raise LogError(msg)
        return stem

    def calibration(self, frame: str | int) -> KittiCalibration:
        """The calibration of a frame (by name ``"000001"`` or number ``1``).

        Its ``projections`` and ``image_from_velodyne(camera)`` project velodyne points and box
        corners into ``image_2`` (camera 2) and the other cameras.
        """
        stem = self._stem(frame)
        if self._calib_cache is None or self._calib_cache[0] != stem:
            self._calib_cache = (stem, parse_calibration(self.root / "calib" / f"{stem}.txt"))
        return self._calib_cache[1]

    # -- reading -------------------------------------------------------------------------------

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        wanted = [t for t in self._topics_present if topics is None or t in topics]
        loaders: dict[str, Callable[[str, int], Decoded]] = {
            TOPIC_TF_STATIC: self._load_tf,
            TOPIC_VELODYNE: self._load_velodyne,
            TOPIC_IMAGE_2: self._load_image,
            TOPIC_CAMERA_INFO: self._load_camera_info,
            TOPIC_LABEL_2: self._load_labels,
        }
        for stem in self._frames:
            stamp_ns = self.stamp_ns_of(stem)
            if (start_ns is not None and stamp_ns < start_ns) or (
                stop_ns is not None and stamp_ns >= stop_ns
            ):
                continue
            logger.debug("KITTI frame %s", stem)
            for topic in wanted:
                yield LogMessage(
                    topic=topic,
                    msgtype=_MSGTYPES[topic],
                    log_time_ns=stamp_ns,
                    encoding="native",
                    payload=loaders[topic](stem, stamp_ns),
                )

    def _file(self, topic: str, stem: str) -> Path:
        """The file a frame's message of ``topic`` is read from."""
        sub, suffix = _FILES[topic]
        return self.root / sub / f"{stem}{suffix}"

    def _decoded(self, stamp_ns: int, frame_id: str, value: DecodedValue) -> Decoded:
        return Decoded(stamp_ns=stamp_ns, frame_id=frame_id, value=value)

    def _load_tf(self, stem: str, stamp_ns: int) -> Decoded:
        transforms = (_BASE_FROM_VELODYNE, *self.calibration(stem).transforms())
        return self._decoded(stamp_ns, "base_link", transforms)

    def _load_velodyne(self, stem: str, stamp_ns: int) -> Decoded:
        path = self._file(TOPIC_VELODYNE, stem)
        try:
            raw = np.fromfile(path, dtype="<f4")
        except OSError as err:
            msg = f"{path}: cannot read the scan ({err.strerror}); check the file"
            raise LogError(msg) from err
        if raw.size % 4:
            msg = f"{path}: {raw.nbytes} bytes is not a multiple of 16; the scan is truncated, restore it"
            raise LogError(msg)
        points = raw.reshape(-1, 4)
        cloud = PointCloud(
            xyz=np.ascontiguousarray(points[:, :3], dtype=np.float32),
            channels={"intensity": np.ascontiguousarray(points[:, 3], dtype=np.float32)},
        )
        return self._decoded(stamp_ns, "velodyne", cloud)

    def _load_image(self, stem: str, stamp_ns: int) -> Decoded:
        path = self._file(TOPIC_IMAGE_2, stem)
        try:
            with PilImage.open(path) as img:
                if img.mode == "L":
                    image = Image(pixels=np.asarray(img, dtype=np.uint8), encoding="mono8")
                elif img.mode in ("I;16", "I;16B"):
                    image = Image(pixels=np.asarray(img, dtype=np.uint16), encoding="mono16")
                else:
                    image = Image(
                        pixels=np.asarray(img.convert("RGB"), dtype=np.uint8), encoding="rgb8"
                    )
        except (OSError, ValueError) as err:
            msg = f"{path}: cannot read the image ({err}); restore the PNG"
            raise LogError(msg) from err
        return self._decoded(stamp_ns, "cam2", image)

    def _load_camera_info(self, stem: str, stamp_ns: int) -> Decoded:
        path = self._file(TOPIC_IMAGE_2, stem)
        try:
            with PilImage.open(path) as img:  # reads the header only
                width, height = img.size
        except OSError as err:
            msg = f"{path}: cannot read the image ({err}); restore the PNG"
            raise LogError(msg) from err
        k = self.calibration(stem).projections[2][:, :3].copy()
        p = np.zeros((3, 4))
        p[:, :3] = k
        info = CameraInfo(width=width, height=height, k=k, d=np.zeros(0), p=p)
        return self._decoded(stamp_ns, "cam2", info)

    def _load_labels(self, stem: str, stamp_ns: int) -> Decoded:
        objects = parse_labels(self.root / "label_2" / f"{stem}.txt", self.calibration(stem))
        return self._decoded(stamp_ns, "velodyne", objects)

    def deserialize(self, message: LogMessage) -> object:
        """KITTI messages are already decoded (``message.payload``); there are no ROS bytes.

        Raises:
            UnsupportedMessageError: always.
        """
        msg = (
            f"{self.path}: topic {message.topic} at {message.log_time_ns} ns is a native KITTI "
            "message; use message.payload (a Decoded) instead of deserialize()"
        )
        raise UnsupportedMessageError(msg)

    def close(self) -> None:
        self._calib_cache = None

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
