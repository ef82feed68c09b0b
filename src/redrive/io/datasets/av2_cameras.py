"""The camera images of an Argoverse 2 sensor log: ``sensors/cameras/<name>/<timestamp_ns>.jpg``
with the intrinsics of ``calibration/intrinsics.feather``.

av2-api (``geometry/camera/pinhole_camera.py``, ``Intrinsics``; ``utils/io.py``,
``read_feather`` of the intrinsics): fx_px, fy_px, cx_px, cy_px, radial distortion k1, k2, k3,
height_px, width_px per camera.  The extrinsics (``egovehicle_SE3_sensor``) place each camera's
optical frame (z forward, x right, y down), which is the frame of its images here.  The camera
info is ``plumb_bob`` with D = (k1, k2, 0, 0, k3) (no tangential terms) and P = [K | 0].
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image as PilImage

from redrive.errors import LogError
from redrive.io.datasets._feather import read_feather_columns
from redrive.io.datasets.native import Loader, decoded
from redrive.types import CameraInfo, Image

__all__ = ["camera_images", "camera_infos", "image_loader", "image_topic", "info_topic"]

_INTRINSICS = Path("calibration") / "intrinsics.feather"
_COLUMNS = (
    "sensor_name",
    "fx_px",
    "fy_px",
    "cx_px",
    "cy_px",
    "k1",
    "k2",
    "k3",
    "height_px",
    "width_px",
)


def image_topic(camera: str) -> str:
    return f"/cameras/{camera}/image"


def info_topic(camera: str) -> str:
    return f"/cameras/{camera}/camera_info"


def camera_images(log_dir: Path) -> dict[str, dict[int, Path]]:
    """camera name → {stamp_ns: its JPEG} of every image file present."""
    out: dict[str, dict[int, Path]] = {}
    root = log_dir / "sensors" / "cameras"
    if not root.is_dir():
        return out
    for camera in sorted(p for p in root.iterdir() if p.is_dir()):
        files = {int(p.stem): p for p in camera.glob("*.jpg") if p.stem.isdigit()}
        if files:
            out[camera.name] = files
    return out


def camera_infos(log_dir: Path, cameras: set[str]) -> dict[str, CameraInfo]:
    """The CameraInfo of each camera in ``cameras``.

    Raises:
        LogError: the intrinsics table is missing, damaged, or has no row for one of them.
    """
    if not cameras:
        return {}
    path = log_dir / _INTRINSICS
    if not path.is_file():
        msg = f"{path}: missing; the camera images of {', '.join(sorted(cameras))} need it"
        raise LogError(msg)
    table = read_feather_columns(path, _COLUMNS)
    rows = {str(name): i for i, name in enumerate(table["sensor_name"])}
    out = {}
    for camera in sorted(cameras):
        if camera not in rows:
            msg = f"{path}: no intrinsics for camera {camera} (it has {', '.join(sorted(rows))})"
            raise LogError(msg)
        i = rows[camera]
        k = np.array(
            [
                [float(table["fx_px"][i]), 0.0, float(table["cx_px"][i])],
                [0.0, float(table["fy_px"][i]), float(table["cy_px"][i])],
                [0.0, 0.0, 1.0],
            ]
        )
        p = np.zeros((3, 4))
        p[:, :3] = k
        out[camera] = CameraInfo(
            width=int(table["width_px"][i]),
            height=int(table["height_px"][i]),
            k=k,
            d=np.array(
                [table["k1"][i], table["k2"][i], 0.0, 0.0, table["k3"][i]], dtype=np.float64
            ),
            distortion_model="plumb_bob",
            p=p,
        )
    return out


def image_loader(camera: str, stamp_ns: int, path: Path) -> Loader:
    def load() -> Any:
        try:
            with PilImage.open(path) as img:
                pixels = np.asarray(img.convert("RGB"), dtype=np.uint8)
        except (OSError, ValueError) as err:
            msg = f"{path}: cannot read the {camera} image ({err}); restore the JPEG"
            raise LogError(msg) from err
        return decoded(stamp_ns, camera, Image(pixels=pixels, encoding="rgb8"))

    return load
