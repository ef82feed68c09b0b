"""The nuScenes table layout read as a log: ``v1.0-*/`` JSON tables, ``samples/``, ``sweeps/``.

Written on the documented schema (https://www.nuscenes.org/nuscenes#data-format); the devkit is
not needed.  ``path`` is the data root (the folder holding ``v1.0-mini/`` …, ``samples/``,
``sweeps/``) or a version folder itself (its parent is then the data root).

What is read, per **sample** (keyframe), in timestamp order:

- ``sample`` → its ``sample_data`` (``sample_token``, ``is_key_frame``): the key ``LIDAR_TOP``
  sweep and the six key camera images; ``calibrated_sensor`` → ``sensor`` says each one's
  channel and modality;
- ``calibrated_sensor``: ``translation`` (m), ``rotation`` (w, x, y, z) of the sensor in the ego
  frame; ``camera_intrinsic`` (3×3);
- ``ego_pose`` of the LiDAR sweep: ``translation``, ``rotation`` (w, x, y, z) in the global frame;
  the ego velocity and yaw rate from the neighbouring samples of the scene;
- ``sample_annotation``: ``translation`` (box centre, global), ``size`` (**w, l, h**), ``rotation``
  (w, x, y, z, global), ``num_lidar_pts``; ``instance`` → ``category`` names the class; the
  velocity is the devkit's ``box_velocity`` (centre difference of the previous and next
  annotations of the instance, NaN beyond 1.5 s, read as 0 here).  Boxes are moved into base_link
  at the LiDAR's stamp as the devkit's ``get_sample_data`` does (translate by −ego, rotate by the
  ego's inverse); ``object_id`` is a stable number of the instance token.

Sweeps (the non-key ``sample_data`` between keyframes) are not streamed: the frames are the
keyframes, where ground truth is.  Radar is not read.  Messages are those of
:mod:`redrive.io.datasets.nuscenes_common`.
"""

from __future__ import annotations

import json
import logging
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import LogError
from redrive.geometry.quaternion import rotation_matrix_from_quaternion
from redrive.geometry.se3 import invert, se3_from_rotation_translation
from redrive.io.datasets.nuscenes_common import (
    CAMERA_CHANNELS,
    LIDAR_CHANNEL,
    NuScenesCamera,
    NuScenesReaderBase,
    NuScenesSample,
    boxes_to_base,
    object_class_of,
    velocity_and_yaw_rate,
)

__all__ = ["NUSCENES_TABLES", "NuScenesReader", "find_version_dir", "se3_from_nuscenes"]

logger = logging.getLogger(__name__)

#: The tables read (``<name>.json`` in the version folder).
NUSCENES_TABLES = (
    "sample",
    "sample_data",
    "calibrated_sensor",
    "sensor",
    "ego_pose",
    "sample_annotation",
    "instance",
    "category",
    "scene",
)
_MAX_VELOCITY_DT_S = 1.5  # devkit box_velocity's max_time_diff


def find_version_dir(path: Path) -> Path | None:
    """The ``v1.0-*`` folder ``path`` is or holds (the only one), or None."""
    if not path.is_dir():
        return None
    if (path / "sample.json").is_file() and (path / "sample_data.json").is_file():
        return path
    found = sorted(
        p
        for p in path.glob("v*")
        if (p / "sample.json").is_file() and (p / "sample_data.json").is_file()
    )
    if len(found) > 1:
        names = ", ".join(p.name for p in found)
        msg = f"{path}: holds several nuScenes versions ({names}); pass the one to read"
        raise LogError(msg)
    return found[0] if found else None


def se3_from_nuscenes(record: Mapping[str, Any]) -> npt.NDArray[np.float64]:
    """A 4×4 ``parent_from_child`` from a record's ``translation`` and ``rotation`` (w, x, y, z)."""
    w, x, y, z = (float(v) for v in record["rotation"])
    rotation = rotation_matrix_from_quaternion([x, y, z, w])
    return se3_from_rotation_translation(rotation, np.asarray(record["translation"], dtype=float))


def _rotation(rotation_wxyz: Any) -> npt.NDArray[np.float64]:
    w, x, y, z = (float(v) for v in rotation_wxyz)
    return rotation_matrix_from_quaternion([x, y, z, w])


