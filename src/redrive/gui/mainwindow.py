"""The main window: planview in the centre; camera, timeline, plots, log box and the
re-simulation panel as docks that can be rearranged (the layout is remembered)."""

from __future__ import annotations

import functools
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from redrive.errors import RedriveError
from redrive.gui import live
from redrive.gui.camera import CameraView
from redrive.gui.loader import FrameLoader, LogSummary, ViewOptions
from redrive.gui.logbox import LogBox
from redrive.gui.menu_helpers import RecentPaths, show_about
from redrive.gui.planview import Planview
from redrive.gui.plots import PlotsPanel
from redrive.gui.scene import Layer, Scene
from redrive.gui.session import RunData, Series, find_run_log
from redrive.gui.timeline import StripData, StripMarker, Timeline

__all__ = ["MainWindow"]

logger = logging.getLogger(__name__)

_MAX_RECENT = 8
_DEFAULT_RATE_HZ = 10.0


def is_run_dir(path: Path) -> bool:
    return path.is_dir() and (path / "manifest.json").is_file() and (path / "frames").is_dir()


def deviation_strip(run: RunData) -> StripData | None:
    """The timeline's deviation strip of a closed-loop run (None: the run has no deviation
    series).  Markers: the collisions of the stored evaluation (``at_fault_collisions``'
    ``collision`` bookmarks; none before ``redrive evaluate``) and the frames where the run's
    ``deviated`` flag turns on.  Time: seconds since the run's first frame."""
    dev = run.deviation
    if dev is None or not run.closed_loop:
        return None
    start_ns = int(dev.stamps_ns[0])

    def t_s(stamp_ns: int) -> float:
        return (stamp_ns - start_ns) / 1e9

    limits = " / ".join(
        text
        for text in (
            None if dev.threshold_m is None else f"{dev.threshold_m:g} m",
            None if dev.threshold_rad is None else f"{np.degrees(dev.threshold_rad):g}°",
        )
        if text
    )
    markers = [
        StripMarker(frame=b.frame_index, t_s=t_s(b.stamp_ns), kind="collision", text=b.detail)
        for b in run.bookmarks
        if b.metric == "at_fault_collisions" and b.kind == "collision"
    ]
    by_frame = dict(zip(dev.frames.tolist(), dev.stamps_ns.tolist(), strict=True))
    markers += [
        StripMarker(
            frame=f,
            t_s=t_s(by_frame[f]),
            kind="deviation",
            text=f"deviation from the logged ego passed {limits or 'its threshold'}",
        )
        for f in dev.crossings()
    ]
    return StripData(
        frames=dev.frames,
        t_s=(dev.stamps_ns - start_ns).astype(np.float64) / 1e9,
        distance_m=dev.distance_m,
        heading_rad=dev.heading_rad,
        threshold_m=dev.threshold_m,
        threshold_rad=dev.threshold_rad,
        bookmarks=tuple(sorted(markers, key=lambda m: (m.frame, m.kind))),
    )


