"""KittiReader on the real KITTI object frames in ../shared/data and on broken folders."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import LogError, UnsupportedMessageError
from redrive.geometry.boxes import points_in_box, transform_box
from redrive.geometry.projection import project_points
from redrive.geometry.se3 import compose, matrix_from_transform, transform_points
from redrive.io.base import LogReader
from redrive.io.datasets.kitti import (
    TOPIC_CAMERA_INFO,
    TOPIC_IMAGE_2,
    TOPIC_LABEL_2,
    TOPIC_TF_STATIC,
    TOPIC_VELODYNE,
    KittiReader,
)
from redrive.io.ros.decoders import DecodedKind, decoder_for, topic_kind
from redrive.io.ros.decoders.base import Decoded
from redrive.types import DetectedObject, Image, ObjectClass, PointCloud, SensorType, Transform

pytestmark = pytest.mark.shared_data


@pytest.fixture(scope="module")
def frames(kitti_dir: Path) -> dict[tuple[str, int], Decoded]:
    """(topic, stamp_ns) → payload of every message."""
    with KittiReader(kitti_dir) as reader:
        out = {}
        for message in reader.messages():
            assert message.encoding == "native"
            assert message.raw == b""
            assert isinstance(message.payload, Decoded)
            out[(message.topic, message.log_time_ns)] = message.payload
        return out


def _value(frames: dict[tuple[str, int], Decoded], topic: str, index: int) -> object:
    return frames[(topic, index * 100_000_000)].value


def test_summary(kitti_dir: Path) -> None:
    for path in (kitti_dir, kitti_dir / "training"):
        with KittiReader(path) as reader:
            assert isinstance(reader, LogReader)
            assert reader.format == "kitti"
            assert reader.frame_names == ("000000", "000001", "000002")
            assert set(reader.topics) == {
                TOPIC_TF_STATIC,
                TOPIC_VELODYNE,
                TOPIC_IMAGE_2,
                TOPIC_CAMERA_INFO,
                TOPIC_LABEL_2,
            }
            # native values, not ROS messages: the types name what they hold, and the reader
            # says how each topic is used (no decoder is asked)
            assert reader.topics[TOPIC_LABEL_2].msgtype == "redrive/GroundTruthObjects"
            assert reader.topics[TOPIC_CAMERA_INFO].msgtype == "redrive/CameraInfo"
            assert topic_kind(reader.topics[TOPIC_VELODYNE]) == (
                DecodedKind.SENSOR,
                SensorType.LIDAR,
            )
            assert topic_kind(reader.topics[TOPIC_LABEL_2]) == (DecodedKind.OBJECTS, None)
            assert all(decoder_for(t.msgtype) is None for t in reader.topics.values())
            caps = reader.capabilities
            assert (caps.message_typed, caps.calibration_per_frame) == (False, True)
            assert (caps.has_tf, caps.has_ground_truth, caps.has_ego_pose) == (True, True, False)
            assert all(t.count == 3 and t.encoding == "native" for t in reader.topics.values())
            assert (reader.start_ns, reader.end_ns, reader.message_count) == (0, 200_000_000, 15)


def test_point_clouds(frames: dict[tuple[str, int], Decoded]) -> None:
    for index, count in enumerate((115_384, 120_268, 126_891)):
        cloud = _value(frames, TOPIC_VELODYNE, index)
        assert isinstance(cloud, PointCloud)
        assert cloud.num_points == count
        assert cloud.xyz.dtype == np.float32
        assert cloud.xyz.flags.c_contiguous
        assert set(cloud.channels) == {"intensity"}
        assert (
            0.0
            <= float(cloud.channels["intensity"].min())
            <= float(cloud.channels["intensity"].max())
            <= 1.0
        )
        assert frames[(TOPIC_VELODYNE, index * 100_000_000)].frame_id == "velodyne"


def test_images(frames: dict[tuple[str, int], Decoded]) -> None:
    sizes = [(1224, 370), (1242, 375), (1242, 375)]
    for index, (width, height) in enumerate(sizes):
        image = _value(frames, TOPIC_IMAGE_2, index)
        assert isinstance(image, Image)
        assert (image.width, image.height, image.encoding) == (width, height, "rgb8")
        assert image.pixels.shape == (height, width, 3)


def _labels(frames: dict[tuple[str, int], Decoded], index: int) -> tuple[DetectedObject, ...]:
    value = _value(frames, TOPIC_LABEL_2, index)
    assert isinstance(value, tuple)
    return value


def test_label_classes_and_fields(frames: dict[tuple[str, int], Decoded]) -> None:
    classes = [[o.object_class for o in _labels(frames, i)] for i in range(3)]
    assert classes == [
        [ObjectClass.PEDESTRIAN],
        [ObjectClass.TRUCK, ObjectClass.VEHICLE, ObjectClass.BICYCLE],
        [ObjectClass.OTHER, ObjectClass.VEHICLE],
    ]
    ped = _labels(frames, 0)[0]
    # Pedestrian 0.00 0 -0.20 712.40 143.00 810.73 307.92 1.89 0.48 1.20 1.84 1.47 8.41 0.01
    assert ped.object_id == 0
    assert ped.confidence == 1.0
    np.testing.assert_allclose(ped.box.size, [1.20, 0.48, 1.89])
    assert ped.bbox_2d == pytest.approx((712.40, 143.00, 810.73 - 712.40, 307.92 - 143.00))
    assert ped.box.yaw_rad == pytest.approx(-0.01 - math.pi / 2)
    # ~8.4 m ahead, 1.9 m to the right, centre at mid-height below the roof-mounted LiDAR
    np.testing.assert_allclose(ped.box.center, [8.74, -1.87, -0.65], atol=0.01)
    truck = _labels(frames, 1)[0]
    assert truck.box.center[0] == pytest.approx(69.7, abs=0.1)
    assert truck.box.yaw_rad == pytest.approx(1.56 - math.pi / 2)
    car = _labels(frames, 1)[1]
    assert abs(abs(car.box.yaw_rad) - math.pi) < 0.01  # rotation_y 1.57: facing backwards
    assert _labels(frames, 2)[1].object_id == 1


def test_boxes_hold_the_lidar_points(
    kitti_dir: Path, frames: dict[tuple[str, int], Decoded]
) -> None:
    expected = {0: [376], 1: [70, 9, 18]}  # counted with the devkit's box in camera coordinates
    with KittiReader(kitti_dir) as reader:
        for index, counts in expected.items():
            cloud = _value(frames, TOPIC_VELODYNE, index)
            assert isinstance(cloud, PointCloud)
            labels = _labels(frames, index)
            # In the velodyne frame the boxes are upright only to ~0.5°: nearly the same count.
            in_velo = [int(points_in_box(cloud.xyz, o.box).sum()) for o in labels]
            assert all(abs(a - b) <= 2 for a, b in zip(in_velo, counts, strict=True)), in_velo
            # In rectified cam0 (REP-103 axes) the KITTI boxes are exactly upright: exact counts.
            flu_from_velo = reader.calibration(index).rect_flu_from_velodyne
            pts = transform_points(flu_from_velo, cloud.xyz)
            exact = [
                int(points_in_box(pts, transform_box(flu_from_velo, o.box)).sum()) for o in labels
            ]
            assert exact == counts


def test_calibration_and_tf(kitti_dir: Path, frames: dict[tuple[str, int], Decoded]) -> None:
    with KittiReader(kitti_dir) as reader:
        calib = reader.calibration("000000")
        assert calib is reader.calibration(0)
        assert calib.velodyne_from_imu is not None
        cloud = _value(frames, TOPIC_VELODYNE, 0)
        assert isinstance(cloud, PointCloud)
        uv, depth = project_points(calib.image_from_velodyne(2), cloud.xyz)
        inside = (
            (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < 1224) & (uv[:, 1] >= 0) & (uv[:, 1] < 370)
        )
        assert 15_000 < int(inside.sum()) < 25_000  # README: about 20k points project in
        # the pedestrian's 3D box projects onto its 2D box
        ped = _labels(frames, 0)[0]
        assert ped.bbox_2d is not None
        uv_c, _ = project_points(calib.image_from_velodyne(2), ped.box.center.reshape(1, 3))
        left, top, width, height = ped.bbox_2d
        assert left < uv_c[0, 0] < left + width
        assert top < uv_c[0, 1] < top + height
    tfs = _value(frames, TOPIC_TF_STATIC, 0)
    assert isinstance(tfs, tuple)
    assert all(isinstance(t, Transform) for t in tfs)
    by_child = {t.child_frame: t for t in tfs if isinstance(t, Transform)}
    assert set(by_child) == {"velodyne", "imu", "cam0", "cam0_rect", "cam1", "cam2", "cam3"}
    # KITTI's vehicle frame is the velodyne's: base_link → velodyne is the identity
    assert by_child["velodyne"].parent_frame == "base_link"
    np.testing.assert_array_equal(matrix_from_transform(by_child["velodyne"]), np.eye(4))
    # the tf chain velodyne → cam0 → cam0_rect agrees with R0_rect @ Tr_velo_to_cam
    velo_from_rect = compose(
        matrix_from_transform(by_child["cam0"]), matrix_from_transform(by_child["cam0_rect"])
    )
    np.testing.assert_allclose(velo_from_rect, calib.velodyne_from_rect, atol=1e-5)
    # cam2 sits ~6 cm to the left of cam0: P2 = K [I | t], t = K⁻¹ p4 = (0.0605, -0.0018, 0.0050)
    np.testing.assert_allclose(by_child["cam2"].translation, [-0.0605, 0.0018, -0.0050], atol=1e-4)


def test_time_and_topic_filters(kitti_dir: Path) -> None:
    with KittiReader(kitti_dir) as reader:
        got = [
            (m.topic, m.log_time_ns)
            for m in reader.messages(
                topics=[TOPIC_LABEL_2, TOPIC_VELODYNE], start_ns=1, stop_ns=200_000_000
            )
        ]
        assert got == [(TOPIC_VELODYNE, 100_000_000), (TOPIC_LABEL_2, 100_000_000)]
        message = next(reader.messages(topics=[TOPIC_TF_STATIC]))
        with pytest.raises(UnsupportedMessageError, match="native"):
            reader.deserialize(message)


# -- broken folders ------------------------------------------------------------------------------


@pytest.fixture
def small_kitti(kitti_dir: Path, tmp_path: Path) -> Path:
    """A copy of frames 000000 and 000001 (lidar shortened to 100 points) under tmp/training."""
    root = tmp_path / "kitti" / "training"
    for sub, suffix in (
        ("calib", ".txt"),
        ("image_2", ".png"),
        ("label_2", ".txt"),
        ("velodyne", ".bin"),
    ):
        (root / sub).mkdir(parents=True)
        for stem in ("000000", "000001"):
            src = kitti_dir / "training" / sub / f"{stem}{suffix}"
            dst = root / sub / f"{stem}{suffix}"
            if sub == "velodyne":
                dst.write_bytes(src.read_bytes()[: 16 * 100])
            else:
                shutil.copyfile(src, dst)
    return tmp_path / "kitti"


def test_small_copy_reads(small_kitti: Path) -> None:
    with KittiReader(small_kitti) as reader:
        clouds = [m.payload for m in reader.messages(topics=[TOPIC_VELODYNE])]
    assert [
        c.value.num_points
        for c in clouds
        if isinstance(c, Decoded) and isinstance(c.value, PointCloud)
    ] == [100, 100]


def test_testing_split_without_labels(small_kitti: Path) -> None:
    shutil.rmtree(small_kitti / "training" / "label_2")
    (small_kitti / "training").rename(small_kitti / "testing")
    with KittiReader(small_kitti) as reader:
        assert TOPIC_LABEL_2 not in reader.topics
        assert reader.message_count == 8  # tf_static, velodyne, image_2, camera_info


def test_missing_calib(small_kitti: Path) -> None:
    (small_kitti / "training" / "calib" / "000001.txt").unlink()
    with pytest.raises(LogError, match=r"calib/000001\.txt"):
        KittiReader(small_kitti)


def test_missing_velodyne(small_kitti: Path) -> None:
    (small_kitti / "training" / "velodyne" / "000000.bin").unlink()
    with pytest.raises(LogError, match=r"no velodyne/000000\.bin"):
        KittiReader(small_kitti)


def test_bad_bin_size(small_kitti: Path) -> None:
    path = small_kitti / "training" / "velodyne" / "000001.bin"
    path.write_bytes(path.read_bytes()[:-3])
    with pytest.raises(LogError, match=r"000001\.bin: 1597 bytes is not a multiple of 16"):
        KittiReader(small_kitti)


def test_malformed_label_line(small_kitti: Path) -> None:
    path = small_kitti / "training" / "label_2" / "000001.txt"
    path.write_text(path.read_text() + "Car 0.00 0 1.85 387.63\n")
    with (
        KittiReader(small_kitti) as reader,
        pytest.raises(LogError, match=r"label_2/000001\.txt:8: a KITTI label row has 15 fields"),
    ):
        list(reader.messages(topics=[TOPIC_LABEL_2]))
    path.write_text(
        "Car 0.00 0 1.85 387.63 181.54 423.81 203.12 1.67 1.87 x -16.53 2.39 58.49 1.57\n"
    )
    with KittiReader(small_kitti) as reader, pytest.raises(LogError, match="non-number"):
        list(reader.messages(topics=[TOPIC_LABEL_2], start_ns=100_000_000))


def test_malformed_calib_and_score_column(small_kitti: Path) -> None:
    label = small_kitti / "training" / "label_2" / "000000.txt"
    label.write_text(label.read_text().strip() + " 0.75\n")
    with KittiReader(small_kitti) as reader:
        objects = next(reader.messages(topics=[TOPIC_LABEL_2])).payload
        assert isinstance(objects, Decoded)
        assert isinstance(objects.value, tuple)
        assert [o.confidence for o in objects.value if isinstance(o, DetectedObject)] == [0.75]
    calib = small_kitti / "training" / "calib" / "000000.txt"
    calib.write_text(
        "\n".join(line for line in calib.read_text().splitlines() if not line.startswith("R0_rect"))
    )
    with KittiReader(small_kitti) as reader, pytest.raises(LogError, match="lacks R0_rect"):
        list(reader.messages())


def test_not_a_kitti_folder(tmp_path: Path) -> None:
    with pytest.raises(LogError, match="not a KITTI object folder"):
        KittiReader(tmp_path)
