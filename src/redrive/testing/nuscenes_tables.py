"""A small, valid nuScenes table set (``v1.0-mini`` layout) made from one real keyframe.

No full nuScenes tables are in ``../shared/data``; its ``nuscenes_mmdet3d_demo`` keyframe (an
mmdetection3d info file, its LiDAR sweep and six camera images) is turned into ``n_samples``
samples of one scene, written as the documented JSON tables (sample, sample_data,
calibrated_sensor, sensor, ego_pose, sample_annotation, instance, category, attribute,
visibility, scene, log, map with an empty mask in ``maps/``) with ``samples/<channel>/`` files linked to the real ones:

- sample ``k`` is ``k × dt_s`` after the keyframe; the ego moves ``k × ego_step_m`` along its own
  heading (every sample shows the same real sweep and images);
- every box keeps its size and orientation and moves with its info-file velocity (LiDAR frame,
  turned into the global frame), so the devkit's ``box_velocity`` of a middle sample gives it back;
- boxes are written in the global frame (centre, size **w, l, h**, rotation w x y z), from the
  info file's LiDAR-frame boxes through ``lidar2ego`` and ``ego2global``.

Quaternions are made with scipy (independently of redrive's geometry, which reads them back).
Used by ``tests/io/test_nuscenes_tables.py`` and ``scripts/check_nuscenes_reader.py``.
"""

from __future__ import annotations

import json
import os
import uuid
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from PIL import Image as PilImage
from scipy.spatial.transform import Rotation

from redrive.io.datasets.nuscenes_common import gravity_aligned_rotations

__all__ = ["CATEGORY_OF_DETECTION_NAME", "write_mini_tables"]

#: mmdetection3d's class (detection name) → the nuScenes category written for it; label −1
#: (classes the benchmark ignores) becomes ``animal``.
CATEGORY_OF_DETECTION_NAME = {
    "car": "vehicle.car",
    "truck": "vehicle.truck",
    "trailer": "vehicle.trailer",
    "bus": "vehicle.bus.rigid",
    "construction_vehicle": "vehicle.construction",
    "bicycle": "vehicle.bicycle",
    "motorcycle": "vehicle.motorcycle",
    "pedestrian": "human.pedestrian.adult",
    "traffic_cone": "movable_object.trafficcone",
    "barrier": "movable_object.barrier",
}


def _token(*parts: object) -> str:
    return uuid.uuid5(uuid.NAMESPACE_URL, "/".join(str(p) for p in parts)).hex


def _wxyz(rotation: npt.NDArray[np.float64]) -> list[float]:
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return [float(w), float(x), float(y), float(z)]