class MainWindow(QtWidgets.QMainWindow):
    """``redrive gui``: open a log or a run, play it, look at it."""

    frame_shown = QtCore.Signal(int)  # a frame's scene reached the views

    def __init__(self, *, settings: QtCore.QSettings | None = None) -> None:
        super().__init__()
        self.setWindowTitle("redrive")
        self.resize(1500, 950)
        self.settings = settings or QtCore.QSettings()
        self.loader = FrameLoader(self)
        self.summary: LogSummary | None = None
        self.run: RunData | None = None
        self.scene: Scene | None = None
        self.current = 0
        self.frame_count = 0
        self.rate_hz = _DEFAULT_RATE_HZ
        self.frames_shown = 0
        self.skipped_ticks = 0
        self._play_t0 = 0.0
        self._play_from = 0
        self._open_t0 = time.perf_counter()
        self._first_frame_s: float | None = None
        self._closed = False
        self.live_feed: live.LiveFeed | None = None  # while live
        self.shown_sensors: frozenset[str] | None = None  # the topic picker's choice
        self.time_origin_ns: int | None = None
        self._series: Series | None = None
        self._cursor_stamp: int | None = None
        self._cursor_timer = QtCore.QTimer(self)
        self._cursor_timer.setSingleShot(True)
        self._cursor_timer.setInterval(200)
        self._cursor_timer.timeout.connect(self._move_cursor)

        self.planview = Planview()
        self.setCentralWidget(self.planview)
        self.camera = CameraView()
        self.timeline = Timeline()
        self.plots = PlotsPanel()
        self.logbox = LogBox()
        self.docks: dict[str, QtWidgets.QDockWidget] = {}
        area = QtCore.Qt.DockWidgetArea
        self._dock("Camera", self.camera, area.RightDockWidgetArea)
        self._dock("Plots", self.plots, area.RightDockWidgetArea)
        self._dock("Log", self.logbox, area.RightDockWidgetArea)
        self.tabifyDockWidget(self.docks["Plots"], self.docks["Log"])
        self.docks["Plots"].raise_()
        self._dock("Timeline", self.timeline, area.BottomDockWidgetArea)
        self.resizeDocks([self.docks["Camera"]], [620], QtCore.Qt.Orientation.Horizontal)
        self.resim: Any = None
        self._build_toolbar()
        self._build_menus()
        self.status = self.statusBar()
        #: says the open log is damaged (stays while it is open; status messages come and go)
        self.damage_label = QtWidgets.QLabel("")
        self.damage_label.setStyleSheet("color: #c0392b")
        self.status.addPermanentWidget(self.damage_label)

        self.play_timer = QtCore.QTimer(self)
        self.play_timer.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
        self.play_timer.timeout.connect(self._tick)

        self.loader.opened.connect(self._opened)
        self.loader.open_failed.connect(self._open_failed)
        self.loader.indexed.connect(self._indexed)
        self.loader.series_ready.connect(self._series_ready)
        self.loader.scene_ready.connect(self.show_scene)
        self.loader.frame_failed.connect(self._frame_failed)
        self.timeline.frame_requested.connect(self.go_to)
        self.timeline.play_toggled.connect(self._play_toggled)
        self.timeline.speed_changed.connect(lambda _s: self._restart_clock())
        self.planview.options_changed.connect(self.refresh)
        self.camera.camera_changed.connect(lambda _c: self.refresh())
        if logging.getLogger("redrive").level == logging.NOTSET:
            logging.getLogger("redrive").setLevel(logging.INFO)
        self._restore_layout()

    # -- building ---------------------------------------------------------------------------------

    def _dock(self, title: str, widget: QtWidgets.QWidget, area: Any) -> QtWidgets.QDockWidget:
        dock = QtWidgets.QDockWidget(title, self)
        dock.setObjectName(f"dock-{title.lower().replace(' ', '-')}")
        dock.setWidget(widget)
        self.addDockWidget(area, dock)
        self.docks[title] = dock
        return dock

    def _build_toolbar(self) -> None:
        bar = self.addToolBar("View")
        bar.setObjectName("toolbar-view")
        self.visible_button = QtWidgets.QToolButton()
        self.visible_button.setText("Object Visible ▾")
        self.visible_button.setPopupMode(QtWidgets.QToolButton.ToolButtonPopupMode.InstantPopup)
        menu = QtWidgets.QMenu(self.visible_button)
        self.layer_actions: dict[Layer, QtGui.QAction] = {}
        for layer in Layer:
            action = menu.addAction(layer.value)
            action.setCheckable(True)
            action.setChecked(True)
            action.toggled.connect(lambda _on: self.refresh())
            self.layer_actions[layer] = action
        self.visible_button.setMenu(menu)
        bar.addWidget(self.visible_button)

    def _build_menus(self) -> None:
        menus = self.menuBar()
        file = menus.addMenu("&File")
        file.addAction("Open &log…", QtGui.QKeySequence.StandardKey.Open, self._ask_open_log)
        file.addAction("Open &run…", self._ask_open_run)
        file.addAction("&Topics…", self.pick_topics)
        self.recent_menu = file.addMenu("Open &recent")
        self._fill_recent()
        file.addSeparator()
        file.addAction("&Quit", QtGui.QKeySequence.StandardKey.Quit, self.close)
        live_menu = menus.addMenu("&Live")
        live_menu.addAction("&Connect to ROS master…", self.connect_live)
        self.record_action = live_menu.addAction("&Record to MCAP…", self.record_live)
        live_menu.addAction("&Disconnect", self.disconnect_live)
        resim = menus.addMenu("Re-&simulation")
        resim.addAction("Show the re-simulation panel", self.show_resim)
        view = menus.addMenu("&View")
        for dock in self.docks.values():
            view.addAction(dock.toggleViewAction())
        view.addSeparator()
        view.addAction("Reset planview camera", self.planview.reset_view)
        view.addAction("Reset layout", self.reset_layout)
        help_menu = menus.addMenu("&Help")
        help_menu.addAction("&About redrive", self._about)
        self._space = QtGui.QShortcut(QtGui.QKeySequence("Space"), self)
        self._space.activated.connect(lambda: self.timeline.set_playing(not self.timeline.playing))
        QtGui.QShortcut(QtGui.QKeySequence("Right"), self).activated.connect(
            lambda: self.go_to(self.current + 1)
        )
        QtGui.QShortcut(QtGui.QKeySequence("Left"), self).activated.connect(
            lambda: self.go_to(self.current - 1)
        )

    # -- layout -----------------------------------------------------------------------------------

    def _restore_layout(self) -> None:
        self._default_state = self.saveState()
        geometry = self.settings.value("window/geometry")
        state = self.settings.value("window/state")
        if isinstance(geometry, QtCore.QByteArray):
            self.restoreGeometry(geometry)
        if isinstance(state, QtCore.QByteArray):
            self.restoreState(state)

    def reset_layout(self) -> None:
        self.restoreState(self._default_state)
        for dock in self.docks.values():
            dock.show()

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:
        self.play_timer.stop()
        self._cursor_timer.stop()
        self._closed = True
        self.settings.setValue("window/geometry", self.saveGeometry())
        self.settings.setValue("window/state", self.saveState())
        self.disconnect_live()
        self.loader.close()
        self.planview.shutdown()
        self.logbox.detach()
        if self.resim is not None and hasattr(self.resim, "shutdown"):
            self.resim.shutdown()
        super().closeEvent(event)

    # -- opening ----------------------------------------------------------------------------------

    def open_path(self, path: str | Path) -> None:
        """A run directory (its log is opened too) or a log."""
        path = Path(path)
        if is_run_dir(path):
            self.open_run(path)
        else:
            self.open_log(path)

    def open_log(self, path: str | Path) -> None:
        self.timeline.set_playing(False)
        self.status.showMessage(f"opening {path} …")
        self.restart_first_frame_clock()
        self.loader.open(path)

    def open_run(self, path: str | Path) -> None:
        try:
            run = RunData.load(path)
        except (RedriveError, OSError) as err:
            self.show_error("Cannot open the run", f"{path}: {err}")
            return
        self.run = run
        self.loader.set_run(run)
        self.plots.set_run(run)
        bookmarks = {b.frame_index: f"{b.metric}/{b.algorithm}: {b.detail}" for b in run.bookmarks}
        strip = deviation_strip(run)
        for marker in strip.bookmarks if strip is not None else ():
            if marker.kind == "deviation":
                bookmarks.setdefault(marker.frame, marker.text)
        self.timeline.set_bookmarks(bookmarks)
        self.timeline.set_deviation(strip)
        self._add_recent(Path(path))
        log = find_run_log(run)
        logger.info(
            "run %s: %d frames, algorithms %s, %d bookmarks",
            path,
            len(run.frames),
            ", ".join(run.detections) or "none",
            len(run.bookmarks),
        )
        recorded = run.manifest.closed_loop.get("sensor_log")
        if log is None and recorded:
            self.show_error(
                "The run's sensor recording is missing",
                f"{path}: a sensor-level closed-loop run records its rendered sensors in "
                f"{recorded!r}, which is not in the run directory (the run may have been stopped "
                f"before it was written); `redrive report {path}` shows its metrics, "
                f"`redrive export {path}` its tables.",
            )
            return
        if log is None and run.closed_loop:
            # An object-level closed loop (or one whose recorded log is gone): no sensor data,
            # so the view plays the run's own frames — its ego, ground truth and outputs.
            self.timeline.set_playing(False)
            self.status.showMessage(f"opening {path} (the run's frames, no sensor data) …")
            self.restart_first_frame_clock()
            self.loader.open_run_frames(run)
            return
        if log is None:
            self.show_error(
                "The run's log is missing",
                f"{path}: its manifest names the log {run.manifest.log.path!r}, "
                "which is not there; open the log with File → Open log.",
            )
            return
        if self.summary is None or self.summary.path != log or self.summary.format == "run":
            self.open_log(log)
        else:
            self.refresh()

    def _ask_open_log(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, "Open log", "", "Logs (*.bag *.mcap *.db3 metadata.yaml);;All files (*)"
        )
        if path:
            self.open_log(path)

    def _ask_open_run(self) -> None:
        path = QtWidgets.QFileDialog.getExistingDirectory(self, "Open run directory")
        if path:
            self.open_run(path)

    def _opened(self, summary: LogSummary) -> None:
        self.summary = summary
        self.shown_sensors = None
        self.frame_count = summary.expected_frames
        duration = (summary.end_ns - summary.start_ns) / 1e9
        if summary.expected_frames > 1 and duration > 0:
            self.rate_hz = (summary.expected_frames - 1) / duration
        self.timeline.set_frame_count(summary.expected_frames)
        self.camera.set_cameras(summary.cameras)
        # Time zero of the timeline and plots: the first frame's stamp (header stamps can be on
        # another clock than the log's record times, e.g. simulated time).
        self.time_origin_ns = None
        self._series = None
        self.setWindowTitle(f"redrive — {summary.path.name}")
        self._add_recent(summary.path)
        logger.info(
            "opened %s (%s, %d topics, %d frames driven by %s) in %.2f s",
            summary.path,
            summary.format,
            len(summary.topics),
            summary.expected_frames,
            summary.driver_topic,
            summary.open_s,
        )
        self.current = 0
        self.damage_label.setText("")
        self.damage_label.setToolTip("")
        if summary.damage:
            logger.warning(
                "%s is damaged; the intact part is shown: %s",
                summary.path,
                "; ".join(summary.damage),
            )
            self.damage_label.setText(
                f"damaged log: {len(summary.damage)} part(s) skipped, the intact part is shown"
            )
            self.damage_label.setToolTip(
                "\n".join(summary.damage)
                + "\n\nThe Log panel lists them; `redrive repair LOG -o FIXED.mcap` saves the "
                "intact part."
            )
        self.refresh()

    def _open_failed(self, path: str, message: str) -> None:
        self.status.showMessage(f"could not open {path}")
        self.show_error("Cannot open the log", message)

    def _indexed(self, count: int, done: bool) -> None:
        if done:
            self.frame_count = count
            self.timeline.set_frame_count(count)
            self.status.showMessage(f"{count} frames", 5000)

    def _series_ready(self, series: Series) -> None:
        self._series = series
        if self.time_origin_ns is not None:
            self.plots.set_series(series, start_ns=self.time_origin_ns)

    # -- frames -----------------------------------------------------------------------------------

    def view_options(self) -> ViewOptions:
        return ViewOptions(
            color_mode=self.planview.color_mode,
            layers=frozenset(k for k, a in self.layer_actions.items() if a.isChecked()),
            planview_2d=self.planview.is_2d,
            camera=self.camera.camera if self.docks["Camera"].isVisible() else None,
            raster=self.planview.raster_spec,
            sensors=self.shown_sensors,
        )

    def go_to(self, index: int) -> None:
        """Show frame ``index`` (clamped to the log)."""
        if self.summary is None or self.live_feed is not None:
            return
        last = max(0, self.frame_count - 1)
        index = min(max(0, index), last)
        self.current = index
        self.loader.request(index, self.view_options())
        if self.timeline.playing:
            self._restart_clock()

    def refresh(self) -> None:
        self.go_to(self.current)

    def show_scene(self, scene: Scene) -> None:
        """Draw ``scene`` (a frame's, from the loader or a live feed) in every view."""
        if self._closed:  # a scene queued before the window closed: its views are gone
            return
        self.scene = scene
        self.planview.show_scene(scene)
        self.camera.show_camera(scene.cameras.get(self.camera.camera or ""))
        if self.time_origin_ns is None:
            self.time_origin_ns = scene.stamp_ns
            self.plots.set_start(scene.stamp_ns)
            if self._series is not None:
                self.plots.set_series(self._series, start_ns=scene.stamp_ns)
        origin = self.time_origin_ns
        assert origin is not None
        self.timeline.show_frame(scene.index, scene.stamp_ns, start_ns=origin)
        # The plots repaint in passes of their own (``python -m benchmarks gui``: moving their cursor
        # every frame cost 3-4 window updates per frame): coalesce it to ≤ 5 moves a second,
        # always ending on the frame shown.
        self._cursor_stamp = scene.stamp_ns
        if not self._cursor_timer.isActive():
            self._cursor_timer.start()
        self.frames_shown += 1
        if self._first_frame_s is None:
            self._first_frame_s = time.perf_counter() - self._open_t0
            logger.info("first frame shown %.2f s after opening", self._first_frame_s)
        self.frame_shown.emit(scene.index)

    def restart_first_frame_clock(self) -> None:
        """Time the next first frame from now (a log being opened, a live feed connecting)."""
        self._open_t0 = time.perf_counter()
        self._first_frame_s = None

    def _move_cursor(self) -> None:
        if self._cursor_stamp is not None:
            self.plots.set_cursor(self._cursor_stamp)

    def _frame_failed(self, index: int, message: str) -> None:
        if self.timeline.playing and index >= self.frame_count - 1:
            self.timeline.set_playing(False)
            return
        logger.warning("%s", message)
        self.status.showMessage(message, 5000)
        if "past the end" in message:
            self.timeline.set_playing(False)

    # -- playback ---------------------------------------------------------------------------------

    def _play_toggled(self, on: bool) -> None:
        if on and self.live_feed is not None:
            self.timeline.set_playing(False)
            return
        if on and self.summary is not None:
            if self.current >= self.frame_count - 1:
                self.go_to(0)
            self._restart_clock()
            self.play_timer.start(max(5, round(1000 / (self.rate_hz * self.timeline.speed) / 2)))
        else:
            self.play_timer.stop()

    def _restart_clock(self) -> None:
        self._play_t0 = time.perf_counter()
        self._play_from = self.current
        if self.play_timer.isActive():
            self.play_timer.setInterval(
                max(5, round(1000 / (self.rate_hz * self.timeline.speed) / 2))
            )

    def _tick(self) -> None:
        """Advance to the frame the wall clock says; while a frame is still on its way, skip
        (never queue) — a slow frame makes playback drop frames, not fall behind."""
        if self.loader.busy:
            self.skipped_ticks += 1
            return
        elapsed = time.perf_counter() - self._play_t0
        target = self._play_from + int(elapsed * self.rate_hz * self.timeline.speed)
        if target <= self.current and self.scene is not None and self.scene.index == self.current:
            return
        if target >= self.frame_count:
            self.timeline.set_playing(False)
            return
        self.current = target
        self.loader.request(target, self.view_options())

    # -- topics -----------------------------------------------------------------------------------

    def pick_topics(self) -> Any:
        """The topic picker on the open log: the topics moved to "shown" are the sensors drawn
        (the LiDAR of the planview, the cameras of the camera panel)."""
        from redrive.gui.topics import TopicPicker

        if self.summary is None or self.summary.format in ("live", "run"):
            self.status.showMessage("open a log first (live topics: Live → Connect)", 5000)
            return None
        summary = self.summary
        picker = TopicPicker.for_log(
            summary.topics, duration_s=(summary.end_ns - summary.start_ns) / 1e9, parent=self
        )
        shown = self.shown_sensors
        picker.show_topics(
            t for sid, t in summary.sensor_topics.items() if shown is None or sid in shown
        )
        picker.topics_chosen.connect(self.show_topics)
        picker.open()
        self.topic_picker = picker
        return picker

    def show_topics(self, topics: list[str]) -> None:
        """Draw only the sensors of ``topics`` (all when every sensor topic is among them)."""
        if self.summary is None:
            return
        chosen = set(topics)
        sensors = frozenset(s for s, t in self.summary.sensor_topics.items() if t in chosen)
        self.shown_sensors = None if len(sensors) == len(self.summary.sensor_topics) else sensors
        self.camera.set_cameras([c for c in self.summary.cameras if c in sensors])
        logger.info("showing %s", ", ".join(sorted(topics)) or "no topic")
        self.refresh()

    # -- live -------------------------------------------------------------------------------------

    def connect_live(self) -> None:
        live.connect_dialog(self)

    def record_live(self) -> None:
        live.record_dialog(self)

    def disconnect_live(self) -> None:
        feed = self.live_feed
        if feed is not None:
            feed.stop()
            self.live_feed = None

    # -- re-simulation ----------------------------------------------------------------------------

    def show_resim(self) -> None:
        if self.resim is None:
            from redrive.gui.resim import ResimPanel

            self.resim = ResimPanel()
            dock = self._dock(
                "Re-simulation", self.resim, QtCore.Qt.DockWidgetArea.RightDockWidgetArea
            )
            self.tabifyDockWidget(self.docks["Camera"], dock)
            if self.summary is not None and self.summary.format != "live":
                self.resim.load_log(self.summary.path)
            self.resim.run_finished.connect(self.open_run)
        self.docks["Re-simulation"].show()
        self.docks["Re-simulation"].raise_()

    def grab_window(self) -> QtGui.QImage:
        """A screenshot of the whole window, the 3D view included."""
        image = self.grab().toImage()
        self.planview.paint_gl_into(image, self)
        return image

    # -- misc -------------------------------------------------------------------------------------

    def _fill_recent(self) -> None:
        self.recent_menu.clear()
        paths = RecentPaths(self.settings, _MAX_RECENT).paths()
        for path in paths:
            self.recent_menu.addAction(path, functools.partial(self.open_path, path))
        self.recent_menu.setEnabled(bool(paths))

    def _add_recent(self, path: Path) -> None:
        RecentPaths(self.settings, _MAX_RECENT).add(path)
        self._fill_recent()

    def show_error(self, title: str, message: str) -> None:
        """Log ``message`` and show it in a (non-blocking) message box."""
        logger.error("%s: %s", title, message)
        box = QtWidgets.QMessageBox(
            QtWidgets.QMessageBox.Icon.Critical, title, message, parent=self
        )
        box.setObjectName("error-dialog")
        box.open()
        self.last_error = message

    def _about(self) -> None:
        show_about(self)
