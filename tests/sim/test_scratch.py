"""Sensor models keep their work arrays between calls: what one sweep or image leaves in them
never shows in the next, and threads do not share them."""

from __future__ import annotations

import pickle
import threading

import numpy as np

from redrive.sim.camera import CameraModel
from redrive.sim.lidar import LidarModel
from redrive.sim.rig import CameraIntrinsics, default_rig
from redrive.sim.scratch import Scratch
from tests.sim.test_lidar import make_scene

# a full scene (boxes all around, near and far) and a sparse one, sweeps of different cull
_BUSY = [
    (6.0, 0.0, 0.9, 4.5, 1.9, 1.8, 0.2),
    (-8.0, 3.0, 1.5, 10.0, 2.5, 3.0, 1.0),
    (0.0, -7.0, 0.8, 1.0, 1.0, 1.6, 0.0),
    (15.0, 8.0, 4.0, 8.0, 8.0, 8.0, 0.4),
]
_SPARSE = [(25.0, -2.0, 0.9, 4.5, 1.9, 1.8, -0.3)]


def _mount() -> np.ndarray:
    m = np.eye(4)
    m[2, 3] = 1.8
    return m


def test_a_sweep_after_another_equals_a_fresh_models() -> None:
    used = LidarModel("VLP-16", base_from_sensor=_mount())
    used.scan(make_scene(_BUSY), np.random.default_rng(1))
    after = used.scan(make_scene(_SPARSE), np.random.default_rng(2))
    fresh = LidarModel("VLP-16", base_from_sensor=_mount()).scan(
        make_scene(_SPARSE), np.random.default_rng(2)
    )
    assert len(after.cloud) > 0
    assert np.array_equal(after.cloud.xyz, fresh.cloud.xyz)
    for name in fresh.cloud.channels:
        assert np.array_equal(after.cloud.channels[name], fresh.cloud.channels[name])
    assert np.array_equal(after.object_ids, fresh.object_ids)
    assert after.hits_per_object == fresh.hits_per_object


def test_an_image_after_another_equals_a_fresh_cameras() -> None:
    intr = CameraIntrinsics(width=160, height=120, fx=120.0, fy=120.0, cx=79.5, cy=59.5)
    optical = default_rig()["camera_front"].base_from_optical()
    used = CameraModel(intr, base_from_optical=optical, workers=2)
    first = used.render(make_scene(_BUSY))
    after = used.render(make_scene(_SPARSE))
    fresh = CameraModel(intr, base_from_optical=optical, workers=1).render(make_scene(_SPARSE))
    assert not np.array_equal(first.image.pixels, after.image.pixels)
    assert np.array_equal(after.image.pixels, fresh.image.pixels)
    assert np.array_equal(after.depth_m, fresh.depth_m)
    assert after.pixels_per_object == fresh.pixels_per_object
    # what was handed out is not overwritten by the next image
    again = used.render(make_scene(_BUSY))
    assert np.array_equal(first.image.pixels, again.image.pixels)
    assert np.array_equal(first.depth_m, again.depth_m)


def test_each_thread_gets_its_own_arrays() -> None:
    scratch = Scratch()
    mine = scratch.array("a", (4,), np.float32)
    assert scratch.array("a", (4,), np.float32) is mine
    assert scratch.array("a", (5,), np.float32) is not mine  # a new shape: a new array
    seen: list[np.ndarray] = []
    thread = threading.Thread(target=lambda: seen.append(scratch.array("a", (5,), np.float32)))
    thread.start()
    thread.join()
    assert seen[0] is not scratch.array("a", (5,), np.float32)


def test_a_model_with_work_arrays_still_pickles() -> None:
    model = LidarModel("VLP-16", base_from_sensor=_mount())
    sweep = model.scan(make_scene(_SPARSE), np.random.default_rng(2))
    copy = pickle.loads(pickle.dumps(model))
    again = copy.scan(make_scene(_SPARSE), np.random.default_rng(2))
    assert np.array_equal(again.cloud.xyz, sweep.cloud.xyz)
