"""open_log on every log in ../shared/data, time/topic filters, and bad input."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import LogError, LogTruncatedError
from redrive.io import LogReader, detect_format, open_log
from redrive.io.ros.decoders import decode
from redrive.types import PointCloud

# (relative path, format, {topic: count}) — counts from ../shared/data/README.md
LOGS = [
    ("ouster/512x10_raw.bag", "ros1",
     {"/os_node0/lidar_packets": 32, "/os_node0/imu_packets": 10, "/os_node0/metadata": 1}),
    ("rosbag1_real/embag_luminar_test.bag", "ros1",
     {"/luminar_pointcloud": 5, "/base_scan": 5, "/base_pose_ground_truth": 5}),
    ("rosbag1_real/robot_localization_test1_husky.bag", "ros1",
     {"/imu/data": 11865, "/husky_velocity_controller/odom": 3952, "/fix": 989}),
    ("rosbag1_real/robot_localization_test2_jackal.bag", "ros1",
     {"/imu/data": 3061, "/jackal_velocity_controller/odom": 3060}),
    ("rosbag1_recorded_here/kitti_3frames_rosbag_record_lz4.bag", "ros1",
     {"/kitti/velo/pointcloud": 3, "/kitti/camera_color_left/image_raw": 3,
      "/kitti/camera_color_left/image_raw/compressed": 3}),
    ("rosbag_fixtures/rosbagjs_turtlesim_bz2.bag", "ros1", {"/tf_static": 1}),
    ("rosbag_fixtures/rosbagjs_turtlesim_lz4.bag", "ros1", {"/tf_static": 1}),
    ("rosbag_fixtures/evo_tf_example.bag", "ros1", {"/tf": 517, "/tf_static": 1}),
    ("rosbag_fixtures/evo_tf_example_ros2", "ros2", {"/tf": 517, "/tf_static": 1}),
    ("rosbag_fixtures/evo_nav2_turtlebot_sim.mcap", "mcap",
     {"/odom": 2639, "/tf": 5422, "/tf_static": 1, "/amcl_pose": 135}),
    ("trajectories/evo_ROS_example_poses.bag", "ros1",
     {"groundtruth": 12765, "ORB-SLAM": 8362, "S-PTAM": 5439}),
    ("velodyne_nebula_ros2/vlp16/1673400471837873222", "ros2", {"/velodyne_packets": 4}),
    ("velodyne_nebula_ros2/vlp32/1713492677464078412", "ros2",
     {"/sensing/lidar/front/velodyne_packets": 5}),
]  # fmt: skip


@pytest.mark.parametrize(("rel", "fmt", "counts"), LOGS, ids=[r for r, _, _ in LOGS])
def test_every_shared_log_opens_with_the_right_counts(
    shared_data: Path, rel: str, fmt: str, counts: dict[str, int]
) -> None:
    with open_log(shared_data / rel, packets="raw") as log:  # the file's own messages
        assert isinstance(log, LogReader)
        assert log.format == fmt
        for topic, count in counts.items():
            assert log.topics[topic].count == count
        seen: dict[str, int] = {}
        last = 0
        for message in log.messages():
            seen[message.topic] = seen.get(message.topic, 0) + 1
            assert message.log_time_ns >= last, "messages must come in log-time order"
            last = message.log_time_ns
            assert log.start_ns <= message.log_time_ns <= log.end_ns
        assert seen == {t: i.count for t, i in log.topics.items()}
        assert sum(seen.values()) == log.message_count


def test_every_typed_message_deserialises(shared_data: Path) -> None:
    """rosbags deserialises each message through redrive's typestores (embedded or shipped)."""
    for rel, _, _ in LOGS:
        with open_log(shared_data / rel, packets="raw") as log:  # the file's own messages
            for message in log.messages():
                assert log.topics[message.topic].has_definition, (rel, message.topic)
                assert log.deserialize(message) is not None


