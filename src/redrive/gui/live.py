"""The **Live** menu: connect to a ROS 1 master, pick topics, draw them as they arrive, record.

The menu entries call :func:`connect_dialog` (master URI → Topic Picker → :class:`LiveFeed`) and
:func:`record_dialog` (restart the feed recording to an MCAP file, or record the next one).  The
feed itself is in :mod:`redrive.gui.live_feed`; both work on any :class:`LiveWindow`.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Sequence
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from redrive.errors import ConfigError
from redrive.gui.live_feed import LiveFeed, LiveWindow
from redrive.gui.topics import TopicPicker, ros_status
from redrive.live.ros1 import check_master_uri, default_master_uri

__all__ = [
    "LiveFeed",
    "LiveWindow",
    "connect_dialog",
    "record_dialog",
    "show_ros_status",
    "start_feed",
]

logger = logging.getLogger(__name__)

#: a window's dynamic property: the MCAP file the next connection records to
_RECORD_NEXT = "redrive_live_record"


# -- the Live menu ---------------------------------------------------------------------------------


class _StatusBridge(QtCore.QObject):
    """Carries :func:`ros_status` from the thread pool to the log box (a queued signal)."""

    text = QtCore.Signal(str)


def show_ros_status(window: LiveWindow, uri: str) -> None:
    """Put :func:`~redrive.gui.topics.ros_status` of ``uri`` in the log box's status line; asked
    in a worker thread (it blocks up to about a second)."""
    bridge = window.logbox.findChild(_StatusBridge)
    if bridge is None:
        bridge = _StatusBridge(window.logbox)
        bridge.text.connect(window.logbox.set_status)
    window.logbox.set_status(f"ROS master at {uri}: asking …")

    def ask() -> None:
        try:
            text = ros_status(uri)
        except Exception as err:  # a bad URI says so in the status line
            text = f"ROS master: {err}"
        with contextlib.suppress(RuntimeError):  # the window is gone
            bridge.text.emit(text)

    QtCore.QThreadPool.globalInstance().start(ask)


def start_feed(
    window: LiveWindow, uri: str, topics: Sequence[str], *, record: str | Path | None = None
) -> LiveFeed:
    """Stop the window's feed (if any) and start one of ``topics`` as ``window.live_feed``."""
    window.disconnect_live()
    feed = LiveFeed(window, uri, topics, record=record)
    window.live_feed = feed
    feed.start()
    return feed


def connect_dialog(window: LiveWindow) -> TopicPicker | None:
    """Live → Connect: ask the master URI, open the Topic Picker on it; its Run starts a
    :class:`LiveFeed` (recording when :func:`record_dialog` asked for it).  Returns the picker
    (opened, not executed), or None when cancelled."""
    remembered = window.settings.value("live/master_uri")
    default = str(remembered) if remembered else default_master_uri()
    text, ok = QtWidgets.QInputDialog.getText(
        window.window(),
        "Connect to ROS master",
        "ROS master URI:",
        QtWidgets.QLineEdit.EchoMode.Normal,
        default,
    )
    if not ok or not text.strip():
        return None
    try:
        uri = check_master_uri(text)
    except ConfigError as err:
        window.show_error("Cannot connect", str(err))
        return None
    window.settings.setValue("live/master_uri", uri)
    show_ros_status(window, uri)
    picker = TopicPicker.for_master(uri, parent=window.window())
    picker.setAttribute(QtCore.Qt.WidgetAttribute.WA_DeleteOnClose)

    def chosen(topics: list[str]) -> None:
        if not topics:
            return
        record = window.property(_RECORD_NEXT) or None
        window.setProperty(_RECORD_NEXT, "")
        start_feed(window, uri, topics, record=record)

    picker.topics_chosen.connect(chosen)
    picker.open()
    return picker


def record_dialog(window: LiveWindow) -> LiveFeed | None:
    """Live → Record: ask an output ``.mcap``; restart the running feed recording to it (returns
    the new feed), or remember it for the next connection (returns None)."""
    last = window.settings.value("live/record_dir")
    start = Path(str(last)) if last else Path.cwd()
    name = f"live-{time.strftime('%Y%m%d-%H%M%S')}.mcap"
    path_text, _ = QtWidgets.QFileDialog.getSaveFileName(
        window.window(),
        "Record live topics to MCAP",
        str(start / name),
        "MCAP (*.mcap);;All files (*)",
    )
    if not path_text:
        return None
    path = Path(path_text)
    if not path.suffix:
        path = path.with_suffix(".mcap")
    window.settings.setValue("live/record_dir", str(path.parent))
    feed = window.live_feed
    if feed is not None and feed.running:
        logger.info("live: restarting the feed to record to %s", path)
        return start_feed(window, feed.uri, feed.topics, record=path)
    window.setProperty(_RECORD_NEXT, str(path))
    logger.info("live: the next connection records to %s", path)
    return None
