"""A small real ROS 1 bag (written with rosbags) for the engine tests: 50 LiDAR frames at 10 Hz."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.testing.demo_log import write_demo_bag


@pytest.fixture(scope="session")
def demo_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_demo_bag(tmp_path_factory.mktemp("engine") / "demo.bag")
