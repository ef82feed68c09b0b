"""mmdetection3d nuScenes info files (``.pkl``, or the same data as JSON) read as a log.

An info file (mmdet3d ≥ 1.1, ``info_version`` 1.1, ``metainfo.dataset == "nuscenes"``) lists
keyframes in ``data_list``; each holds ``timestamp`` (s), ``ego2global`` (4×4), ``lidar_points``
(``lidar_path``, ``lidar2ego`` 4×4, ``num_pts_feats`` 5), ``images`` per camera (``img_path``,
``timestamp``, ``cam2img`` 3×3, ``cam2ego`` 4×4) and ``instances`` (``bbox_3d`` = x, y, z of the
box centre, x_size (length), y_size (width), z_size (height), yaw — in the LiDAR frame;
``bbox_label_3d`` indexes ``metainfo.categories``, −1 for ignored classes; ``velocity`` vx, vy
in the LiDAR frame; ``num_lidar_pts``).  The messages are those of
:mod:`redrive.io.datasets.nuscenes_common`.

``path`` is the info file, or a folder holding one (a ``.pkl`` is taken before a ``.json``).
Data files are looked up by their name next to the info file, then under
``samples/<channel>/`` and ``sweeps/<channel>/`` there (a nuScenes data root), then as given.

Pickles are read with a restricted unpickler: only builtins containers and numpy's array and
scalar reconstruction (``numpy.dtype`` refusing object dtypes, ``_codecs.encode`` only as
latin-1) may be named — any other global in the file is refused, so a hostile ``.pkl`` cannot run
code.
"""

from __future__ import annotations

import _codecs
import io
import json
import logging
import pickle
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import LogError
from redrive.io.datasets.nuscenes_common import (
    CAMERA_CHANNELS,
    LIDAR_CHANNEL,
    NuScenesCamera,
    NuScenesReaderBase,
    NuScenesSample,
    boxes_to_base,
    gravity_aligned_rotations,
    object_class_of,
)
from redrive.types import ObjectClass

__all__ = ["Mmdet3dInfoReader", "find_info_file", "load_info", "restricted_loads"]

logger = logging.getLogger(__name__)

_HEAD_BYTES = 65536  # the metainfo and the first keys of data_list are near the start


def _latin1_encode(obj: str, encoding: str = "latin1") -> bytes:
    """``_codecs.encode`` as numpy's protocol-2 pickles use it: str → bytes, latin-1 only."""
    if encoding not in ("latin1", "latin-1") or not isinstance(obj, str):
        msg = f"_codecs.encode with encoding {encoding!r} is not allowed in an info file"
        raise pickle.UnpicklingError(msg)
    out: bytes = _codecs.encode(obj, "latin1")
    return out


def _plain_dtype(*args: Any) -> np.dtype[Any]:
    dtype: np.dtype[Any] = np.dtype(*args)
    if dtype.hasobject:
        msg = f"object arrays ({dtype}) are not allowed in an info file"
        raise pickle.UnpicklingError(msg)
    return dtype


def _frombuffer(buf: Any, dtype: Any, shape: Any, order: str) -> Any:
    """numpy's protocol-5 array reconstruction, refusing object dtypes."""
    plain = _plain_dtype(dtype)
    return np.frombuffer(buf, dtype=plain).reshape(shape, order=order)  # type: ignore[call-overload]


_ALLOWED: Mapping[tuple[str, str], Any] = {
    ("numpy.core.numeric", "_frombuffer"): _frombuffer,
    ("numpy._core.numeric", "_frombuffer"): _frombuffer,
    ("numpy.core.multiarray", "_reconstruct"): np._core.multiarray._reconstruct,  # type: ignore[attr-defined]
    ("numpy._core.multiarray", "_reconstruct"): np._core.multiarray._reconstruct,  # type: ignore[attr-defined]
    ("numpy.core.multiarray", "scalar"): np._core.multiarray.scalar,  # type: ignore[attr-defined]
    ("numpy._core.multiarray", "scalar"): np._core.multiarray.scalar,  # type: ignore[attr-defined]
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): _plain_dtype,
    ("_codecs", "encode"): _latin1_encode,
}


class _RestrictedUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        try:
            return _ALLOWED[(module, name)]
        except KeyError:
            msg = (
                f"global {module}.{name} is not allowed (only builtins and numpy arrays may be "
                "named in an info file)"
            )
            raise pickle.UnpicklingError(msg) from None

    def persistent_load(self, pid: Any) -> Any:
        msg = "persistent ids are not allowed in an info file"
        raise pickle.UnpicklingError(msg)


