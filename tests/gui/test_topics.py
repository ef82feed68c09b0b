"""The Topic Picker against a real log (the synthetic writer's MCAP) and a real ROS 1 master."""

from __future__ import annotations

import pytest

pytest.importorskip("PySide6")

import socket
import time
from collections.abc import Iterator
from pathlib import Path

from PySide6 import QtCore, QtWidgets
from pytestqt.qtbot import QtBot

from redrive.gui.topics import (
    DECODABLE_COLOR,
    UNDECODABLE_COLOR,
    TopicPicker,
    ros_status,
    rospy_problem,
)
from redrive.io import open_log
from redrive.io.mcap.writer import McapWriter
from tests.live.conftest import RosCore, dead_master_uri, roscore  # noqa: F401  (fixtures)

LEFT = QtCore.Qt.MouseButton.LeftButton
CTRL = QtCore.Qt.KeyboardModifier.ControlModifier
NO_MOD = QtCore.Qt.KeyboardModifier.NoModifier


def _picker_for(path: Path, qtbot: QtBot) -> TopicPicker:
    with open_log(path) as log:
        picker = TopicPicker.for_log(
            log.topics, duration_s=(log.end_ns - log.start_ns) / 1e9, source=path.name
        )
    qtbot.addWidget(picker)
    picker.show()
    qtbot.waitExposed(picker)
    return picker


def _click(
    qtbot: QtBot,
    picker: TopicPicker,
    topic: str,
    *,
    modifier: QtCore.Qt.KeyboardModifier = NO_MOD,
    double: bool = False,
) -> None:
    item = picker.item(topic)
    assert item is not None, topic
    widget = item.listWidget()
    widget.scrollToItem(item)
    center = widget.visualItemRect(item).center()
    if double:  # as a real double-click: press and release, then the double-click event
        qtbot.mouseClick(widget.viewport(), LEFT, modifier, center)
        qtbot.mouseDClick(widget.viewport(), LEFT, modifier, center)
    else:
        qtbot.mouseClick(widget.viewport(), LEFT, modifier, center)


def _assert_decodable(picker: TopicPicker, topic: str, *, decodable: bool) -> None:
    item = picker.item(topic)
    assert item is not None, topic
    assert item.font().bold() is decodable
    color = DECODABLE_COLOR if decodable else UNDECODABLE_COLOR
    assert item.foreground().color() == color