def test_topic_and_time_filters_seek(shared_data: Path) -> None:
    path = shared_data / "rosbag1_real/robot_localization_test1_husky.bag"
    with open_log(path) as log:
        all_fix = [m.log_time_ns for m in log.messages(topics=["/fix"])]
        assert len(all_fix) == 989
        start, stop = all_fix[100], all_fix[200]
        got = list(log.messages(topics=["/fix", "/imu/data"], start_ns=start, stop_ns=stop))
        assert {m.topic for m in got} == {"/fix", "/imu/data"}
        assert all(start <= m.log_time_ns < stop for m in got)
        assert sum(m.topic == "/fix" for m in got) == 100
        # random access: the first message at or after a time, read without scanning from 0
        first = next(iter(log.messages(start_ns=start)))
        assert first.log_time_ns >= start


@pytest.mark.parametrize(("rel", "fmt", "counts"), LOGS, ids=[r for r, _, _ in LOGS])
def test_a_topic_the_log_lacks_yields_nothing(
    shared_data: Path, rel: str, fmt: str, counts: dict[str, int]
) -> None:
    # issue 35: the real ROS 1 bags have no /tf_static; asking for it raised IndexError from
    # the bag reader's empty merged index (and the GUI could not open them)
    with open_log(shared_data / rel, packets="raw") as log:  # the file's own messages
        assert list(log.messages(topics=["/no/such/topic"])) == []
        first = next(iter(counts))
        assert len(list(log.messages(topics=["/no/such/topic", first]))) == counts[first]
        # a span past the end, and one before the start
        assert list(log.messages(topics=[first], start_ns=log.end_ns + 1)) == []
        assert list(log.messages(topics=[first], stop_ns=log.start_ns)) == []


def test_mcap_and_ros2_time_filters(shared_data: Path) -> None:
    for rel in (
        "rosbag_fixtures/evo_nav2_turtlebot_sim.mcap",
        "rosbag_fixtures/evo_tf_example_ros2",
    ):
        with open_log(shared_data / rel, packets="raw") as log:  # the file's own messages
            mid = (log.start_ns + log.end_ns) // 2
            after = list(log.messages(start_ns=mid))
            before = list(log.messages(stop_ns=mid))
            assert len(after) + len(before) == log.message_count
            assert all(m.log_time_ns >= mid for m in after)


def test_luminar_cloud_decodes_from_the_real_bag(shared_data: Path) -> None:
    with open_log(shared_data / "rosbag1_real/embag_luminar_test.bag") as log:
        clouds = [
            decode(m, log.deserialize).value for m in log.messages(topics=["/luminar_pointcloud"])
        ]
    assert len(clouds) == 5
    assert all(isinstance(c, PointCloud) for c in clouds)
    sizes = [c.num_points for c in clouds if isinstance(c, PointCloud)]
    assert all(35_000 < n < 37_000 for n in sizes)  # "about 35.7k pts each"
    first = clouds[0]
    assert isinstance(first, PointCloud)
    assert first.channels["laser_id"].dtype == np.uint16
    assert float(np.nanmax(np.abs(first.xyz[:, 0]))) <= 200.5  # "x spans ±200 m"


def test_detect_format_by_content_not_suffix(shared_data: Path, tmp_path: Path) -> None:
    renamed = tmp_path / "drive.data"
    renamed.write_bytes((shared_data / "rosbag1_real/embag_luminar_test.bag").read_bytes())
    assert detect_format(renamed) == "ros1"
    assert detect_format(shared_data / "kitti_object") == "kitti"
    assert detect_format(shared_data / "kitti_object/training") == "kitti"


# -- bad input ----------------------------------------------------------------------------------


def test_empty_file(tmp_path: Path) -> None:
    for name in ("empty.bag", "empty.mcap", "empty"):
        (tmp_path / name).write_bytes(b"")
        with pytest.raises(LogError, match="empty"):
            open_log(tmp_path / name)


def test_not_a_log(tmp_path: Path) -> None:
    (tmp_path / "notes.bag").write_text("just text\n")
    with pytest.raises(LogError, match=r"notes\.bag.*not a log"):
        open_log(tmp_path / "notes.bag")
    with pytest.raises(LogError, match="no such file"):
        open_log(tmp_path / "missing.bag")