def restricted_loads(data: bytes) -> object:
    """Unpickle ``data`` allowing only builtins and numpy array/scalar reconstruction.

    Raises:
        pickle.UnpicklingError: the pickle names anything else (or is damaged).
    """
    return _RestrictedUnpickler(io.BytesIO(data)).load()


def load_info(path: Path) -> dict[str, Any]:
    """The info file's content (``metainfo``, ``data_list``) from a ``.pkl`` or its JSON form.

    Raises:
        LogError: unreadable, refused by the restricted unpickler, or not an info file.
    """
    try:
        data = path.read_bytes()
    except OSError as err:
        msg = f"{path}: cannot read the info file ({err.strerror})"
        raise LogError(msg) from err
    try:
        content = restricted_loads(data) if data[:1] == b"\x80" else json.loads(data)
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError) as err:
        msg = (
            f"{path}: cannot read the mmdetection3d info file ({err}); it must be a pickle of "
            "plain data and numpy arrays, or its JSON form"
        )
        raise LogError(msg) from err
    if not isinstance(content, dict) or not isinstance(content.get("data_list"), list):
        msg = (
            f"{path}: not an mmdetection3d info file (no data_list); convert old infos with "
            "mmdet3d's tools/dataset_converters/update_infos_to_v2.py"
        )
        raise LogError(msg)
    return content


def _looks_like_info(path: Path) -> bool:
    if not path.is_file() or path.suffix.lower() not in (".pkl", ".json"):
        return False
    with path.open("rb") as fh:
        head = fh.read(_HEAD_BYTES)
    return (
        b"data_list" in head
        and b"metainfo" in head
        and b"lidar_points" in head
        and b"nuscenes" in head.lower()  # metainfo: dataset "nuscenes" (KITTI's has other names)
    )


def find_info_file(path: Path) -> Path | None:
    """The info file ``path`` is, or the one a folder holds (``.pkl`` before ``.json``)."""
    if path.is_file():
        return path if _looks_like_info(path) else None
    if not path.is_dir():
        return None
    for pattern in ("*.pkl", "*.json"):
        found = sorted(p for p in path.glob(pattern) if _looks_like_info(p))
        if found:
            return found[0]
    return None


def _matrix(value: Any, shape: tuple[int, int], what: str) -> npt.NDArray[np.float64]:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != shape:
        msg = f"{what} must be {shape[0]}×{shape[1]}, got shape {arr.shape}"
        raise ValueError(msg)
    return arr


