"""The live view: a real ROS master and rospy publisher → scrapers → shared memory → the main
window's planview and camera; recording to MCAP; a dead master; the Live menu's dialogs."""

from __future__ import annotations

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyqtgraph")

import itertools
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from PySide6 import QtWidgets
from pytestqt.qtbot import QtBot

from redrive.gui import live
from redrive.gui.live import LiveFeed
from redrive.gui.mainwindow import MainWindow
from redrive.io import open_log
from redrive.io.ros.decoders import decode
from redrive.types import PointCloud
from tests.live.conftest import RosCore, dead_master_uri, roscore  # noqa: F401  (fixtures)

_WAIT_MS = 25_000
POINTS, IMAGE = "/gui/points", "/gui/image"

# A sensor rig at 10 Hz until stopped: a 5000-point cloud and a small rgb8 image, same stamps.
PUBLISHER = r"""
import numpy as np
import rospy
from sensor_msgs.msg import Image, PointCloud2, PointField

rospy.init_node("gui_rig", anonymous=True)
points = rospy.Publisher("/gui/points", PointCloud2, queue_size=10)
image = rospy.Publisher("/gui/image", Image, queue_size=10)
print("READY", flush=True)
rng = np.random.default_rng(0)
n = 5000
fields = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1)
          for i, c in enumerate(("x", "y", "z", "intensity"))]
rate = rospy.Rate(10)
while not rospy.is_shutdown():
    now = rospy.Time.now()
    xyz = np.c_[rng.uniform(-20, 20, (n, 2)), rng.normal(-1.7, 0.05, n)]
    pts = np.c_[xyz, rng.random(n)].astype(np.float32)
    cloud = PointCloud2(height=1, width=n, fields=fields, is_bigendian=False, point_step=16,
                        row_step=16 * n, is_dense=True, data=pts.tobytes())
    cloud.header.stamp = now; cloud.header.frame_id = "velodyne"
    img = Image(height=48, width=64, encoding="rgb8", is_bigendian=0, step=64 * 3,
                data=rng.integers(0, 256, 64 * 48 * 3, dtype=np.uint8).tobytes())
    img.header.stamp = now; img.header.frame_id = "camera"
    points.publish(cloud)
    image.publish(img)
    try:
        rate.sleep()
    except rospy.ROSInterruptException:
        break
"""


@pytest.fixture(scope="module")
def rig(roscore: RosCore) -> Iterator[RosCore]:  # noqa: F811
    with roscore.python_process(PUBLISHER):
        yield roscore


def _segments(feed: LiveFeed) -> list[Path]:
    return sorted(Path("/dev/shm").glob(f"redrive.{feed.session_name}.*"))


def _shown_indices(window: MainWindow) -> list[int]:
    shown: list[int] = []
    window.frame_shown.connect(shown.append)
    return shown


def test_live_feed_draws_records_and_cleans_up(
    qtbot: QtBot, window: MainWindow, rig: RosCore, tmp_path: Path
) -> None:
    out = tmp_path / "live.mcap"
    shown = _shown_indices(window)
    stats: list[dict[str, Any]] = []
    feed = LiveFeed(window, rig.uri, [POINTS, IMAGE], record=out)
    feed.stats.connect(stats.append)
    window.live_feed = feed
    feed.start()
    qtbot.waitUntil(lambda: len(shown) >= 5, timeout=_WAIT_MS)
    assert window.scene is not None
    assert window.scene.point_count == 5000
    assert window.planview.isEnabled()
    assert window.summary is not None
    assert window.summary.format == "live"
    assert window.summary.cameras  # the image topic is a camera
    qtbot.waitUntil(lambda: window.camera.scene is not None, timeout=5000)
    assert window.camera.scene is not None
    assert window.camera.scene.image.shape == (48, 64, 3)
    assert not window.timeline.play_button.isEnabled()  # no playback while live
    assert _segments(feed)

    # A GUI thread busy for a second: the frames meanwhile are dropped, never queued.
    skipped_before = feed.skipped
    time.sleep(1.0)
    qtbot.waitUntil(lambda: len(shown) >= 10, timeout=_WAIT_MS)
    assert feed.skipped >= skipped_before + 5
    assert all(b > a for a, b in itertools.pairwise(shown)), shown
    assert max(b - a for a, b in itertools.pairwise(shown)) >= 5, shown
    qtbot.waitUntil(lambda: bool(stats), timeout=3000)
    assert {"frames", "shown", "skipped", "received", "recorded"} <= set(stats[-1])

    t0 = time.perf_counter()
    window.disconnect_live()
    assert time.perf_counter() - t0 < 30.0  # returns (joins its threads), however loaded
    assert window.live_feed is None
    assert not feed.running
    assert _segments(feed) == []
    assert window.timeline.play_button.isEnabled()
    assert window.summary is None  # nothing to play back; the last live frame stays drawn
    assert feed.recorded_path == out
    with open_log(out) as log:
        assert log.topics[POINTS].count >= feed.frames >= len(shown)
        assert log.topics[IMAGE].count >= 1
        first = next(iter(log.messages(topics=[POINTS])))
        cloud = decode(first, log.deserialize).value
    assert isinstance(cloud, PointCloud)
    assert cloud.xyz.shape == (5000, 3)
    qtbot.waitUntil(lambda: "recorded" in window.logbox.text.toPlainText(), timeout=3000)
    assert str(out) in window.logbox.text.toPlainText()