class NuScenesReader(NuScenesReaderBase):
    """A nuScenes data root (table layout) as a :class:`~redrive.io.base.LogReader`
    (format ``nuscenes``).

    Raises (at open):
        LogError: no version folder; a table is missing or not JSON; a record refers to a token
            no table holds; a sample has no LiDAR sweep; a file it names is missing.
    """

    format = "nuscenes"
    description = (
        "a nuScenes data root (v1.0-*/ JSON tables with samples/ and sweeps/, or the version "
        "folder)"
    )

    @classmethod
    def recognises(cls, path: Path) -> bool:
        try:
            return find_version_dir(path) is not None
        except LogError:
            return True  # several versions: opening says which to pass

    def __init__(self, path: str | Path, *, strict: bool = True) -> None:
        """``strict`` is accepted like every reader's; the tables are checked whole at open."""
        self.path = Path(path)
        version_dir = find_version_dir(self.path)
        if version_dir is None:
            msg = (
                f"{self.path}: not a nuScenes data root: no v1.0-*/ folder with sample.json and "
                "sample_data.json; pass the folder that holds v1.0-mini/ (or the like)"
            )
            raise LogError(msg)
        self.version_dir = version_dir
        self.root = version_dir.parent
        self.version = version_dir.name
        tables = {name: self._table(name) for name in NUSCENES_TABLES}
        try:
            self._samples = self._build(tables)
        except KeyError as err:
            msg = (
                f"{version_dir}: a record refers to token {err.args[0]!r}, which no table holds; "
                "the tables are incomplete — extract the whole version again"
            )
            raise LogError(msg) from err
        self._init_topics()

    def _table(self, name: str) -> dict[str, dict[str, Any]]:
        path = self.version_dir / f"{name}.json"
        try:
            records = json.loads(path.read_text(encoding="utf-8"))
        except OSError as err:
            msg = f"{path}: cannot read the {name} table ({err.strerror}); restore it"
            raise LogError(msg) from err
        except ValueError as err:
            msg = f"{path}: the {name} table is not JSON ({err}); restore it"
            raise LogError(msg) from err
        if not isinstance(records, list):
            msg = f"{path}: the {name} table must be a JSON list of records"
            raise LogError(msg)
        return {str(r["token"]): r for r in records}

    def _file(self, filename: str) -> Path:
        path = self.root / filename
        if not path.is_file():
            msg = f"{path}: file named by sample_data is missing; restore samples/ and sweeps/"
            raise LogError(msg)
        return path

    def _build(self, tables: Mapping[str, dict[str, dict[str, Any]]]) -> list[NuScenesSample]:
        channel_of: dict[str, str] = {}
        for token, cs in tables["calibrated_sensor"].items():
            channel_of[token] = str(tables["sensor"][cs["sensor_token"]]["channel"])
        key_data: dict[str, dict[str, dict[str, Any]]] = {}
        for sd in tables["sample_data"].values():
            if sd.get("is_key_frame", True):
                channel = channel_of[sd["calibrated_sensor_token"]]
                key_data.setdefault(sd["sample_token"], {})[channel] = sd
        anns_of: dict[str, list[dict[str, Any]]] = {}
        for ann in tables["sample_annotation"].values():
            anns_of.setdefault(ann["sample_token"], []).append(ann)
        by_scene: dict[str, list[dict[str, Any]]] = {}
        for sample in tables["sample"].values():
            by_scene.setdefault(str(sample.get("scene_token", "")), []).append(sample)
        out: list[NuScenesSample] = []
        for samples in by_scene.values():
            samples.sort(key=lambda s: int(s["timestamp"]))
            lidars = []
            for sample in samples:
                lidar = key_data.get(sample["token"], {}).get(LIDAR_CHANNEL)
                if lidar is None:
                    msg = (
                        f"{self.version_dir}: sample {sample['token']} has no key {LIDAR_CHANNEL} "
                        "sample_data; the tables are incomplete"
                    )
                    raise LogError(msg)
                lidars.append(lidar)
            poses = [se3_from_nuscenes(tables["ego_pose"][sd["ego_pose_token"]]) for sd in lidars]
            stamps = [int(sd["timestamp"]) * 1000 for sd in lidars]
            motion = velocity_and_yaw_rate(poses, stamps)
            for sample, lidar, pose, stamp_ns, (velocity, yaw_rate) in zip(
                samples, lidars, poses, stamps, motion, strict=True
            ):
                cameras = []
                data = key_data[sample["token"]]
                for channel in CAMERA_CHANNELS:
                    cam_sd = data.get(channel)
                    if cam_sd is None:
                        continue
                    cs = tables["calibrated_sensor"][cam_sd["calibrated_sensor_token"]]
                    cameras.append(
                        NuScenesCamera(
                            channel=channel,
                            path=self._file(str(cam_sd["filename"])),
                            stamp_ns=int(cam_sd["timestamp"]) * 1000,
                            intrinsic=np.asarray(cs["camera_intrinsic"], dtype=np.float64),
                            ego_from_camera=se3_from_nuscenes(cs),
                        )
                    )
                cs_lidar = tables["calibrated_sensor"][lidar["calibrated_sensor_token"]]
                out.append(
                    NuScenesSample(
                        token=str(sample["token"]),
                        stamp_ns=stamp_ns,
                        lidar_path=self._file(str(lidar["filename"])),
                        ego_from_lidar=se3_from_nuscenes(cs_lidar),
                        global_from_ego=pose,
                        ego_velocity_mps=velocity,
                        ego_yaw_rate_rad_s=yaw_rate,
                        cameras=tuple(cameras),
                        objects=self._objects(anns_of.get(sample["token"], []), pose, tables),
                    )
                )
        out.sort(key=lambda s: s.stamp_ns)
        return out

    def _objects(
        self,
        anns: list[dict[str, Any]],
        global_from_ego: npt.NDArray[np.float64],
        tables: Mapping[str, dict[str, dict[str, Any]]],
    ) -> tuple[Any, ...]:
        if not anns:
            return ()
        anns = sorted(anns, key=lambda a: str(a["token"]))
        centers = np.array([a["translation"] for a in anns], dtype=np.float64)
        wlh = np.array([a["size"] for a in anns], dtype=np.float64)
        rotations = np.array([_rotation(a["rotation"]) for a in anns])
        velocities = np.array([self._velocity(a, tables) for a in anns])
        classes = []
        ids = []
        for a in anns:
            instance = tables["instance"][a["instance_token"]]
            category = tables["category"][instance["category_token"]]
            classes.append(object_class_of(str(category["name"])))
            ids.append(zlib.crc32(str(a["instance_token"]).encode()) & 0x7FFFFFFF)
        points = [
            int(a["num_lidar_pts"]) if a.get("num_lidar_pts") is not None else None for a in anns
        ]
        return boxes_to_base(
            centers=centers,
            sizes_lwh=wlh[:, [1, 0, 2]],
            rotations=rotations,
            velocities=velocities,
            base_from_src=invert(global_from_ego),
            classes=classes,
            num_lidar_points=points,
            object_ids=ids,
        )

    @staticmethod
    def _velocity(
        ann: Mapping[str, Any], tables: Mapping[str, dict[str, dict[str, Any]]]
    ) -> npt.NDArray[np.float64]:
        """The devkit's ``box_velocity``: global m/s from the previous and next annotations."""
        annotations, samples = tables["sample_annotation"], tables["sample"]
        has_prev, has_next = bool(ann.get("prev")), bool(ann.get("next"))
        if not has_prev and not has_next:
            return np.full(3, np.nan)
        first = annotations[ann["prev"]] if has_prev else ann
        last = annotations[ann["next"]] if has_next else ann
        dt_s = (
            int(samples[last["sample_token"]]["timestamp"])
            - int(samples[first["sample_token"]]["timestamp"])
        ) * 1e-6
        limit = 2 * _MAX_VELOCITY_DT_S if has_prev and has_next else _MAX_VELOCITY_DT_S
        if dt_s <= 0 or dt_s > limit:
            return np.full(3, np.nan)
        diff = np.asarray(last["translation"], float) - np.asarray(first["translation"], float)
        out: npt.NDArray[np.float64] = diff / dt_s
        return out