@pytest.fixture(scope="module")
def mixed_log(demo_log: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The demo log's lidar and IMU topics plus a std_msgs/String topic redrive does not decode."""
    out = tmp_path_factory.mktemp("picker") / "mixed.mcap"
    with open_log(demo_log) as log, McapWriter(out) as writer:
        for message in log.messages(topics=["/lidar_top", "/imu"]):
            writer.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
        string_type = writer.typestore.types["std_msgs/msg/String"]
        for i in range(5):
            raw = writer.typestore.serialize_cdr(string_type(data=f"hi {i}"), "std_msgs/msg/String")
            writer.write_raw("/chatter", "std_msgs/msg/String", log.start_ns + i * 10**9, raw)
    return out


# --- a log --------------------------------------------------------------------------------------


def test_lists_the_log_topics_highlighted(qtbot: QtBot, demo_log: Path) -> None:
    picker = _picker_for(demo_log, qtbot)
    with open_log(demo_log) as log:
        names = sorted(log.topics)
        lidar = log.topics["/lidar_top"]
    assert picker.available_topics() == names
    assert picker.shown_topics() == []
    assert picker.chosen_topics() == []
    assert picker.available_list.count() == len(names)
    for name in names:  # every topic the synthetic writer records has a decoder
        _assert_decodable(picker, name, decodable=True)
    item = picker.item("/lidar_top")
    assert item is not None
    assert "sensor_msgs/msg/PointCloud2" in item.text()
    assert f"{lidar.count} msgs" in item.text()
    assert "10.0 Hz" in item.text()
    assert "redrive decodes it" in item.toolTip()
    assert (
        picker.status_label.text()
        == f"{demo_log.name}: {len(names)} topics, {len(names)} decodable"
    )
    assert not picker.run_button.isEnabled()  # nothing shown yet
    assert not picker.refresh_button.isVisible()  # a log is not refreshed


def test_undecodable_topic_is_greyed_with_the_reason(qtbot: QtBot, mixed_log: Path) -> None:
    picker = _picker_for(mixed_log, qtbot)
    assert picker.available_topics() == ["/chatter", "/imu", "/lidar_top"]
    _assert_decodable(picker, "/chatter", decodable=False)
    _assert_decodable(picker, "/imu", decodable=True)
    _assert_decodable(picker, "/lidar_top", decodable=True)
    chatter = picker.item("/chatter")
    assert chatter is not None
    assert "no decoder for std_msgs/msg/String" in chatter.toolTip()
    assert picker.status_label.text() == "mixed.mcap: 3 topics, 2 decodable"


def test_add_remove_clear_and_double_click(qtbot: QtBot, demo_log: Path) -> None:
    picker = _picker_for(demo_log, qtbot)
    everything = picker.available_topics()
    # multi-selection: click, ctrl-click, Add
    _click(qtbot, picker, "/lidar_top")
    _click(qtbot, picker, "/imu", modifier=CTRL)
    assert {
        i.data(QtCore.Qt.ItemDataRole.UserRole) for i in picker.available_list.selectedItems()
    } == {
        "/lidar_top",
        "/imu",
    }
    qtbot.mouseClick(picker.add_button, LEFT)
    assert set(picker.shown_topics()) == {"/lidar_top", "/imu"}
    assert picker.shown_list.count() == 2
    assert "/lidar_top" not in picker.available_topics()
    assert picker.available_list.count() == len(everything) - 2
    _assert_decodable(picker, "/lidar_top", decodable=True)  # still highlighted on the right
    assert picker.run_button.isEnabled()

    # double-click moves across, both ways
    _click(qtbot, picker, "/odom", double=True)
    assert picker.shown_topics()[-1] == "/odom"
    _click(qtbot, picker, "/imu", double=True)
    assert set(picker.shown_topics()) == {"/lidar_top", "/odom"}
    assert "/imu" in picker.available_topics()

    # Remove the selected one
    _click(qtbot, picker, "/odom")
    qtbot.mouseClick(picker.remove_button, LEFT)
    assert picker.shown_topics() == ["/lidar_top"]

    # Clear Topics: everything back, in the original order
    _click(qtbot, picker, "/gnss", double=True)
    qtbot.mouseClick(picker.clear_button, LEFT)
    assert picker.shown_topics() == []
    assert picker.shown_list.count() == 0
    assert picker.available_topics() == everything
    assert not picker.run_button.isEnabled()


def test_run_emits_exactly_the_shown_topics(qtbot: QtBot, demo_log: Path) -> None:
    picker = _picker_for(demo_log, qtbot)
    for topic in ("/lidar_top", "/camera_front/image_raw", "/odom"):
        _click(qtbot, picker, topic, double=True)
    with qtbot.waitSignal(picker.topics_chosen, timeout=2000) as blocker:
        qtbot.mouseClick(picker.run_button, LEFT)
    assert blocker.args == [["/lidar_top", "/camera_front/image_raw", "/odom"]]
    assert picker.chosen_topics() == ["/lidar_top", "/camera_front/image_raw", "/odom"]
    assert picker.result() == QtWidgets.QDialog.DialogCode.Accepted
    assert not picker.isVisible()


def test_run_all_gives_every_decodable_topic(qtbot: QtBot, mixed_log: Path) -> None:
    picker = _picker_for(mixed_log, qtbot)
    _click(qtbot, picker, "/chatter", double=True)  # shown, but not decodable
    with qtbot.waitSignal(picker.topics_chosen, timeout=2000) as blocker:
        qtbot.mouseClick(picker.run_all_button, LEFT)
    assert blocker.args == [["/imu", "/lidar_top"]]
    assert picker.chosen_topics() == ["/imu", "/lidar_top"]
    assert picker.result() == QtWidgets.QDialog.DialogCode.Accepted


def test_cancel_chooses_nothing(qtbot: QtBot, demo_log: Path) -> None:
    picker = _picker_for(demo_log, qtbot)
    _click(qtbot, picker, "/imu", double=True)
    with qtbot.assertNotEmitted(picker.topics_chosen):
        qtbot.mouseClick(picker.cancel_button, LEFT)
    assert picker.result() == QtWidgets.QDialog.DialogCode.Rejected
    assert picker.chosen_topics() == []


# --- a live ROS 1 master --------------------------------------------------------------------------

#: A rospy node publishing a PointCloud2 (decodable) and a std_msgs/String (not) at 10 Hz.
PUBLISHER = """
import sys
import rospy
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import String

ns = sys.argv[1]
rospy.init_node("picker_sensors")
cloud_pub = rospy.Publisher(ns + "/points", PointCloud2, queue_size=1)
text_pub = rospy.Publisher(ns + "/chatter", String, queue_size=1)
cloud = PointCloud2(
    height=1, width=2, is_bigendian=False, point_step=12, row_step=24, is_dense=True,
    data=bytes(24),
    fields=[PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
            for i, n in enumerate("xyz")],
)
print("READY", flush=True)
rate = rospy.Rate(10)
try:
    while not rospy.is_shutdown():
        cloud.header.stamp = rospy.Time.now()
        cloud_pub.publish(cloud)
        text_pub.publish(String(data="hello"))
        rate.sleep()
except rospy.ROSInterruptException:
    pass
"""
NS = "/picker_test"


@pytest.fixture(scope="module")
def publisher(roscore: RosCore) -> Iterator[RosCore]:  # noqa: F811
    with roscore.python_process(PUBLISHER, NS):
        yield roscore


def _open_master(qtbot: QtBot, uri: str, **kwargs: float) -> TopicPicker:
    start = time.monotonic()
    picker = TopicPicker.for_master(uri, **kwargs)
    assert time.monotonic() - start < 0.5  # the master is asked in a worker thread
    qtbot.addWidget(picker)
    picker.show()
    qtbot.waitExposed(picker)
    return picker


def test_live_master_topics(qtbot: QtBot, publisher: RosCore) -> None:
    picker = _open_master(qtbot, publisher.uri)
    points, chatter = f"{NS}/points", f"{NS}/chatter"

    def listed() -> None:
        # rospy registers asynchronously: Refresh until both topics are there
        if not {points, chatter} <= set(picker.available_topics()) and (
            picker.refresh_button.isEnabled()
        ):
            qtbot.mouseClick(picker.refresh_button, LEFT)
        assert {points, chatter} <= set(picker.available_topics())

    qtbot.waitUntil(listed, timeout=10_000)
    _assert_decodable(picker, points, decodable=True)
    _assert_decodable(picker, chatter, decodable=False)
    item, grey = picker.item(points), picker.item(chatter)
    assert item is not None
    assert grey is not None
    assert "sensor_msgs/PointCloud2" in item.text()
    assert "1 publisher" in item.text()
    assert "no decoder for std_msgs/String" in grey.toolTip()
    assert picker.status_label.text().startswith(f"master at {publisher.uri}: ")
    assert picker.refresh_button.isVisible()
    assert picker.refresh_button.isEnabled()

    # shown topics survive a refresh
    _click(qtbot, picker, points, double=True)
    qtbot.mouseClick(picker.refresh_button, LEFT)
    qtbot.waitUntil(picker.refresh_button.isEnabled, timeout=5000)
    assert picker.shown_topics() == [points]
    with qtbot.waitSignal(picker.topics_chosen, timeout=2000) as blocker:
        qtbot.mouseClick(picker.run_all_button, LEFT)
    assert points in blocker.args[0]
    assert chatter not in blocker.args[0]


def test_dead_master_says_not_reachable(qtbot: QtBot, dead_master_uri: str) -> None:  # noqa: F811
    picker = _open_master(qtbot, dead_master_uri)
    expected = f"master at {dead_master_uri} not reachable"
    qtbot.waitUntil(lambda: picker.status_label.text() == expected, timeout=5000)
    assert "connection refused" in picker.status_label.toolTip()
    assert picker.available_topics() == []
    assert picker.refresh_button.isEnabled()
    qtbot.mouseClick(picker.refresh_button, LEFT)
    assert "asking the ROS master" in picker.status_label.text()
    qtbot.waitUntil(lambda: picker.status_label.text() == expected, timeout=5000)


def test_a_hanging_master_does_not_freeze_the_dialog(qtbot: QtBot) -> None:
    with socket.socket() as server:  # listens, never accepts: the XML-RPC call hangs
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        uri = f"http://127.0.0.1:{server.getsockname()[1]}"
        picker = _open_master(qtbot, uri, timeout_s=1.5)
        assert "asking the ROS master" in picker.status_label.text()
        # the event loop runs while the worker waits: a timer fires
        with qtbot.waitSignal(picker.windowTitleChanged, timeout=500):
            QtCore.QTimer.singleShot(50, lambda: picker.setWindowTitle("still alive"))
        qtbot.waitUntil(
            lambda: picker.status_label.text() == f"master at {uri} not reachable", timeout=5000
        )
        assert "did not answer" in picker.status_label.toolTip()


# --- ros_status -----------------------------------------------------------------------------------


def test_ros_status(roscore: RosCore, dead_master_uri: str) -> None:  # noqa: F811
    up = ros_status(roscore.uri).splitlines()
    assert up[0] == f"ROS master at {roscore.uri}: reachable"
    assert rospy_problem() is None  # the roscore fixture skips when rospy is missing
    assert up[1] == "rospy: available under /usr/bin/python3"
    down = ros_status(dead_master_uri, timeout_s=0.5).splitlines()
    assert down[0] == f"ROS master at {dead_master_uri}: not reachable"
    assert ros_status("localhost:11311").startswith("ROS master: ROS master URI")
