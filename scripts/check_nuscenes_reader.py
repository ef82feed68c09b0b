"""Compare redrive's nuScenes readers with nuscenes-devkit, run in a separate virtual environment.

The devkit pins numpy < 2, so it is not installed beside redrive: give its interpreter with
``--devkit-python``.  Without ``--dataroot`` a mini table set is written from the real keyframe in
``../shared/data/nuscenes_mmdet3d_demo`` (:func:`redrive.testing.nuscenes_tables.write_mini_tables`);
with it, a real nuScenes data root (``v1.0-mini`` …) is checked.

For every sample the devkit's boxes (``get_sample_data`` on the LIDAR_TOP keyframe: global →
ego → sensor, then moved back into the ego frame through the calibrated sensor) are compared
with what :class:`redrive.io.datasets.nuscenes.NuScenesReader` gives in base_link: centre, size, yaw
(the devkit evaluation's ``quaternion_yaw``: the heading of the box's x axis — pyquaternion's
``yaw_pitch_roll[0]`` differs from it by up to ~2e-4 rad when the ego is pitched or rolled),
velocity (``box_velocity``, which ``get_sample_data`` boxes do not carry, turned into the ego
frame), class; and the LiDAR point count, the ego pose and the camera intrinsics.  The first sample of the generated set is compared with
:class:`redrive.io.datasets.mmdet3d_info.Mmdet3dInfoReader` on the info file too.

    python3 -m venv /tmp/nusc-venv && /tmp/nusc-venv/bin/pip install nuscenes-devkit
    PYTHONPATH=src python scripts/check_nuscenes_reader.py --devkit-python /tmp/nusc-venv/bin/python

Exit status 0 when everything agrees within ``--tolerance``, 1 otherwise, 2 on a usage error.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

_DEVKIT_SIDE = r"""
import json, sys
import numpy as np
from pyquaternion import Quaternion
from nuscenes.eval.common.utils import quaternion_yaw
from nuscenes.nuscenes import NuScenes
from nuscenes.utils.data_classes import LidarPointCloud

version, dataroot = sys.argv[1], sys.argv[2]
nusc = NuScenes(version=version, dataroot=dataroot, verbose=False)
out = {}
for sample in nusc.sample:
    sd_token = sample["data"]["LIDAR_TOP"]
    sd = nusc.get("sample_data", sd_token)
    cs = nusc.get("calibrated_sensor", sd["calibrated_sensor_token"])
    pose = nusc.get("ego_pose", sd["ego_pose_token"])
    path, boxes, _ = nusc.get_sample_data(sd_token)
    cloud = LidarPointCloud.from_file(path)
    ego_from_global = Quaternion(pose["rotation"]).inverse.rotation_matrix
    objects = []
    for box in boxes:
        box.rotate(Quaternion(cs["rotation"]))  # sensor -> ego, as get_sample_data undid it
        box.translate(np.array(cs["translation"]))
        ann = nusc.get("sample_annotation", box.token)
        objects.append({
            "instance_token": ann["instance_token"],
            "center": box.center.tolist(),
            "wlh": box.wlh.tolist(),
            "yaw": quaternion_yaw(box.orientation),
            "velocity": np.nan_to_num(ego_from_global @ nusc.box_velocity(box.token)).tolist(),
            "category": box.name,
            "num_lidar_pts": ann["num_lidar_pts"],
        })
    cameras = {}
    for channel, token in sample["data"].items():
        if channel.startswith("CAM"):
            _, _, intrinsic = nusc.get_sample_data(token)
            cameras[channel] = np.asarray(intrinsic).tolist()
    out[sample["token"]] = {
        "timestamp_us": sample["timestamp"],
        "points": int(cloud.points.shape[1]),
        "ego_translation": pose["translation"],
        "ego_yaw": quaternion_yaw(Quaternion(pose["rotation"])),
        "objects": objects,
        "cameras": cameras,
    }
