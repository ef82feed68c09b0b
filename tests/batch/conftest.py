"""Fixtures of the batch tests: short demo bags (ROS 1, LiDAR + odometry + IMU + GNSS, written
with the real writer) of slightly different lengths, two cheap pipeline files, and small MCAP
logs with ground truth for the evaluation of batches."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from redrive.io.mcap.writer import McapWriter
from redrive.testing.demo_log import write_demo_bag
from redrive.types import (
    Box3D,
    DetectedObject,
    Frame,
    ObjectClass,
    PointCloud,
    SensorData,
    SensorType,
    VehicleState,
)

from .outputs import batch

#: seconds of the four logs: about 2 s each, different so that their cells differ.
DURATIONS_S = (2.0, 2.1, 2.2, 2.3)

PIPELINE_A = """\
[[stage]]
name = "planning"
[[stage.algorithm]]
plugin = "idm-planner"

[[stage]]
name = "control"
[[stage.algorithm]]
plugin = "pure-pursuit-pid"
"""

PIPELINE_B = """\
[[stage]]
name = "detection"
[[stage.algorithm]]
plugin = "cluster-detector"

[[stage]]
name = "planning"
[[stage.algorithm]]
plugin = "idm-planner"
"""


@pytest.fixture(scope="package")
def logs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("batch_logs")
    return [
        write_demo_bag(folder / f"drive{i}.bag", duration_s=d) for i, d in enumerate(DURATIONS_S)
    ]


@pytest.fixture(scope="package")
def pipelines(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("batch_pipelines")
    out = []
    for name, text in (("a", PIPELINE_A), ("b", PIPELINE_B)):
        path = folder / f"{name}.toml"
        path.write_text(text, encoding="utf-8")
        out.append(path)
    return out


@pytest.fixture(scope="package")
def two_workers(
    logs: list[Path], pipelines: list[Path], tmp_path_factory: pytest.TempPathFactory
) -> Path:
    out = tmp_path_factory.mktemp("two_workers") / "batch"
    args = [str(p) for p in logs]
    for p in pipelines:
        args += ["--pipeline", str(p)]
    assert batch(out, *args, "--workers", "2") == 0
    return out


def write_truth_log(path: Path, *, seed: int, frames: int = 20) -> Path:
    """A small MCAP log (written by the real writer) with a LiDAR, the ego's odometry and
    ground-truth objects that move with their ids kept: vehicles and pedestrians, how many and
    where depending on ``seed``."""
    rng = np.random.default_rng(seed)
    n_obj = 3 + seed % 3
    start = rng.uniform([5.0, -8.0], [40.0, 8.0], size=(n_obj, 2))
    speed = rng.uniform(-2.0, 2.0, size=(n_obj, 2))
    classes = [ObjectClass.VEHICLE if i % 3 else ObjectClass.PEDESTRIAN for i in range(n_obj)]
    t0_ns = 1_700_000_000_000_000_000 + seed * 10**12
    with McapWriter(path) as out:
        for k in range(frames):
            stamp = t0_ns + k * 100_000_000
            xy = start + speed * (k * 0.1)
            truth = tuple(
                DetectedObject(
                    object_id=i + 1,
                    object_class=classes[i],
                    confidence=1.0,
                    box=Box3D(
                        center=np.array([xy[i, 0], xy[i, 1], 0.8]),
                        size=np.array([4.5, 1.9, 1.6] if i % 3 else [0.7, 0.7, 1.8]),
                        yaw_rad=0.1 * i,
                    ),
                )
                for i in range(n_obj)
            )
            cloud = PointCloud(xyz=rng.normal(size=(64, 3)).astype(np.float32), channels={})
            out.write_frame(
                Frame(
                    stamp_ns=stamp,
                    index=k,
                    sensors={
                        "lidar_top": SensorData(
                            sensor_id="lidar_top",
                            sensor_type=SensorType.LIDAR,
                            stamp_ns=stamp,
                            frame_id="lidar",
                            data=cloud,
                        )
                    },
                    vehicle_state=VehicleState(
                        stamp_ns=stamp,
                        frame_id="map",
                        position=np.array([k * 0.5, 0.0, 0.0]),
                        velocity=np.array([5.0, 0.0, 0.0]),
                    ),
                    ground_truth=truth,
                )
            )
    return path


@pytest.fixture(scope="package")
def truth_logs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Three logs with ground truth, of different lengths."""
    folder = tmp_path_factory.mktemp("truth_logs")
    return [
        write_truth_log(folder / f"truth{i}.mcap", seed=i, frames=n)
        for i, n in enumerate((20, 14, 26))
    ]