def _link(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    if not dst.exists():
        os.symlink(src.resolve(), dst)


def write_mini_tables(
    root: Path,
    info_json: Path,
    *,
    n_samples: int = 3,
    dt_s: float = 0.5,
    ego_step_m: float = 4.0,
    version: str = "v1.0-mini",
) -> Path:
    """Write the table set under ``root`` (``root/version/*.json``, ``root/samples/…``) from
    the first keyframe of the mmdetection3d info file ``info_json``; returns ``root``."""
    info = json.loads(Path(info_json).read_text(encoding="utf-8"))
    entry = info["data_list"][0]
    names = {int(i): n for n, i in info["metainfo"]["categories"].items()}
    data_dir = Path(info_json).parent
    base_us = round(float(entry["timestamp"]) * 1e6)
    ego2global = np.asarray(entry["ego2global"], dtype=np.float64)
    tables: dict[str, list[dict[str, Any]]] = {
        k: []
        for k in (
            "sample",
            "sample_data",
            "calibrated_sensor",
            "sensor",
            "ego_pose",
            "sample_annotation",
            "instance",
            "category",
            "attribute",
            "visibility",
            "scene",
            "log",
            "map",
        )
    }
    log_token, scene_token = _token("log"), _token("scene")
    tables["log"].append(
        {
            "token": log_token,
            "logfile": "n015-2018-07-24-11-22-45+0800",
            "vehicle": "n015",
            "date_captured": "2018-07-24",
            "location": "singapore-onenorth",
        }
    )
    # the devkit indexes logs by map and wants its mask file: an empty 8×8 one
    (root / "maps").mkdir(parents=True, exist_ok=True)
    PilImage.fromarray(np.zeros((8, 8), dtype=np.uint8)).save(root / "maps" / "empty.png")
    tables["map"].append(
        {
            "token": _token("map"),
            "log_tokens": [log_token],
            "category": "semantic_prior",
            "filename": "maps/empty.png",
        }
    )
    tables["visibility"] = [
        {"token": str(i), "level": level, "description": level}
        for i, level in enumerate(["v0-40", "v40-60", "v60-80", "v80-100"], start=1)
    ]
    categories = sorted({*CATEGORY_OF_DETECTION_NAME.values(), "animal"})
    tables["category"] = [
        {"token": _token("category", c), "name": c, "description": c} for c in categories
    ]
    # sensors and their calibration (one of each channel)
    lidar = entry["lidar_points"]
    channels: dict[str, tuple[str, npt.NDArray[np.float64], Any]] = {
        "LIDAR_TOP": ("lidar", np.asarray(lidar["lidar2ego"], dtype=np.float64), []),
    }
    for channel, image in entry["images"].items():
        channels[channel] = (
            "camera",
            np.asarray(image["cam2ego"], dtype=np.float64),
            np.asarray(image["cam2img"], dtype=np.float64).tolist(),
        )
    for channel, (modality, ego_from_sensor, intrinsic) in channels.items():
        tables["sensor"].append(
            {"token": _token("sensor", channel), "channel": channel, "modality": modality}
        )
        tables["calibrated_sensor"].append(
            {
                "token": _token("cs", channel),
                "sensor_token": _token("sensor", channel),
                "translation": ego_from_sensor[:3, 3].tolist(),
                "rotation": _wxyz(ego_from_sensor[:3, :3]),
                "camera_intrinsic": intrinsic,
            }
        )
    # samples, ego poses, sample data
    sample_tokens = [_token("sample", k) for k in range(n_samples)]
    poses = []
    for k, sample_token in enumerate(sample_tokens):
        step = np.eye(4)
        step[0, 3] = k * ego_step_m
        pose = ego2global @ step  # moved along the ego's own x
        poses.append(pose)
        stamp_us = base_us + round(k * dt_s * 1e6)
        tables["sample"].append(
            {
                "token": sample_token,
                "timestamp": stamp_us,
                "prev": sample_tokens[k - 1] if k else "",
                "next": sample_tokens[k + 1] if k + 1 < n_samples else "",
                "scene_token": scene_token,
            }
        )
        files = {"LIDAR_TOP": (lidar["lidar_path"], base_us, "pcd", 0, 0)}
        for channel, image in entry["images"].items():
            cam_us = round(float(image["timestamp"]) * 1e6)
            files[channel] = (image["img_path"], cam_us, "jpg", 900, 1600)
        for channel, (name, orig_us, fmt, height, width) in files.items():
            sd_us = orig_us + round(k * dt_s * 1e6)
            filename = f"samples/{channel}/{str(name).replace(str(orig_us), str(sd_us))}"
            _link(data_dir / str(name), root / filename)
            pose_token = _token("ego_pose", k, channel)
            tables["ego_pose"].append(
                {
                    "token": pose_token,
                    "timestamp": sd_us,
                    "rotation": _wxyz(pose[:3, :3]),
                    "translation": pose[:3, 3].tolist(),
                }
            )
            tables["sample_data"].append(
                {
                    "token": _token("sd", k, channel),
                    "sample_token": sample_token,
                    "ego_pose_token": pose_token,
                    "calibrated_sensor_token": _token("cs", channel),
                    "timestamp": sd_us,
                    "fileformat": fmt,
                    "is_key_frame": True,
                    "height": height,
                    "width": width,
                    "filename": filename,
                    "prev": _token("sd", k - 1, channel) if k else "",
                    "next": _token("sd", k + 1, channel) if k + 1 < n_samples else "",
                }
            )
    # annotations: the info file's boxes, moving with their velocities
    global_from_lidar = ego2global @ np.asarray(lidar["lidar2ego"], dtype=np.float64)
    for i, inst in enumerate(entry["instances"]):
        x, y, z, box_l, box_w, box_h, yaw = (float(v) for v in inst["bbox_3d"][:7])
        center = global_from_lidar @ np.array([x, y, z, 1.0])
        # upright in the global frame, as nuScenes annotates (the info keeps the LiDAR heading)
        rot = (
            global_from_lidar[:3, :3]
            @ gravity_aligned_rotations(np.array([yaw]), global_from_lidar)[0]
        )
        vel = np.zeros(3)
        vel[:2] = np.nan_to_num(
            np.asarray(inst.get("velocity", [0.0, 0.0])[:2], float)
        )  # NaN: unknown
        vel_global = global_from_lidar[:3, :3] @ vel
        label = int(inst["bbox_label_3d"])
        category = CATEGORY_OF_DETECTION_NAME.get(names.get(label, ""), "animal")
        instance_token = _token("instance", i)
        ann_tokens = [_token("ann", i, k) for k in range(n_samples)]
        tables["instance"].append(
            {
                "token": instance_token,
                "category_token": _token("category", category),
                "nbr_annotations": n_samples,
                "first_annotation_token": ann_tokens[0],
                "last_annotation_token": ann_tokens[-1],
            }
        )
        for k in range(n_samples):
            tables["sample_annotation"].append(
                {
                    "token": ann_tokens[k],
                    "sample_token": sample_tokens[k],
                    "instance_token": instance_token,
                    "visibility_token": "4",
                    "attribute_tokens": [],
                    "translation": (center[:3] + vel_global * k * dt_s).tolist(),
                    "size": [box_w, box_l, box_h],
                    "rotation": _wxyz(rot),
                    "prev": ann_tokens[k - 1] if k else "",
                    "next": ann_tokens[k + 1] if k + 1 < n_samples else "",
                    "num_lidar_pts": int(inst.get("num_lidar_pts", 0)),
                    "num_radar_pts": int(inst.get("num_radar_pts", 0)),
                }
            )
    tables["scene"].append(
        {
            "token": scene_token,
            "log_token": log_token,
            "nbr_samples": n_samples,
            "first_sample_token": sample_tokens[0],
            "last_sample_token": sample_tokens[-1],
            "name": "scene-0000",
            "description": "redrive test scene from the mmdetection3d demo keyframe",
        }
    )
    out = root / version
    out.mkdir(parents=True, exist_ok=True)
    for name, records in tables.items():
        (out / f"{name}.json").write_text(json.dumps(records, indent=0), encoding="utf-8")
    return root