class Mmdet3dInfoReader(NuScenesReaderBase):
    """An mmdetection3d nuScenes info file as a :class:`~redrive.io.base.LogReader`
    (format ``nuscenes-mmdet3d``).

    Raises (at open):
        LogError: no info file; it is refused or damaged; a keyframe lacks a field; a LiDAR
            sweep or camera image it names is not found.
    """

    format = "nuscenes-mmdet3d"
    description = (
        "an mmdetection3d nuScenes info file (.pkl or its JSON form, or a folder holding one) "
        "with its LiDAR sweeps and camera images"
    )

    @classmethod
    def recognises(cls, path: Path) -> bool:
        return find_info_file(path) is not None

    def __init__(self, path: str | Path, *, strict: bool = True) -> None:
        """``strict`` is accepted like every reader's; the info file is checked whole at open."""
        self.path = Path(path)
        # a file given by name is read whatever it holds: load_info and the dataset check say why not
        info_file = self.path if self.path.is_file() else find_info_file(self.path)
        if info_file is None:
            msg = (
                f"{self.path}: no mmdetection3d info file (a .pkl or .json with metainfo and "
                "data_list) here; pass the info file or its folder"
            )
            raise LogError(msg)
        self.info_file = info_file
        content = load_info(info_file)
        meta = content.get("metainfo") or {}
        dataset = str(meta.get("dataset", meta.get("DATASET", "nuscenes")))
        if dataset.lower() != "nuscenes":
            msg = (
                f"{info_file}: an mmdetection3d info file of {dataset}, not nuScenes; redrive "
                "reads nuScenes and KITTI info files (a KITTI one as format kitti-mmdet3d)"
            )
            raise LogError(msg)
        categories = meta.get("categories") or {}
        self.class_names: dict[int, str] = {int(i): str(n) for n, i in categories.items()}
        samples: list[NuScenesSample] = []
        for index, entry in enumerate(content["data_list"]):
            where = f"{info_file}: data_list[{index}]"
            try:
                samples.append(self._sample(entry))
            except (KeyError, TypeError, ValueError) as err:
                msg = f"{where}: {err!s} — the keyframe is incomplete; regenerate the info file"
                raise LogError(msg) from err
        samples.sort(key=lambda s: s.stamp_ns)
        self._samples = samples
        self._init_topics()

    def _file(self, name: str, channel: str) -> Path:
        given = Path(name)
        root = self.info_file.parent
        candidates = [
            root / given.name,
            root / "samples" / channel / given.name,
            root / "sweeps" / channel / given.name,
            root / given,
            given,
        ]
        for cand in candidates:
            if cand.is_file():
                return cand
        msg = (
            f"{self.info_file}: {channel} file {name!r} not found next to the info file nor "
            f"under samples/{channel}/ or sweeps/{channel}/ there; put the data beside it"
        )
        raise LogError(msg)

    def _sample(self, entry: Mapping[str, Any]) -> NuScenesSample:
        stamp_ns = _stamp_ns(entry["timestamp"])
        lidar = entry["lidar_points"]
        if int(lidar.get("num_pts_feats", 5)) != 5:
            msg = f"num_pts_feats is {lidar['num_pts_feats']}, nuScenes sweeps have 5"
            raise ValueError(msg)
        ego_from_lidar = _matrix(lidar["lidar2ego"], (4, 4), "lidar2ego")
        cameras: list[NuScenesCamera] = []
        images = entry.get("images") or {}
        for channel in CAMERA_CHANNELS:
            image = images.get(channel)
            if not image or not image.get("img_path"):
                continue
            cameras.append(
                NuScenesCamera(
                    channel=channel,
                    path=self._file(str(image["img_path"]), channel),
                    stamp_ns=_stamp_ns(image.get("timestamp", entry["timestamp"])),
                    intrinsic=_matrix(image["cam2img"], (3, 3), f"{channel} cam2img"),
                    ego_from_camera=_matrix(image["cam2ego"], (4, 4), f"{channel} cam2ego"),
                )
            )
        global_from_ego = _matrix(entry["ego2global"], (4, 4), "ego2global")
        return NuScenesSample(
            token=str(entry.get("token", "")),
            stamp_ns=stamp_ns,
            lidar_path=self._file(str(lidar["lidar_path"]), LIDAR_CHANNEL),
            ego_from_lidar=ego_from_lidar,
            global_from_ego=global_from_ego,
            cameras=tuple(cameras),
            objects=self._objects(
                entry.get("instances") or [], ego_from_lidar, global_from_ego @ ego_from_lidar
            ),
        )

    def _objects(
        self,
        instances: Sequence[Mapping[str, Any]],
        ego_from_lidar: npt.NDArray[np.float64],
        global_from_lidar: npt.NDArray[np.float64],
    ) -> tuple[Any, ...]:
        """The boxes of an info entry (LiDAR frame, heading only) as ground truth in base_link.
        nuScenes annotates boxes upright in the global frame; the info keeps only their heading
        in the LiDAR frame, so the whole rotation is rebuilt upright in the global frame
        (:func:`gravity_aligned_rotations`) — the box the devkit counts ``num_lidar_pts`` in."""
        if not instances:
            return ()
        boxes = np.array([inst["bbox_3d"] for inst in instances], dtype=np.float64)
        if boxes.ndim != 2 or boxes.shape[1] < 7:
            msg = f"instances' bbox_3d must hold 7 values (x y z l w h yaw), got {boxes.shape}"
            raise ValueError(msg)
        velocities = np.zeros((len(instances), 3))
        for i, inst in enumerate(instances):
            vel = inst.get("velocity")
            if vel is not None and len(vel) >= 2:
                velocities[i, :2] = vel[:2]
        classes: list[ObjectClass] = []
        for inst in instances:
            label = int(inst.get("bbox_label_3d", inst.get("bbox_label", -1)))
            name = self.class_names.get(label, "")
            classes.append(object_class_of(name) if name else ObjectClass.OTHER)
        points = [
            int(inst["num_lidar_pts"]) if inst.get("num_lidar_pts") is not None else None
            for inst in instances
        ]
        return boxes_to_base(
            centers=boxes[:, :3],
            sizes_lwh=boxes[:, 3:6],
            rotations=gravity_aligned_rotations(boxes[:, 6], global_from_lidar),
            velocities=velocities,
            base_from_src=ego_from_lidar,
            classes=classes,
            num_lidar_points=points,
        )


def _stamp_ns(seconds: Any) -> int:
    """nuScenes stamps are whole microseconds: s (float) → int ns without float dust."""
    return round(float(seconds) * 1e6) * 1000
