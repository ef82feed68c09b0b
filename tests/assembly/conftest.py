"""Fixtures shared with the io tests."""

from tests.io.conftest import kitti_dir

__all__ = ["kitti_dir"]
