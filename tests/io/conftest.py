"""Fixtures shared by the io tests."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def kitti_dir(shared_data: Path) -> Path:
    path = shared_data / "kitti_object"
    if not (path / "training" / "velodyne").is_dir():
        pytest.skip("kitti_object is not in ../shared/data")
    return path


@pytest.fixture(scope="module")
def nuscenes_demo(shared_data: Path) -> Path:
    """The real nuScenes keyframe as mmdetection3d ships it (info .pkl + .json, sweep, images)."""
    path = shared_data / "nuscenes_mmdet3d_demo"
    if not any(path.glob("*.pkl")):
        pytest.skip("nuscenes_mmdet3d_demo is not in ../shared/data")
    return path
