"""The timeline: Replay/Pause, Step back, Step over, speed, a scrub slider with failure-frame
bookmarks from evaluation, jump to the previous/next bookmark, frame index and timestamp; for a
closed-loop run, a strip below plots the deviation of the driven from the logged ego over time,
with markers at collisions and at the frames where the deviation passes its threshold (a click
on a marker, or anywhere on the strip, seeks there)."""

from __future__ import annotations

import bisect
import datetime as dt
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

__all__ = ["SPEEDS", "BookmarkSlider", "DeviationStrip", "StripData", "StripMarker", "Timeline"]

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


@dataclass(frozen=True, slots=True, kw_only=True)
class StripMarker:
    """A bookmark of the deviation strip: ``kind`` is ``collision`` or ``deviation``."""

    frame: int
    t_s: float
    kind: str
    text: str


@dataclass(frozen=True, slots=True, kw_only=True)
class StripData:
    """What the deviation strip plots: one value per frame (``frames`` ascending, ``t_s`` their
    times), the thresholds (None: not known) and the markers."""

    frames: npt.NDArray[np.int64]
    t_s: npt.NDArray[np.float64]
    distance_m: npt.NDArray[np.float64]
    heading_rad: npt.NDArray[np.float64]
    threshold_m: float | None
    threshold_rad: float | None
    bookmarks: tuple[StripMarker, ...]


_MARKER_STYLE = {  # kind → symbol, colour
    "collision": ("x", (255, 70, 70)),
    "deviation": ("t", (255, 170, 40)),
}
_DISTANCE_COLOR = (90, 200, 255)
_HEADING_COLOR = (200, 140, 255)


class DeviationStrip(pg.PlotWidget):
    """Distance (m) and heading difference (°) of the driven from the logged ego over time
    (s since the first frame), the thresholds dashed, the bookmarks as markers along the top
    and a cursor at the frame shown.  Emits ``frame_requested`` on a click."""

    frame_requested = QtCore.Signal(int)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent, background=(24, 24, 28))
        self.setMinimumHeight(110)
        self.setMaximumHeight(170)
        item = self.getPlotItem()
        item.showGrid(x=True, y=True, alpha=0.2)
        item.setLabel("bottom", "t", units="s")
        item.setLabel("left", "deviation")
        item.setMouseEnabled(y=False)
        item.addLegend(offset=(8, 4), labelTextSize="8pt")
        self.distance = item.plot(pen=pg.mkPen(_DISTANCE_COLOR, width=2), name="distance (m)")
        self.heading = item.plot(pen=pg.mkPen(_HEADING_COLOR, width=2), name="heading (°)")
        dash = QtCore.Qt.PenStyle.DashLine
        self.limit_m = pg.InfiniteLine(angle=0, pen=pg.mkPen(_DISTANCE_COLOR, style=dash))
        self.limit_deg = pg.InfiniteLine(angle=0, pen=pg.mkPen(_HEADING_COLOR, style=dash))
        self.cursor = pg.InfiniteLine(angle=90, pen=pg.mkPen((255, 255, 0), width=1))
        for line in (self.limit_m, self.limit_deg, self.cursor):
            item.addItem(line, ignoreBounds=line is not self.cursor)
        self.marker_lines: list[pg.InfiniteLine] = []
        self.markers = pg.ScatterPlotItem(size=13, pxMode=True, hoverable=True)
        self.markers.sigClicked.connect(self._marker_clicked)
        item.addItem(self.markers)
        self.bookmarks: list[StripMarker] = []
        self.frames: npt.NDArray[np.int64] = np.zeros(0, np.int64)
        self.t_s: npt.NDArray[np.float64] = np.zeros(0)
        self.scene().sigMouseClicked.connect(self._clicked)
        self._marker_hit = False

    def set_data(self, data: StripData) -> None:
        """The series (one value per frame) and the markers."""
        self.frames, self.t_s = data.frames, data.t_s
        distance_m, heading_rad = data.distance_m, data.heading_rad
        threshold_m, threshold_rad = data.threshold_m, data.threshold_rad
        heading_deg = np.degrees(heading_rad)
        self.distance.setData(self.t_s, distance_m, connect="finite")
        self.heading.setData(self.t_s, heading_deg, connect="finite")
        for line, value in (
            (self.limit_m, threshold_m),
            (self.limit_deg, None if threshold_rad is None else math.degrees(threshold_rad)),
        ):
            line.setVisible(value is not None)
            if value is not None:
                line.setValue(value)
        finite = np.concatenate([distance_m[np.isfinite(distance_m)],
                                 heading_deg[np.isfinite(heading_deg)]])  # fmt: skip
        top = max(
            float(finite.max()) if len(finite) else 1.0,
            threshold_m or 0.0,
            math.degrees(threshold_rad or 0.0),
        )
        self.bookmarks = list(data.bookmarks)
        for line in self.marker_lines:
            self.getPlotItem().removeItem(line)
        self.marker_lines = []
        spots = []
        for b in self.bookmarks:
            symbol, color = _MARKER_STYLE.get(b.kind, ("o", (220, 220, 220)))
            line = pg.InfiniteLine(pos=b.t_s, angle=90, pen=pg.mkPen((*color, 140), width=1))
            self.getPlotItem().addItem(line, ignoreBounds=True)
            self.marker_lines.append(line)
            spots.append(
                {
                    "pos": (b.t_s, top * 1.08),
                    "symbol": symbol,
                    "brush": pg.mkBrush(color),
                    "pen": pg.mkPen(color),
                    "data": b.frame,
                }
            )
        self.markers.setData(spots=spots)
        self.markers.setToolTip("\n".join(b.text for b in self.bookmarks))
        self.getPlotItem().setYRange(0.0, top * 1.15, padding=0)
        if len(self.t_s):
            self.getPlotItem().setXRange(float(self.t_s[0]), float(self.t_s[-1]), padding=0.01)

    def show_frame(self, frame: int) -> None:
        """Move the cursor to ``frame``'s time."""
        i = int(np.searchsorted(self.frames, frame))
        if i < len(self.frames) and self.frames[i] == frame:
            self.cursor.setValue(float(self.t_s[i]))

    def frame_near(self, t_s: float) -> int | None:
        """The frame whose time is nearest ``t_s``."""
        if len(self.t_s) == 0:
            return None
        return int(self.frames[int(np.argmin(np.abs(self.t_s - t_s)))])

    def _marker_clicked(self, _item: object, points: Sequence[pg.SpotItem], *_: object) -> None:
        if len(points):
            self._marker_hit = True
            self.frame_requested.emit(int(points[0].data()))

    def _clicked(self, event: object) -> None:
        if self._marker_hit:  # the marker's own click already sought
            self._marker_hit = False
            return
        pos = event.scenePos()  # type: ignore[attr-defined]
        vb = self.getPlotItem().getViewBox()
        if not vb.sceneBoundingRect().contains(pos):
            return
        frame = self.frame_near(float(vb.mapSceneToView(pos).x()))
        if frame is not None:
            self.frame_requested.emit(frame)


