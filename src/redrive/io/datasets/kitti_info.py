"""mmdetection3d KITTI info files (``.pkl``, or the same data as JSON) read as a KITTI log.

mmdetection3d (≥ 1.1) describes KITTI frames in an info file written by
``tools/dataset_converters/update_infos_to_v2.py`` (``update_kitti_infos``): ``metainfo``
(``dataset`` ``kitti`` — ``DATASET`` ``KITTI`` in the demo file of ``demo/data/kitti`` — and
``categories``, class name → label) and ``data_list``, one entry per frame:

* ``sample_idx`` (``sample_id`` in the demo file): the KITTI frame number;
* ``images``: ``CAM0`` … ``CAM3`` each with ``cam2img`` (P0 … P3 as 4×4), ``CAM2`` with
  ``img_path`` (``image_2``'s file name), ``height``, ``width``; ``R0_rect`` (4×4);
* ``lidar_points``: ``lidar_path``, ``num_pts_feats`` (4: x, y, z, reflectance),
  ``Tr_velo_to_cam`` and ``Tr_imu_to_velo`` (4×4);
* ``instances``: ``bbox_3d`` = the KITTI label's ``location`` (bottom centre, rectified cam0
  frame), ``dimensions`` in the order *l, h, w* (the label's h, w, l reordered by
  ``kitti_data_utils.get_label_anno``) and ``rotation_y``; ``bbox_label_3d`` indexes the
  categories (−1: ``DontCare`` and other ignored classes); ``bbox`` x1, y1, x2, y2 px.

A file without ``categories`` (the demo's) has the converter's class list, ``Pedestrian``,
``Cyclist``, ``Car``, ``Van``, ``Truck``, ``Person_sitting``, ``Tram``, ``Misc``.  The frames
are given the topics, frames and stamps of the KITTI folder reader
(:mod:`redrive.io.datasets.kitti`: frame *N* at *N* × 100 ms, ``base_link`` ≡ ``velodyne``,
labels in the velodyne frame), so everything that runs on a KITTI folder runs on an info file.
The pickle is read by the restricted unpickler of :mod:`.mmdet3d_info` (plain data and numpy
arrays only).  Data files are looked up next to the info file, then under ``velodyne/`` /
``velodyne_reduced/`` and ``image_2/`` there (a KITTI ``training/`` folder), then as given.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import LogError
from redrive.io.datasets.kitti import (
    TOPIC_CAMERA_INFO,
    TOPIC_IMAGE_2,
    TOPIC_LABEL_2,
    TOPIC_TF_STATIC,
    TOPIC_VELODYNE,
    KittiReader,
)
from redrive.io.datasets.kitti_calib import (
    KITTI_CLASSES,
    KittiCalibration,
    camera_box_object,
)
from redrive.io.datasets.mmdet3d_info import load_info
from redrive.io.ros.decoders.base import Decoded
from redrive.types import DetectedObject, ObjectClass

__all__ = ["KittiInfoReader", "find_kitti_info"]

logger = logging.getLogger(__name__)

_HEAD_BYTES = 65536
#: ``update_kitti_infos``' METAINFO classes: a label's index when the file has no categories.
_CONVERTER_CLASSES = (
    "Pedestrian",
    "Cyclist",
    "Car",
    "Van",
    "Truck",
    "Person_sitting",
    "Tram",
    "Misc",
)


def _looks_like_kitti_info(path: Path) -> bool:
    if not path.is_file() or path.suffix.lower() not in (".pkl", ".json"):
        return False
    with path.open("rb") as fh:
        head = fh.read(_HEAD_BYTES)
    return (
        b"data_list" in head
        and b"metainfo" in head
        and b"lidar_points" in head
        and b"Tr_velo_to_cam" in head
        and b"kitti" in head.lower()
    )


def find_kitti_info(path: Path) -> Path | None:
    """The KITTI info file ``path`` is, or the one a folder holds (``.pkl`` before ``.json``)."""
    if path.is_file():
        return path if _looks_like_kitti_info(path) else None
    if not path.is_dir():
        return None
    for pattern in ("*.pkl", "*.json"):
        found = sorted(p for p in path.glob(pattern) if _looks_like_kitti_info(p))
        if found:
            return found[0]
    return None


def _matrix(value: Any, what: str) -> npt.NDArray[np.float64]:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape not in ((4, 4), (3, 4)) or not np.all(np.isfinite(arr)):
        msg = f"{what} must be a finite 4×4 (or 3×4) matrix, got shape {arr.shape}"
        raise ValueError(msg)
    out = np.eye(4)
    out[: arr.shape[0]] = arr
    return out


@dataclass(frozen=True, slots=True, kw_only=True)
class _Entry:
    calibration: KittiCalibration
    lidar: Path
    image: Path | None
    objects: tuple[DetectedObject, ...]


class KittiInfoReader(KittiReader):
    """An mmdetection3d KITTI info file as a :class:`~redrive.io.base.LogReader` (format
    ``kitti-mmdet3d``): the topics of :class:`~redrive.io.datasets.kitti.KittiReader`.

    Raises (at open):
        LogError: no info file; it is refused or damaged; an entry lacks a field or names a
            LiDAR scan or image that is not there.
    """

    format = "kitti-mmdet3d"
    description = (
        "an mmdetection3d KITTI info file (.pkl or its JSON form, or a folder holding one) with "
        "its LiDAR scans and image_2 images"
    )

    @classmethod
    def recognises(cls, path: Path) -> bool:
        return find_kitti_info(path) is not None

    def __init__(self, path: str | Path, *, strict: bool = True) -> None:
        """``strict`` is accepted like every reader's; the info file is checked whole at open."""
        self.path = Path(path)
        info_file = self.path if self.path.is_file() else find_kitti_info(self.path)
        if info_file is None:
            msg = (
                f"{self.path}: no mmdetection3d KITTI info file (a .pkl or .json with metainfo "
                "and data_list) here; pass the info file or its folder"
            )
            raise LogError(msg)
        self.info_file = info_file
        self.root = info_file.parent
        content = load_info(info_file)
        meta = content.get("metainfo") or {}
        dataset = str(meta.get("dataset", meta.get("DATASET", "kitti")))
        if dataset.lower() != "kitti":
            msg = f"{info_file}: an mmdetection3d info file of {dataset}, not KITTI"
            raise LogError(msg)
        categories = meta.get("categories") or {n: i for i, n in enumerate(_CONVERTER_CLASSES)}
        self.class_names: dict[int, str] = {int(i): str(n) for n, i in categories.items()}
        entries: dict[str, _Entry] = {}
        for index, entry in enumerate(content["data_list"]):
            where = f"{info_file}: data_list[{index}]"
            try:
                stem = f"{int(entry.get('sample_idx', entry.get('sample_id'))):06d}"
                entries[stem] = self._entry(entry)
            except (KeyError, TypeError, ValueError, IndexError) as err:
                msg = f"{where}: {err!s} — the frame is incomplete; regenerate the info file"
                raise LogError(msg) from err
        self._entries = entries
        self._frames = sorted(entries, key=int)
        with_image = all(e.image is not None for e in entries.values())
        self._topics_present = [
            t
            for t in (TOPIC_TF_STATIC, TOPIC_VELODYNE, TOPIC_IMAGE_2, TOPIC_CAMERA_INFO)
            if with_image or t not in (TOPIC_IMAGE_2, TOPIC_CAMERA_INFO)
        ]
        self._topics_present.append(TOPIC_LABEL_2)
        self._calib_cache = None
        self._topics = self._topic_infos()

    def _data_file(self, name: str, folders: tuple[str, ...]) -> Path:
        given = Path(name)
        candidates = [self.root / given.name]
        candidates += [self.root / f / given.name for f in folders]
        candidates += [self.root / given, given]
        for cand in candidates:
            if cand.is_file():
                return cand
        msg = (
            f"{name!r} not found next to the info file nor under {'/ or '.join(folders)}/ "
            "there; put the data beside it"
        )
        raise ValueError(msg)

    def _entry(self, entry: Mapping[str, Any]) -> _Entry:
        images = entry["images"]
        lidar = entry["lidar_points"]
        feats = int(lidar.get("num_pts_feats", 4))
        if feats != 4:
            msg = f"num_pts_feats is {feats}; KITTI scans have 4 (x, y, z, reflectance)"
            raise ValueError(msg)
        projections = tuple(
            _matrix(images[f"CAM{i}"]["cam2img"], f"images.CAM{i}.cam2img")[:3, :4]
            for i in range(4)
        )
        imu = lidar.get("Tr_imu_to_velo")
        calibration = KittiCalibration(
            projections=projections,  # type: ignore[arg-type]
            r0_rect=_matrix(images["R0_rect"], "images.R0_rect")[:3, :3],
            cam0_from_velodyne=_matrix(lidar["Tr_velo_to_cam"], "lidar_points.Tr_velo_to_cam"),
            velodyne_from_imu=None if imu is None else _matrix(imu, "Tr_imu_to_velo"),
        )
        image_name = (images.get("CAM2") or {}).get("img_path")
        return _Entry(
            calibration=calibration,
            lidar=self._data_file(str(lidar["lidar_path"]), ("velodyne", "velodyne_reduced")),
            image=None if not image_name else self._data_file(str(image_name), ("image_2",)),
            objects=self._objects(entry.get("instances") or [], calibration),
        )

    def _objects(
        self, instances: list[Mapping[str, Any]], calibration: KittiCalibration
    ) -> tuple[DetectedObject, ...]:
        velodyne_from_rect = calibration.velodyne_from_rect
        out: list[DetectedObject] = []
        for index, inst in enumerate(instances):
            label = int(inst.get("bbox_label_3d", inst.get("bbox_label", -1)))
            if label < 0:
                continue  # DontCare and the converter's other ignored classes
            box = [float(v) for v in inst["bbox_3d"]]
            if len(box) < 7 or not all(np.isfinite(box)) or min(box[3:6]) < 0:
                msg = f"instances[{index}].bbox_3d must be 7 finite values with sizes ≥ 0"
                raise ValueError(msg)
            bbox = inst.get("bbox")
            bbox_2d = None
            if bbox is not None and len(bbox) == 4:
                x1, y1, x2, y2 = (float(v) for v in bbox)
                bbox_2d = (x1, y1, x2 - x1, y2 - y1)
            name = self.class_names.get(label, "")
            out.append(
                camera_box_object(
                    object_id=index,
                    object_class=KITTI_CLASSES.get(name, ObjectClass.UNKNOWN),
                    bottom_center_rect=(box[0], box[1], box[2]),
                    size_lhw=(box[3], box[4], box[5]),
                    rotation_y_rad=box[6],
                    velodyne_from_rect=velodyne_from_rect,
                    bbox_2d=bbox_2d,
                )
            )
        return tuple(out)

    def calibration(self, frame: str | int) -> KittiCalibration:
        """The calibration of a frame (by name ``"000008"`` or number ``8``)."""
        return self._entries[self._stem(frame)].calibration

    def _file(self, topic: str, stem: str) -> Path:
        entry = self._entries[stem]
        if topic in (TOPIC_IMAGE_2, TOPIC_CAMERA_INFO) and entry.image is not None:
            return entry.image
        if topic == TOPIC_VELODYNE:
            return entry.lidar
        return super()._file(topic, stem)

    def _load_labels(self, stem: str, stamp_ns: int) -> Decoded:
        return self._decoded(stamp_ns, "velodyne", self._entries[stem].objects)
