"""camera_calibrations: camera infos + static transforms, read early and paired by namespace."""

from __future__ import annotations

import logging
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.assembly.calibration import CameraCalibration, camera_calibrations, camera_info_topics
from redrive.geometry import (
    compose,
    invert,
    project_points,
    rotation_matrix_from_yaw,
    transform_from_matrix,
)
from redrive.geometry.se3 import se3_from_rotation_translation
from redrive.io import LogReader, open_log
from redrive.io.base import LogMessage, TopicInfo
from redrive.io.mcap.writer import McapWriter
from redrive.types import CameraInfo, Image, Transform

T0 = 1_700_000_000_000_000_000
PERIOD_NS = 100_000_000
K = np.array([[40.0, 0.0, 16.0], [0.0, 40.0, 12.0], [0.0, 0.0, 1.0]])  # a tiny camera
IMAGE = Image(pixels=np.zeros((24, 32, 3), dtype=np.uint8), encoding="rgb8")
# optical (z forward, x right, y down) → body (x forward, y left, z up)
BODY_FROM_OPTICAL = np.array(
    [[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)
BASE_FROM_CAM = se3_from_rotation_translation(
    rotation_matrix_from_yaw(0.1), [1.5, 0.2, 1.6]
)  # turned 0.1 rad to the left, on the roof


def _info(k: np.ndarray = K) -> CameraInfo:
    return CameraInfo(width=32, height=24, k=k, d=np.zeros(5))


def _tf(parent: str, child: str, matrix: np.ndarray) -> Transform:
    return transform_from_matrix(matrix, parent_frame=parent, child_frame=child, stamp_ns=0)


def _mount() -> tuple[Transform, ...]:
    return (
        _tf("base_link", "cam_link", BASE_FROM_CAM),
        _tf("cam_link", "cam_optical", BODY_FROM_OPTICAL),
    )


def _write_log(
    path: Path,
    *,
    frames: int = 50,
    tf_at: int = 0,
    transforms: tuple[Transform, ...] | None = None,
    infos: dict[str, CameraInfo] | None = None,
) -> Path:
    """Images on /cam/image_raw (and /other/image_raw, no camera info) with camera infos on
    /cam/camera_info, every 100 ms; /tf_static written once, at frame ``tf_at``."""
    infos = {"/cam/camera_info": _info()} if infos is None else infos
    with McapWriter(path) as out:
        for i in range(frames):
            stamp = T0 + i * PERIOD_NS
            if i == tf_at:
                out.write("/tf_static", stamp, transforms if transforms is not None else _mount())
            for info_topic, info in infos.items():
                ns = info_topic.rsplit("/", 1)[0]
                out.write(f"{ns}/image_raw", stamp, IMAGE, frame_id="cam_optical")
                out.write(info_topic, stamp, info, frame_id="cam_optical")
            out.write("/other/image_raw", stamp, IMAGE, frame_id="other_optical")
    return path


class _Counting:
    """A log that counts the messages it hands out (to check nothing more is read)."""

    def __init__(self, log: LogReader) -> None:
        self.log = log
        self.read = 0
        self.calls: list[tuple[tuple[str, ...] | None, int | None, int | None]] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self.log, name)

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        self.calls.append((None if topics is None else tuple(topics), start_ns, stop_ns))
        for message in self.log.messages(topics=topics, start_ns=start_ns, stop_ns=stop_ns):
            self.read += 1
            yield message


def _topics(*pairs: tuple[str, str]) -> dict[str, TopicInfo]:
    return {t: TopicInfo(topic=t, msgtype=m, count=1, encoding="cdr") for t, m in pairs}


def test_camera_info_topics_pair_by_namespace() -> None:
    image, compressed = "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"
    info = "sensor_msgs/msg/CameraInfo"
    topics = _topics(
        ("/front/camera_info", info),
        ("/front/image_raw", image),
        ("/front/image_rect_color", image),
        ("/front/image_raw/compressed", compressed),
        ("/front/deep/image_raw", image),  # another namespace below: not this camera's
        ("/rear/image_raw", image),  # no camera info
        ("/rear/points", "sensor_msgs/msg/PointCloud2"),
        ("/left/camera_info", info),  # no image next to it
        ("/camera_info", info),
        ("/image_raw", image),
    )
    assert camera_info_topics(topics) == {
        "/front/image_raw": "/front/camera_info",
        "/front/image_raw/compressed": "/front/camera_info",
        "/front/image_rect_color": "/front/camera_info",
        "/image_raw": "/camera_info",
    }


def test_calibration_from_camera_info_and_tf_static(tmp_path: Path) -> None:
    with open_log(_write_log(tmp_path / "cam.mcap")) as log:
        calibrations = camera_calibrations(log)
    assert set(calibrations) == {"/cam/image_raw"}  # /other has no camera info
    cal = calibrations["/cam/image_raw"]
    assert isinstance(cal, CameraCalibration)
    assert (cal.image_topic, cal.info_topic) == ("/cam/image_raw", "/cam/camera_info")
    assert (cal.frame_id, cal.base_frame, cal.stamp_ns) == ("cam_optical", "base_link", T0)
    np.testing.assert_array_equal(cal.info.k, K)
    base_from_optical = compose(BASE_FROM_CAM, BODY_FROM_OPTICAL)
    np.testing.assert_allclose(cal.base_from_optical, base_from_optical, atol=1e-12)
    assert not cal.base_from_optical.flags.writeable
    # a point 10 m along the camera's axis lands on the principal point; 1 m to its left, left
    image_from_base = cal.image_from_base()
    assert image_from_base.shape == (3, 4)
    on_axis = transform_points_h(base_from_optical, [[0.0, 0.0, 10.0], [-1.0, 0.0, 10.0]])
    uv, depth = project_points(image_from_base, on_axis)
    np.testing.assert_allclose(depth, [10.0, 10.0])
    np.testing.assert_allclose(uv, [[16.0, 12.0], [12.0, 12.0]], atol=1e-9)
    np.testing.assert_allclose(
        image_from_base, K @ invert(base_from_optical)[:3, :], rtol=0, atol=1e-9
    )


def transform_points_h(matrix: np.ndarray, points: list[list[float]]) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    return pts @ matrix[:3, :3].T + matrix[:3, 3]


def test_reads_only_the_needed_topics_and_stops_early(tmp_path: Path) -> None:
    with open_log(_write_log(tmp_path / "cam.mcap", frames=200)) as log:
        counting = _Counting(log)
        assert set(camera_calibrations(counting)) == {"/cam/image_raw"}  # type: ignore[arg-type]
    assert counting.calls == [(("/cam/camera_info", "/tf_static"), None, None)]
    assert counting.read <= 2  # the first tf_static and camera info: 2 of 201 on those topics


def test_late_tf_static_is_read_alone(tmp_path: Path) -> None:
    """/tf_static after the first camera info: the camera infos are not read on."""
    with open_log(_write_log(tmp_path / "cam.mcap", frames=100, tf_at=60)) as log:
        counting = _Counting(log)
        cal = camera_calibrations(counting)["/cam/image_raw"]  # type: ignore[arg-type]
    assert cal.stamp_ns == T0
    assert [c[0] for c in counting.calls] == [("/cam/camera_info", "/tf_static"), ("/tf_static",)]
    assert counting.read <= 3


def test_stamp_reads_later_infos_and_earlier_tf_static(tmp_path: Path) -> None:
    later_k = K.copy()
    later_k[0, 0] = later_k[1, 1] = 80.0
    path = tmp_path / "cam.mcap"
    with McapWriter(path) as out:
        out.write("/tf_static", T0, _mount())
        for i, k in enumerate((K, K, later_k, later_k)):
            stamp = T0 + i * PERIOD_NS
            out.write("/cam/image_raw", stamp, IMAGE, frame_id="cam_optical")
            out.write("/cam/camera_info", stamp, _info(k), frame_id="cam_optical")
    with open_log(path) as log:
        first = camera_calibrations(log)["/cam/image_raw"]
        later = camera_calibrations(log, stamp_ns=T0 + 2 * PERIOD_NS)["/cam/image_raw"]
    assert first.info.k[0, 0] == 40.0
    assert (later.stamp_ns, later.info.k[0, 0]) == (T0 + 2 * PERIOD_NS, 80.0)
    np.testing.assert_allclose(later.base_from_optical, first.base_from_optical)


def test_missing_transform_or_calibration_leaves_the_camera_out(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG, logger="redrive.assembly.calibration")
    no_optical = (_mount()[0],)  # base_link → cam_link only
    with open_log(_write_log(tmp_path / "a.mcap", transforms=no_optical)) as log:
        assert camera_calibrations(log, max_messages=500) == {}
    assert "no static transform base_link → 'cam_optical'" in caplog.text
    uncalibrated = CameraInfo(width=0, height=0, k=np.zeros((3, 3)))
    caplog.clear()
    with open_log(_write_log(tmp_path / "b.mcap", infos={"/cam/camera_info": uncalibrated})) as log:
        assert camera_calibrations(log) == {}
    assert "/cam/camera_info is not calibrated" in caplog.text
    # another base frame than base_link
    with open_log(_write_log(tmp_path / "c.mcap")) as log:
        cal = camera_calibrations(log, base_frame="cam_link")["/cam/image_raw"]
    np.testing.assert_allclose(cal.base_from_optical, BODY_FROM_OPTICAL, atol=1e-12)


def test_max_messages_bounds_the_search(tmp_path: Path) -> None:
    two = {"/cam/camera_info": _info(), "/cam2/camera_info": _info()}
    with open_log(_write_log(tmp_path / "cam.mcap", frames=30, tf_at=20, infos=two)) as log:
        counting = _Counting(log)
        # one camera info, then (alone) one tf_static message: no more
        assert camera_calibrations(counting, max_messages=1) == {}  # type: ignore[arg-type]
        assert counting.read <= 3
        assert set(camera_calibrations(log)) == {"/cam/image_raw", "/cam2/image_raw"}


@pytest.mark.shared_data
def test_kitti_ground_truth_projects_into_its_2d_boxes(kitti_dir: Path) -> None:
    """The KITTI reader's camera infos (P2) and tf chain (base_link ≡ velodyne → cam2) give
    ``P2 · R0_rect · Tr_velo_to_cam``: every labelled box centre lands in its own 2D box."""
    with open_log(kitti_dir) as log:
        assert log.format == "kitti"
        labels = {
            m.log_time_ns: m.payload.value  # type: ignore[union-attr]
            for m in log.messages(topics=["/kitti/label_2"])
        }
        checked = 0
        for index, stamp_ns in enumerate(sorted(labels)):
            cal = camera_calibrations(log, stamp_ns=stamp_ns)["/kitti/image_2"]
            assert (cal.info_topic, cal.frame_id, cal.stamp_ns) == (
                "/kitti/camera_info",
                "cam2",
                stamp_ns,
            )
            assert (cal.info.width, cal.info.height) == ((1224, 370) if index == 0 else (1242, 375))
            reference = log.calibration(index).image_from_velodyne(2)  # type: ignore[attr-defined]
            np.testing.assert_allclose(cal.image_from_base(), reference, rtol=0, atol=1e-3)
            for obj in labels[stamp_ns]:
                uv, depth = project_points(cal.image_from_base(), obj.box.center.reshape(1, 3))
                left, top, width, height = obj.bbox_2d
                assert depth[0] > 0
                assert left < uv[0, 0] < left + width, (index, obj.object_class)
                assert top < uv[0, 1] < top + height, (index, obj.object_class)
                checked += 1
        assert checked == 6  # 1 pedestrian; truck, car, cyclist; misc, car
        # without a stamp: the first frame's calibration (it differs from the next frames')
        first = camera_calibrations(log)["/kitti/image_2"]
        assert first.stamp_ns == 0
        assert first.info.k[0, 0] == pytest.approx(707.0493)