def test_directory_that_is_not_a_log(tmp_path: Path) -> None:
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "a.jpg").write_bytes(b"\xff\xd8")
    with pytest.raises(LogError, match=r"photos.*not a log.*metadata\.yaml"):
        open_log(tmp_path / "photos")
    (tmp_path / "bag2").mkdir()
    (tmp_path / "bag2" / "bag2_0.db3").write_bytes(b"SQLite format 3\x00")
    with pytest.raises(LogError, match=r"bag2_0\.db3 but no metadata\.yaml"):
        open_log(tmp_path / "bag2")


@pytest.mark.parametrize(
    "rel",
    [
        "rosbag1_real/robot_localization_test1_husky.bag",  # bz2 chunks
        "rosbag_fixtures/rosbagjs_turtlesim_lz4.bag",  # lz4, one big chunk
        "rosbag1_recorded_here/kitti_3frames_rosbag_record_lz4.bag",
    ],
)
def test_truncated_bag_yields_every_message_before_the_damage(
    shared_data: Path, tmp_path: Path, rel: str, caplog: pytest.LogCaptureFixture
) -> None:
    src = shared_data / rel
    with open_log(src) as log:
        full = [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages()]
    data = src.read_bytes()
    cut = tmp_path / "cut.bag"
    for fraction in (0.5, 0.9):
        cut.write_bytes(data[: int(len(data) * fraction)])
        with caplog.at_level(logging.WARNING), open_log(cut) as log:
            assert "index" in caplog.text
            got = []
            with pytest.raises(LogTruncatedError, match=r"cut\.bag.*cut off") as info:
                got.extend((m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages())
            assert info.value.messages_read == len(got)
        # What was read are the log's own messages, byte for byte.
        assert set(got) <= set(full)
        with open_log(cut, strict=False) as log:
            salvaged = [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages()]
        assert salvaged == got


def test_truncated_uncompressed_bag_loses_only_the_cut_message(tmp_path: Path) -> None:
    from redrive.testing.demo_log import write_demo_bag

    bag = write_demo_bag(tmp_path / "demo.bag", duration_s=1.0)
    with open_log(bag) as log:
        full = [(m.topic, m.log_time_ns) for m in log.messages()]
    data = bag.read_bytes()
    (tmp_path / "cut.bag").write_bytes(data[: len(data) // 2])
    with open_log(tmp_path / "cut.bag", strict=False) as log:
        got = [(m.topic, m.log_time_ns) for m in log.messages()]
    # Uncompressed chunks are read record by record up to the cut: nothing but the cut message
    # and what follows it is lost.
    assert set(got) <= set(full)  # the log's own messages (in file order, not time order)
    assert 0.3 * len(full) < len(got) < len(full)


def test_corrupted_chunk(shared_data: Path, tmp_path: Path) -> None:
    src = shared_data / "rosbag1_real/robot_localization_test1_husky.bag"
    data = bytearray(src.read_bytes())
    middle = len(data) // 3
    data[middle : middle + 200] = bytes(200)
    bad = tmp_path / "corrupt.bag"
    bad.write_bytes(bytes(data))
    with open_log(bad) as log:
        got: list[str] = []
        with pytest.raises(
            LogError, match=r"corrupt\.bag: damaged at bytes \d+–\d+: the chunk is damaged"
        ):
            got.extend(m.topic for m in log.messages())
        count = len(got)
        assert 0 < count < 16806
    with open_log(bad, strict=False) as log:
        rest = sum(1 for _ in log.messages())
    assert count < rest < 16806  # the damaged chunk is skipped, the rest is read


def test_truncated_mcap_is_reported(shared_data: Path, tmp_path: Path) -> None:
    data = (shared_data / "rosbag_fixtures/evo_nav2_turtlebot_sim.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with open_log(cut) as log, pytest.raises(LogTruncatedError, match=r"cut\.mcap"):
        for _ in log.messages():
            pass
