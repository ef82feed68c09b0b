"""Synthetic logs carry each camera's true intrinsics; camera_calibrations projects like the sim."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from redrive.assembly.calibration import CameraCalibration, camera_calibrations
from redrive.geometry import project_points, rotation_matrix_from_yaw
from redrive.geometry.se3 import se3_from_rotation_translation
from redrive.io import open_log
from redrive.io.ros.decoders import decode
from redrive.sim.camera import CameraModel
from redrive.sim.rig import rig_from_mapping
from redrive.sim.scenario import load_scenario
from redrive.sim.synth import EGO_STATE_TOPIC, GROUND_TRUTH_TOPIC, synthesize
from redrive.types import CameraInfo, DetectedObject, VehicleState
from tests.sim.test_camera import RED, _mask, _rect
from tests.sim.test_lidar import make_scene
from tests.sim.test_synth import SMALL_RIG

IMAGE_TOPIC = "/camera_front/image_raw"
INFO_TOPIC = "/camera_front/camera_info"


@pytest.fixture(scope="module")
def urban_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    scenario = dataclasses.replace(load_scenario("urban"), rig=SMALL_RIG)
    path = tmp_path_factory.mktemp("synth") / "urban.mcap"
    summary = synthesize(scenario, path, duration_s=2.0)
    assert summary.topics[INFO_TOPIC] == "sensor_msgs/msg/CameraInfo"
    return path


@pytest.fixture(scope="module")
def calibration(urban_log: Path) -> CameraCalibration:
    with open_log(urban_log) as log:
        return camera_calibrations(log)[IMAGE_TOPIC]


def test_every_image_has_its_camera_info(urban_log: Path) -> None:
    spec = rig_from_mapping(SMALL_RIG, source="test")["camera_front"]
    assert spec.camera is not None
    with open_log(urban_log) as log:
        assert log.topics[INFO_TOPIC].count == log.topics[IMAGE_TOPIC].count == 10
        by_topic: dict[str, list[tuple[int, int, str]]] = {IMAGE_TOPIC: [], INFO_TOPIC: []}
        for message in log.messages(topics=[IMAGE_TOPIC, INFO_TOPIC]):
            decoded = decode(message, log.deserialize)
            by_topic[message.topic].append(
                (message.log_time_ns, decoded.stamp_ns, decoded.frame_id)
            )
            if isinstance(decoded.value, CameraInfo):
                info = decoded.value
                assert (info.width, info.height) == (320, 180)
                np.testing.assert_array_equal(info.k, spec.camera.matrix())
                np.testing.assert_array_equal(info.p[:, :3], spec.camera.matrix())
                np.testing.assert_array_equal(info.d, np.zeros(5))
    assert by_topic[INFO_TOPIC] == by_topic[IMAGE_TOPIC]
    assert {frame for _, _, frame in by_topic[INFO_TOPIC]} == {"camera_front_optical"}


def test_calibration_is_the_rigs(calibration: CameraCalibration) -> None:
    spec = rig_from_mapping(SMALL_RIG, source="test")["camera_front"]
    assert spec.camera is not None
    assert (calibration.info_topic, calibration.frame_id) == (INFO_TOPIC, "camera_front_optical")
    np.testing.assert_array_equal(calibration.info.k, spec.camera.matrix())
    np.testing.assert_allclose(
        calibration.base_from_optical, spec.base_from_optical(), rtol=0, atol=1e-12
    )


def _map_from_base(state: VehicleState) -> np.ndarray:
    return se3_from_rotation_translation(
        rotation_matrix_from_yaw(state.heading_rad), state.position
    )


def test_ground_truth_projects_as_the_simulated_camera(
    urban_log: Path, calibration: CameraCalibration
) -> None:
    """Ground truth (base_link) through image_from_base lands where the sim's own camera
    (``image_from_map`` at the true ego pose) puts the same objects."""
    camera = CameraModel.from_spec(rig_from_mapping(SMALL_RIG, source="test")["camera_front"])
    with open_log(urban_log) as log:
        image_stamps = {m.log_time_ns for m in log.messages(topics=[IMAGE_TOPIC])}
        states: dict[int, VehicleState] = {}
        objects: dict[int, tuple[DetectedObject, ...]] = {}
        for message in log.messages(topics=[EGO_STATE_TOPIC, GROUND_TRUTH_TOPIC]):
            value = decode(message, log.deserialize).value
            if isinstance(value, VehicleState):
                states[message.log_time_ns] = value
            elif message.log_time_ns in image_stamps and isinstance(value, tuple):
                objects[message.log_time_ns] = value  # type: ignore[assignment]
    assert len(objects) >= 5
    inside = 0
    for stamp_ns, objs in objects.items():
        centres = np.array([o.box.center for o in objs])
        uv, depth = project_points(calibration.image_from_base(), centres)
        map_from_base = _map_from_base(states[stamp_ns])
        map_centres = centres @ map_from_base[:3, :3].T + map_from_base[:3, 3]
        uv_sim, depth_sim = project_points(camera.image_from_map(map_from_base), map_centres)
        np.testing.assert_allclose(depth, depth_sim, rtol=0, atol=1e-6)
        ahead = depth > 0
        np.testing.assert_allclose(uv[ahead], uv_sim[ahead], rtol=0, atol=1e-4)
        inside += int(
            np.sum(ahead & (uv[:, 0] >= 0) & (uv[:, 0] < 320) & (uv[:, 1] >= 0) & (uv[:, 1] < 180))
        )
    assert inside > 0


def test_projected_box_centre_lands_on_the_rendered_box(calibration: CameraCalibration) -> None:
    """The renderer draws a red box; its centre, projected with the log's calibration, falls on
    red pixels, inside the box's drawn bounds."""
    camera = CameraModel.from_spec(rig_from_mapping(SMALL_RIG, source="test")["camera_front"])
    box = (14.0, 1.5, 0.9, 4.5, 1.9, 1.8, 0.3)
    scene = make_scene([box], colors=[RED])  # map = base_link
    red = _mask(camera.render(scene).image.pixels, RED)
    assert red.sum() > 100
    uv, depth = project_points(calibration.image_from_base(), np.array([box[:3]]))
    assert depth[0] > 0
    u, v = uv[0]
    left, top, right, bottom = _rect(red)
    assert left < u < right
    assert top < v < bottom
    assert red[round(v), round(u)]