class Timeline(QtWidgets.QWidget):
    """Transport controls; emits ``frame_requested`` when the user moves to a frame."""

    frame_requested = QtCore.Signal(int)
    play_toggled = QtCore.Signal(bool)
    speed_changed = QtCore.Signal(float)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        rows = QtWidgets.QVBoxLayout(self)
        rows.setContentsMargins(0, 0, 0, 0)
        rows.setSpacing(0)
        layout = QtWidgets.QHBoxLayout()
        layout.setContentsMargins(4, 2, 4, 2)
        rows.addLayout(layout)
        self.deviation = DeviationStrip()
        self.deviation.hide()
        self.deviation.frame_requested.connect(self.frame_requested)
        rows.addWidget(self.deviation, 1)
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

    def set_deviation(self, data: StripData | None) -> None:
        """Show the deviation strip with ``data``; None hides it (an open-loop run, a log)."""
        if data is None:
            self.deviation.hide()
            self.setSizePolicy(
                QtWidgets.QSizePolicy.Policy.Preferred, QtWidgets.QSizePolicy.Policy.Fixed
            )
            return
        self.deviation.set_data(data)
        self.deviation.show()
        self.setSizePolicy(
            QtWidgets.QSizePolicy.Policy.Preferred, QtWidgets.QSizePolicy.Policy.Minimum
        )

    def show_frame(self, index: int, stamp_ns: int, *, start_ns: int) -> None:
        """Move the slider to ``index`` without requesting it, and show index and time."""
        self._setting = True
        self.slider.setValue(index)
        self._setting = False
        if self.deviation.isVisible():
            self.deviation.show_frame(index)
        # counted from 1, of the frames known: "frame 3 / 3" at the last frame of a 3-frame log
        self.frame_label.setText(f"frame {index + 1} / {self.slider.maximum() + 1}")
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
