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
