"""The timeline: Replay/Pause, Step back, Step over, speed, a scrub slider with failure-frame
bookmarks from evaluation, jump to the previous/next bookmark, frame index and timestamp."""

from __future__ import annotations

import bisect
import datetime as dt
from collections.abc import Sequence

from PySide6 import QtCore, QtGui, QtWidgets

__all__ = ["SPEEDS", "BookmarkSlider", "Timeline"]

SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)


class BookmarkSlider(QtWidgets.QSlider):
    """A horizontal slider that paints a red tick at each bookmarked frame."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(QtCore.Qt.Orientation.Horizontal, parent)
        self.bookmarks: list[int] = []
        self.setMinimumHeight(26)

    def set_bookmarks(self, frames: Sequence[int]) -> None:
        self.bookmarks = sorted(set(frames))
        self.update()

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:
        super().paintEvent(event)
        if not self.bookmarks or self.maximum() <= self.minimum():
            return
        painter = QtGui.QPainter(self)
        painter.setPen(QtGui.QPen(QtGui.QColor(235, 60, 60), 2))
        opt = QtWidgets.QStyleOptionSlider()
        self.initStyleOption(opt)
        groove = self.style().subControlRect(
            QtWidgets.QStyle.ComplexControl.CC_Slider,
            opt,
            QtWidgets.QStyle.SubControl.SC_SliderGroove,
            self,
        )
        handle = self.style().subControlRect(
            QtWidgets.QStyle.ComplexControl.CC_Slider,
            opt,
            QtWidgets.QStyle.SubControl.SC_SliderHandle,
            self,
        )
        left = groove.left() + handle.width() // 2
        width = groove.width() - handle.width()
        span = self.maximum() - self.minimum()
        for frame in self.bookmarks:
            x = left + round(width * (frame - self.minimum()) / span)
            painter.drawLine(x, 1, x, 7)
        painter.end()


class Timeline(QtWidgets.QWidget):
    """Transport controls; emits ``frame_requested`` when the user moves to a frame."""

    frame_requested = QtCore.Signal(int)
    play_toggled = QtCore.Signal(bool)
    speed_changed = QtCore.Signal(float)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(4, 2, 4, 2)
        self.setSizePolicy(
            QtWidgets.QSizePolicy.Policy.Preferred, QtWidgets.QSizePolicy.Policy.Fixed
        )

        def button(text: str, tip: str) -> QtWidgets.QPushButton:
            b = QtWidgets.QPushButton(text)
            b.setToolTip(tip)
            layout.addWidget(b)
            return b

        self.prev_bookmark = button("◀ Failure", "Previous failure bookmark (from evaluation)")
        self.step_back = button("Step back", "Previous frame")
        self.play_button = button("Replay", "Play from the current frame (space)")
        self.play_button.setCheckable(True)
        self.step_over = button("Step over", "Next frame")
        self.next_bookmark = button("Failure ▶", "Next failure bookmark (from evaluation)")
        self.speed_box = QtWidgets.QComboBox()
        for s in SPEEDS:
            self.speed_box.addItem(f"{s:g}×", s)
        self.speed_box.setCurrentIndex(SPEEDS.index(1.0))
        self.speed_box.setToolTip("Playback speed")
        layout.addWidget(self.speed_box)
        self.slider = BookmarkSlider()
        self.slider.setRange(0, 0)
        layout.addWidget(self.slider, 1)
        self.frame_label = QtWidgets.QLabel("frame –")
        self.frame_label.setMinimumWidth(110)
        layout.addWidget(self.frame_label)
        self.time_label = QtWidgets.QLabel("")
        self.time_label.setMinimumWidth(210)
        layout.addWidget(self.time_label)
        self.bookmark_frames: list[int] = []
        self.bookmark_text: dict[int, str] = {}

        self.play_button.toggled.connect(self._play_toggled)
        self.step_back.clicked.connect(lambda: self.frame_requested.emit(self.slider.value() - 1))
        self.step_over.clicked.connect(lambda: self.frame_requested.emit(self.slider.value() + 1))
        self.prev_bookmark.clicked.connect(self.jump_previous_bookmark)
        self.next_bookmark.clicked.connect(self.jump_next_bookmark)
        self.slider.valueChanged.connect(self._slider_moved)
        self.speed_box.currentIndexChanged.connect(
            lambda _i: self.speed_changed.emit(float(self.speed_box.currentData()))
        )
        self._setting = False
        self.set_bookmarks({})

    @property
    def speed(self) -> float:
        return float(self.speed_box.currentData())

    @property
    def playing(self) -> bool:
        return self.play_button.isChecked()

    def set_playing(self, on: bool) -> None:
        self.play_button.setChecked(on)

    def _play_toggled(self, on: bool) -> None:
        self.play_button.setText("Pause" if on else "Replay")
        self.play_toggled.emit(on)

    def set_frame_count(self, count: int) -> None:
        self._setting = True
        self.slider.setRange(0, max(0, count - 1))
        self._setting = False

    def set_bookmarks(self, bookmarks: dict[int, str]) -> None:
        """Frame index → what failed there."""
        self.bookmark_frames = sorted(bookmarks)
        self.bookmark_text = dict(bookmarks)
        self.slider.set_bookmarks(self.bookmark_frames)
        for b in (self.prev_bookmark, self.next_bookmark):
            b.setEnabled(bool(bookmarks))

    def show_frame(self, index: int, stamp_ns: int, *, start_ns: int) -> None:
        """Move the slider to ``index`` without requesting it, and show index and time."""
        self._setting = True
        self.slider.setValue(index)
        self._setting = False
        self.frame_label.setText(f"frame {index} / {self.slider.maximum()}")
        when = dt.datetime.fromtimestamp(stamp_ns / 1e9, tz=dt.UTC)
        self.time_label.setText(
            f"t+{(stamp_ns - start_ns) / 1e9:7.3f} s  {when:%H:%M:%S}.{when.microsecond // 1000:03d}"
        )
        text = self.bookmark_text.get(index)
        self.frame_label.setToolTip(text or "")

    def _slider_moved(self, value: int) -> None:
        if not self._setting:
            self.frame_requested.emit(value)

    def jump_next_bookmark(self) -> None:
        i = bisect.bisect_right(self.bookmark_frames, self.slider.value())
        if i < len(self.bookmark_frames):
            self.frame_requested.emit(self.bookmark_frames[i])

    def jump_previous_bookmark(self) -> None:
        i = bisect.bisect_left(self.bookmark_frames, self.slider.value())
        if i > 0:
            self.frame_requested.emit(self.bookmark_frames[i - 1])
