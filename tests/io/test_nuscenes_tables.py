"""NuScenesReader on a mini table set written from the real keyframe
(:func:`redrive.testing.nuscenes_tables.write_mini_tables`): the same boxes, points and
calibration as the info file, the ego moving, boxes moving with their velocities, broken tables."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from redrive.assembly.frames import iter_frames
from redrive.errors import LogError
from redrive.io import detect_format, open_log
from redrive.io.datasets.mmdet3d_info import Mmdet3dInfoReader
from redrive.io.datasets.nuscenes import NuScenesReader
from redrive.testing.nuscenes_tables import write_mini_tables
from redrive.types import Frame

pytestmark = pytest.mark.shared_data

_STEM = "n015-2018-07-24-11-22-45+0800"
_DT_S, _STEP_M = 0.5, 4.0


@pytest.fixture(scope="module")
def tables(nuscenes_demo: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("nuscenes") / "data"
    return write_mini_tables(
        root, nuscenes_demo / f"{_STEM}.info.json", n_samples=3, dt_s=_DT_S, ego_step_m=_STEP_M
    )


@pytest.fixture(scope="module")
def frames(tables: Path) -> list[Frame]:
    with open_log(tables) as log:
        return list(iter_frames(log))


def _nearest(objects, center):  # type: ignore[no-untyped-def]
    return min(objects, key=lambda o: float(np.linalg.norm(o.box.center - center)))


def test_root_and_version_folder_open(tables: Path) -> None:
    for path in (tables, tables / "v1.0-mini"):
        assert detect_format(path) == "nuscenes"
        with open_log(path) as log:
            assert isinstance(log, NuScenesReader)
            assert log.version == "v1.0-mini"
            assert len(log.samples) == 3
            assert log.capabilities.has_ground_truth
            assert log.capabilities.has_ego_pose


def test_first_sample_equals_the_info_file(tables: Path, nuscenes_demo: Path) -> None:
    """Two routes to base_link — the tables' global boxes through the ego pose, the info file's
    LiDAR boxes through lidar2ego — give the same boxes."""
    with open_log(tables) as log, Mmdet3dInfoReader(nuscenes_demo) as info:
        got, want = log.samples[0], info.samples[0]
    assert got.stamp_ns == want.stamp_ns
    np.testing.assert_allclose(got.ego_from_lidar, want.ego_from_lidar, atol=1e-6)
    np.testing.assert_allclose(got.global_from_ego, want.global_from_ego, atol=1e-6)
    assert [c.channel for c in got.cameras] == [c.channel for c in want.cameras]
    for a, b in zip(got.cameras, want.cameras, strict=True):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_allclose(a.intrinsic, b.intrinsic)
        np.testing.assert_allclose(a.ego_from_camera, b.ego_from_camera, atol=1e-6)
    assert len(got.objects) == len(want.objects) == 69
    assert len({o.object_id for o in got.objects}) == 69
    for w in want.objects:
        g = _nearest(got.objects, w.box.center)
        np.testing.assert_allclose(g.box.center, w.box.center, atol=1e-5)
        np.testing.assert_allclose(g.box.size, w.box.size)
        assert math.remainder(g.box.yaw_rad - w.box.yaw_rad, math.tau) == pytest.approx(0, abs=1e-6)
        np.testing.assert_allclose(g.velocity, w.velocity, atol=1e-6)  # devkit box_velocity
        assert g.object_class is w.object_class
        assert g.num_lidar_points == w.num_lidar_points


def test_ego_and_boxes_move_between_samples(tables: Path) -> None:
    with open_log(tables) as log:
        samples = log.samples
    first = {o.object_id: o for o in samples[0].objects}
    heading = samples[0].global_from_ego[:3, 0]
    for k, sample in enumerate(samples):
        assert sample.stamp_ns == samples[0].stamp_ns + round(k * _DT_S * 1e9)
        np.testing.assert_allclose(sample.ego_velocity_mps, heading * _STEP_M / _DT_S, atol=1e-6)
        for obj in sample.objects:
            start = first[obj.object_id]
            expected = start.box.center + start.velocity * k * _DT_S - [k * _STEP_M, 0, 0]
            np.testing.assert_allclose(obj.box.center, expected, atol=1e-5)


def test_frames_carry_every_sensor_ground_truth_and_ego(frames: list[Frame]) -> None:
    assert len(frames) == 3
    for frame in frames:
        assert frame.missing == ()
        assert len(frame.sensors) == 7
        assert frame.sensors["lidar_top"].data.xyz.shape == (34_688, 3)
        assert frame.ground_truth is not None
        assert len(frame.ground_truth) == 69
        assert frame.vehicle_state is not None
        assert frame.vehicle_state.speed_mps == pytest.approx(_STEP_M / _DT_S, rel=1e-3)  # xy only


def test_broken_tables_say_what_and_where(tables: Path, tmp_path: Path) -> None:
    copy = tmp_path / "data"
    shutil.copytree(tables, copy, symlinks=True)
    version = copy / "v1.0-mini"
    (version / "ego_pose.json").write_text("[]")
    with pytest.raises(LogError, match=r"token .* no table holds"):
        open_log(copy)
    shutil.copy(tables / "v1.0-mini" / "ego_pose.json", version / "ego_pose.json")
    (version / "scene.json").write_text("{not json")
    with pytest.raises(LogError, match=r"scene\.json: the scene table is not JSON"):
        open_log(copy)
    shutil.copy(tables / "v1.0-mini" / "scene.json", version / "scene.json")
    sample_data = json.loads((version / "sample_data.json").read_text())
    missing = copy / sample_data[0]["filename"]
    missing.unlink()
    with pytest.raises(LogError, match="file named by sample_data is missing"):
        open_log(copy)
    shutil.copytree(version, copy / "v1.0-trainval")
    with pytest.raises(LogError, match="several nuScenes versions"):
        open_log(copy)