json.dump(out, sys.stdout)
"""


def _devkit(python: str, version: str, dataroot: Path) -> dict[str, Any]:
    proc = subprocess.run(
        [python, "-c", _DEVKIT_SIDE, version, str(dataroot)],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr)
        msg = f"the devkit side failed (exit {proc.returncode}) under {python}"
        raise SystemExit(msg)
    result: dict[str, Any] = json.loads(proc.stdout)
    return result


def _angle(a: float, b: float) -> float:
    return abs(math.remainder(a - b, math.tau))


def _compare(dataroot: Path, devkit: dict[str, Any]) -> dict[str, float]:
    from redrive.geometry.se3 import yaw_from_rotation_matrix
    from redrive.io.datasets.nuscenes import NuScenesReader
    from redrive.io.datasets.nuscenes_common import object_class_of, read_lidar_bin

    worst = {
        "samples missing": 0.0,
        "box centre m": 0.0,
        "box size m": 0.0,
        "box yaw rad": 0.0,
        "velocity m/s": 0.0,
        "class mismatches": 0.0,
        "box count mismatches": 0.0,
        "point count mismatches": 0.0,
        "ego position m": 0.0,
        "ego yaw rad": 0.0,
        "intrinsics px": 0.0,
    }
    with NuScenesReader(dataroot) as log:
        samples = {s.token: s for s in log.samples}
    for token, ref in devkit.items():
        sample = samples.get(token)
        if sample is None:
            worst["samples missing"] += 1
            continue
        ours = {o.object_id: o for o in sample.objects}
        if len(ours) != len(ref["objects"]):
            worst["box count mismatches"] += 1
        for box in ref["objects"]:
            obj = ours.get(zlib.crc32(box["instance_token"].encode()) & 0x7FFFFFFF)
            if obj is None:
                worst["box count mismatches"] += 1
                continue
            w, length, h = box["wlh"]
            worst["box centre m"] = max(
                worst["box centre m"], float(np.abs(obj.box.center - box["center"]).max())
            )
            worst["box size m"] = max(
                worst["box size m"], float(np.abs(obj.box.size - [length, w, h]).max())
            )
            worst["box yaw rad"] = max(worst["box yaw rad"], _angle(obj.box.yaw_rad, box["yaw"]))
            worst["velocity m/s"] = max(
                worst["velocity m/s"], float(np.abs(obj.velocity - box["velocity"]).max())
            )
            if obj.object_class is not object_class_of(box["category"]):
                worst["class mismatches"] += 1
        if len(read_lidar_bin(sample.lidar_path).xyz) != ref["points"]:
            worst["point count mismatches"] += 1
        pose = sample.global_from_ego
        worst["ego position m"] = max(
            worst["ego position m"], float(np.abs(pose[:3, 3] - ref["ego_translation"]).max())
        )
        worst["ego yaw rad"] = max(
            worst["ego yaw rad"], _angle(yaw_from_rotation_matrix(pose[:3, :3]), ref["ego_yaw"])
        )
        for cam in sample.cameras:
            k = np.asarray(ref["cameras"][cam.channel])
            worst["intrinsics px"] = max(
                worst["intrinsics px"], float(np.abs(cam.intrinsic - k).max())
            )
    return worst


def _compare_info(dataroot: Path, info_dir: Path) -> dict[str, float]:
    """The generated set's first sample against the info file it was written from."""
    from redrive.io.datasets.mmdet3d_info import Mmdet3dInfoReader
    from redrive.io.datasets.nuscenes import NuScenesReader

    with NuScenesReader(dataroot) as tables, Mmdet3dInfoReader(info_dir) as info:
        got, want = tables.samples[0], info.samples[0]
    worst = {"info: box centre m": 0.0, "info: box yaw rad": 0.0, "info: box count": 0.0}
    if len(got.objects) != len(want.objects):
        worst["info: box count"] = abs(len(got.objects) - len(want.objects))
    for w in want.objects:
        g = min(got.objects, key=lambda o: float(np.linalg.norm(o.box.center - w.box.center)))
        worst["info: box centre m"] = max(
            worst["info: box centre m"], float(np.abs(g.box.center - w.box.center).max())
        )
        worst["info: box yaw rad"] = max(
            worst["info: box yaw rad"], _angle(g.box.yaw_rad, w.box.yaw_rad)
        )
    return worst


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--devkit-python", required=True, help="python of a venv with the devkit")
    parser.add_argument("--dataroot", type=Path, help="a real nuScenes data root to check")
    parser.add_argument("--version", default="v1.0-mini", help="the tables' version folder")
    parser.add_argument(
        "--shared-data",
        type=Path,
        default=Path(__file__).resolve().parents[2] / "shared" / "data",
        help="../shared/data (for the generated set)",
    )
    parser.add_argument("--tolerance", type=float, default=1e-4, help="metres, radians, m/s")
    args = parser.parse_args(argv)
    info_dir = args.shared_data / "nuscenes_mmdet3d_demo"
    with tempfile.TemporaryDirectory() as tmp:
        if args.dataroot is None:
            from redrive.testing.nuscenes_tables import write_mini_tables

            info_json = next(info_dir.glob("*.info.json"), None)
            if info_json is None:
                print(f"{info_dir}: no info .json; pass --shared-data or --dataroot")
                return 2
            dataroot = write_mini_tables(Path(tmp) / "nuscenes", info_json, version=args.version)
        else:
            dataroot = args.dataroot
        worst = _compare(dataroot, _devkit(args.devkit_python, args.version, dataroot))
        if args.dataroot is None:
            worst |= _compare_info(dataroot, info_dir)
    failed = False
    for name, value in worst.items():
        bad = value > args.tolerance
        failed |= bad
        print(f"{'FAIL' if bad else 'ok  '}  {name:28s} {value:.3g}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
