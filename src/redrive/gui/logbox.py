"""The log box: redrive's log messages, and the ROS master / rospy status line."""

from __future__ import annotations

import contextlib
import logging
import time

from PySide6 import QtCore, QtWidgets

__all__ = ["LogBox"]


class _Bridge(QtCore.QObject):
    message = QtCore.Signal(str)


class _QtHandler(logging.Handler):
    """Forwards records to the GUI thread (a queued signal: safe from worker threads)."""

    def __init__(self, bridge: _Bridge) -> None:
        super().__init__(level=logging.INFO)
        self.bridge = bridge
        self.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))

    def emit(self, record: logging.LogRecord) -> None:
        with contextlib.suppress(RuntimeError):  # the widget is gone
            self.bridge.message.emit(self.format(record))


class LogBox(QtWidgets.QWidget):
    """Messages (newest last, capped) and a status line for the ROS master and rospy."""

    MAX_LINES = 2000

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.status = QtWidgets.QLabel("ROS master: not connected")
        self.status.setWordWrap(True)
        layout.addWidget(self.status)
        self.text = QtWidgets.QPlainTextEdit()
        self.text.setReadOnly(True)
        self.text.setMaximumBlockCount(self.MAX_LINES)
        layout.addWidget(self.text, 1)
        self._bridge = _Bridge()
        self._bridge.message.connect(self.append)
        self.handler = _QtHandler(self._bridge)
        logging.getLogger("redrive").addHandler(self.handler)

    def append(self, text: str) -> None:
        self.text.appendPlainText(f"{time.strftime('%H:%M:%S')}  {text}")

    def set_status(self, text: str) -> None:
        self.status.setText(text)

    def detach(self) -> None:
        logging.getLogger("redrive").removeHandler(self.handler)
