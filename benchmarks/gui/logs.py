"""The benchmark logs (see :mod:`benchmarks.gui`): written by redrive's own McapWriter, one
frame at a time, and cached in a directory by their parameters."""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.synth_log import _SweepMaker
from redrive.geometry.se3 import quaternion_from_rotation_matrix
from redrive.io.mcap.writer import McapWriter
from redrive.types import (
    Box3D,
    CameraInfo,
    DetectedObject,
    Image,
    ObjectClass,
    PointCloud,
    Transform,
    VehicleState,
)

__all__ = ["BenchLog", "bench_log", "default_cache", "write_bench_log"]

LIDAR_TOPIC = "/lidar_top"
CAMERA_TOPIC = "/camera_front/image_raw"
CAMERA_INFO_TOPIC = "/camera_front/camera_info"
GROUND_TRUTH_TOPIC = "/ground_truth/objects"  # as redrive.sim.synth writes it
EGO_STATE_TOPIC = "/ground_truth/ego_state"
_PERIOD_NS = 100_000_000  # 10 Hz
_START_NS = 1_700_000_000_000_000_000


@dataclass(frozen=True, slots=True, kw_only=True)
class BenchLog:
    """A benchmark log: where, what, and whether this run wrote it."""

    path: Path
    frames: int
    points: int
    boxes: int
    image_size: tuple[int, int]  # width, height
    file_bytes: int
    written: bool  # False: found in the cache
    write_s: float


def write_bench_log(
    path: str | Path,
    *,
    frames: int,
    points: int = 120_000,
    boxes: int = 50,
    image_size: tuple[int, int] = (1280, 720),
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> BenchLog:
    """Write the benchmark log (see :mod:`benchmarks.gui`) to ``path`` (atomically: a failure
    leaves nothing).  Memory stays bounded: one frame at a time."""
    if frames < 1 or points < 1 or boxes < 0:
        msg = f"frames ({frames}) and points ({points}) must be ≥ 1, boxes ({boxes}) ≥ 0"
        raise ValueError(msg)
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    sweeps = _SweepMaker(points, "xyzi", seed)
    width, height = image_size
    rows, cols = np.mgrid[0:height, 0:width]
    base_image = np.stack(
        [cols * 255 // width, rows * 255 // height, (rows + cols) * 255 // (width + height)],
        axis=2,
    ).astype(np.uint8)
    info = CameraInfo(
        width=width,
        height=height,
        k=np.array([[900.0, 0.0, width / 2], [0.0, 900.0, height / 2], [0.0, 0.0, 1.0]]),
    )
    # Optical frame: z forward (base x), x right (base −y), y down (base −z).
    base_from_optical = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    static = (
        Transform(
            parent_frame="base_link", child_frame="lidar_top", translation=np.array([0.0, 0.0, 1.8])
        ),
        Transform(
            parent_frame="base_link",
            child_frame="camera_front_optical",
            translation=np.array([1.5, 0.0, 1.5]),
            rotation=quaternion_from_rotation_matrix(base_from_optical),
        ),
    )
    angle = rng.uniform(0.0, 2 * math.pi, boxes)
    radius = rng.uniform(8.0, 55.0, boxes)
    start_xy = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)
    yaw = rng.uniform(-math.pi, math.pi, boxes)
    velocity = rng.uniform(-3.0, 3.0, (boxes, 2))
    with McapWriter(path) as out:
        out.write("/tf_static", _START_NS, static)
        for k in range(frames):
            stamp = _START_NS + k * _PERIOD_NS
            sweep = sweeps.sweep()
            cloud = PointCloud(
                xyz=np.stack([sweep["x"], sweep["y"], sweep["z"]], axis=1),
                channels={"intensity": sweep["intensity"].copy()},
            )
            xy = start_xy + velocity * (k * _PERIOD_NS / 1e9)
            objects = tuple(
                DetectedObject(
                    object_id=i,
                    object_class=ObjectClass.VEHICLE,
                    box=Box3D(
                        center=np.array([xy[i, 0], xy[i, 1], 0.8]),
                        size=np.array([4.5, 1.9, 1.6]),
                        yaw_rad=float(yaw[i]),
                    ),
                    velocity=np.array([velocity[i, 0], velocity[i, 1], 0.0]),
                    num_lidar_points=100,  # ground-truth facts: written as GroundTruthObjectArray
                    visible=True,
                )
                for i in range(boxes)
            )
            pixels = np.roll(base_image, 8 * k, axis=1) + rng.integers(
                0, 6, base_image.shape, dtype=np.uint8
            )
            ego_x = 10.0 * k * _PERIOD_NS / 1e9
            out.write(
                "/tf",
                stamp,
                (
                    Transform(
                        parent_frame="map",
                        child_frame="base_link",
                        translation=np.array([ego_x, 0.0, 0.0]),
                        stamp_ns=stamp,
                    ),
                ),
            )
            out.write(
                EGO_STATE_TOPIC,
                stamp,
                VehicleState(
                    stamp_ns=stamp,
                    position=np.array([ego_x, 0.0, 0.0]),
                    velocity=np.array([10.0, 0.0, 0.0]),
                ),
            )
            out.write(LIDAR_TOPIC, stamp, cloud, frame_id="lidar_top")
            out.write(GROUND_TRUTH_TOPIC, stamp, objects, frame_id="base_link")
            out.write(
                CAMERA_TOPIC,
                stamp,
                Image(pixels=pixels, encoding="rgb8"),
                frame_id="camera_front_optical",
            )
            out.write(CAMERA_INFO_TOPIC, stamp, info, frame_id="camera_front_optical")
            if progress is not None:
                progress(k + 1, frames)
    path = Path(path)
    return BenchLog(
        path=path,
        frames=frames,
        points=points,
        boxes=boxes,
        image_size=(width, height),
        file_bytes=path.stat().st_size,
        written=True,
        write_s=time.perf_counter() - t0,
    )


def bench_log(
    cache: str | Path,
    *,
    frames: int,
    points: int = 120_000,
    boxes: int = 50,
    image_size: tuple[int, int] = (1280, 720),
    progress: Callable[[int, int], None] | None = None,
) -> BenchLog:
    """The benchmark log of these parameters in ``cache`` (created), written only if missing."""
    cache = Path(cache)
    cache.mkdir(parents=True, exist_ok=True)
    width, height = image_size
    path = cache / f"gui-{frames}f-{points}p-{boxes}b-{width}x{height}.mcap"
    if path.is_file():
        return BenchLog(
            path=path,
            frames=frames,
            points=points,
            boxes=boxes,
            image_size=(width, height),
            file_bytes=path.stat().st_size,
            written=False,
            write_s=0.0,
        )
    return write_bench_log(
        path, frames=frames, points=points, boxes=boxes, image_size=image_size, progress=progress
    )


def default_cache() -> Path:
    """Where the logs are kept between runs by default: ``$TMPDIR/redrive-bench-gui``."""
    return Path(tempfile.gettempdir()) / "redrive-bench-gui"