def test_dead_master_fails_fast(
    qtbot: QtBot,
    window: MainWindow,
    dead_master_uri: str,  # noqa: F811
) -> None:
    feed = LiveFeed(window, dead_master_uri, [POINTS])
    t0 = time.perf_counter()
    with qtbot.waitSignal(feed.failed, timeout=5000) as failed:
        feed.start()
    assert time.perf_counter() - t0 < 5.0
    assert dead_master_uri in failed.args[0]
    assert "no ROS master" in failed.args[0]
    qtbot.waitUntil(lambda: "no ROS master" in window.logbox.text.toPlainText(), timeout=3000)
    qtbot.waitUntil(lambda: not feed.running, timeout=3000)
    feed.stop()
    assert window.timeline.play_button.isEnabled()  # usable again
    assert _segments(feed) == []


def test_live_menu_connect_then_record(
    qtbot: QtBot, window: MainWindow, rig: RosCore, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(
        QtWidgets.QInputDialog, "getText", staticmethod(lambda *a, **k: (rig.uri, True))
    )
    picker = live.connect_dialog(window)
    assert picker is not None
    qtbot.waitUntil(lambda: picker.item(POINTS) is not None, timeout=_WAIT_MS)
    qtbot.waitUntil(lambda: "reachable" in window.logbox.status.text(), timeout=_WAIT_MS)
    assert f"ROS master at {rig.uri}: reachable" in window.logbox.status.text()
    picker.show_topics([POINTS])
    picker.run()
    feed = window.live_feed
    assert isinstance(feed, LiveFeed)
    assert feed.record is None
    qtbot.waitUntil(lambda: feed.shown >= 2, timeout=_WAIT_MS)
    assert window.scene is not None
    assert window.scene.point_count == 5000

    out = tmp_path / "menu.mcap"
    monkeypatch.setattr(
        QtWidgets.QFileDialog,
        "getSaveFileName",
        staticmethod(lambda *a, **k: (str(out), "MCAP (*.mcap)")),
    )
    recording = live.record_dialog(window)
    assert recording is not None
    assert window.live_feed is recording
    assert recording.record == out
    assert not feed.running
    assert _segments(feed) == []
    qtbot.waitUntil(lambda: recording.shown >= 3, timeout=_WAIT_MS)
    window.disconnect_live()
    assert _segments(recording) == []
    with open_log(out) as log:
        assert log.topics[POINTS].count >= recording.frames
    qtbot.waitUntil(lambda: str(out) in window.logbox.text.toPlainText(), timeout=3000)

    # not live: Record remembers the file for the next connection
    again = tmp_path / "next.mcap"
    monkeypatch.setattr(
        QtWidgets.QFileDialog,
        "getSaveFileName",
        staticmethod(lambda *a, **k: (str(again), "MCAP (*.mcap)")),
    )
    assert live.record_dialog(window) is None
    second = live.connect_dialog(window)
    assert second is not None
    qtbot.waitUntil(lambda: second.item(POINTS) is not None, timeout=_WAIT_MS)
    second.show_topics([POINTS])
    second.run()
    last = window.live_feed
    assert isinstance(last, LiveFeed)
    assert last.record == again
    qtbot.waitUntil(lambda: last.shown >= 1, timeout=_WAIT_MS)
    window.disconnect_live()
    assert again.is_file()


def test_a_dead_scraper_fails_the_feed(qtbot: QtBot, window: MainWindow, rig: RosCore) -> None:
    feed = LiveFeed(window, rig.uri, [POINTS])
    window.live_feed = feed
    feed.start()
    qtbot.waitUntil(lambda: feed.shown >= 1, timeout=_WAIT_MS)
    session = feed._session
    assert session is not None
    with qtbot.waitSignal(feed.failed, timeout=5000) as failed:
        session.processes[0].kill()  # the scraper this feed started
    assert f"the scraper of {POINTS} exited" in failed.args[0]
    qtbot.waitUntil(lambda: window.live_feed is None, timeout=5000)  # it let go of the window
    assert window.timeline.play_button.isEnabled()
    assert _segments(feed) == []


def test_opening_a_log_ends_the_live_view(
    qtbot: QtBot, window: MainWindow, rig: RosCore, tmp_path: Path
) -> None:
    recorded = tmp_path / "rec.mcap"
    first = live.start_feed(window, rig.uri, [POINTS], record=recorded)
    qtbot.waitUntil(lambda: first.shown >= 3, timeout=_WAIT_MS)
    window.disconnect_live()
    feed = live.start_feed(window, rig.uri, [POINTS])
    qtbot.waitUntil(lambda: feed.shown >= 1, timeout=_WAIT_MS)
    with qtbot.waitSignal(window.frame_shown, timeout=_WAIT_MS, check_params_cb=lambda i: i == 0):
        window.open_log(recorded)  # the recording of a moment ago
    assert window.live_feed is None
    assert not feed.running
    assert window.summary is not None
    assert window.summary.path == recorded
    assert window.summary.format == "mcap"
    assert window.scene is not None
    assert window.scene.point_count == 5000
    assert window.timeline.play_button.isEnabled()
    assert _segments(feed) == []
