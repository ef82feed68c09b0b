"""The measures, each in a fresh main window: playback flat out and on the window's timer, the
bare-pyqtgraph ceilings, and open → first frame on the big log."""

from __future__ import annotations

import contextlib
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from PySide6 import QtCore, QtGui, QtWidgets

from benchmarks.gui.logs import BenchLog
from benchmarks.gui.machine import _gl_renderer
from benchmarks.gui.probe import _WAIT_S, _Cpu, _Probe, _Pump, _size, _wrap, _wrap_event
from benchmarks.gui.result import (
    CeilingResult,
    OpenResult,
    PlaybackResult,
    _ms,
    _playback_result,
)
from redrive.io import open_log

_TIMER_SPEED = 8.0

Progress = Callable[[str], None]


class _Bench:
    def __init__(
        self,
        app: QtWidgets.QApplication,
        *,
        seconds: float,
        window_size: tuple[int, int],
        progress: Progress | None,
    ) -> None:
        self.app = app
        self.pump = _Pump(app)
        self.seconds = seconds
        self.window_size = window_size
        self.progress = progress or (lambda _text: None)
        self._settings_dir = tempfile.TemporaryDirectory(prefix="redrive-bench-gui-")
        self._windows = 0
        self.scenes_3d: list[Any] = []
        self.scenes_2d: list[Any] = []
        self.sizes: dict[str, tuple[int, int]] = {}
        self.gl_renderer = ""

    def close(self) -> None:
        self.pump.close()
        self._settings_dir.cleanup()

    # -- windows ----------------------------------------------------------------------------------

    @contextlib.contextmanager
    def window(self) -> Iterator[tuple[Any, _Probe]]:
        from redrive.gui.mainwindow import MainWindow

        self._windows += 1
        ini = Path(self._settings_dir.name) / f"window-{self._windows}.ini"
        settings = QtCore.QSettings(str(ini), QtCore.QSettings.Format.IniFormat)
        win = MainWindow(settings=settings)
        win.resize(*self.window_size)
        probe = _Probe(win)
        win.show()
        self.pump.until(lambda: win.windowHandle() is not None and win.windowHandle().isExposed())
        self.pump.run_for(0.2)
        try:
            yield win, probe
        finally:
            # Let the last requested frame arrive while the window is alive: a scene queued
            # before close would reach views the close has already torn down.
            win.timeline.set_playing(False)
            self.pump.until(lambda: not win.loader.busy, 10.0)
            self.pump.run_for(0.1)
            win.close()
            win.deleteLater()
            self.pump.run_for(0.2)

    def _open_and_settle(self, win: Any, probe: _Probe, path: Path) -> None:
        """Open ``path``, wait for the first frame and for the background indexing and plot
        series to finish (so no reader thread runs during the measure)."""
        series = [False]
        win.loader.series_ready.connect(lambda _s: series.__setitem__(0, True))
        win.open_path(path)
        if not self.pump.until(lambda: win.frames_shown >= 1):
            msg = f"{path}: no frame shown within {_WAIT_S:.0f} s"
            raise RuntimeError(msg)
        self.pump.until(lambda: series[0])
        probe.attach_session()

    # -- playback -----------------------------------------------------------------------------------

    def playback(self, log: BenchLog, view: str, mode: str) -> PlaybackResult:
        self.progress(f"window, {view.upper()} {mode} ({self.seconds:g} s)")
        with self.window() as (win, probe):
            self._open_and_settle(win, probe, log.path)
            if view == "2d":
                win.planview.convert_button.setChecked(True)
                self.pump.until(lambda: win.scene is not None and win.scene.raster is not None)
            count = max(1, win.frame_count)

            def next_frame(index: int) -> None:
                win.go_to((index + 1) % count)

            win.frame_shown.connect(next_frame)
            win.go_to(win.current + 1)
            self.pump.run_for(min(1.0, self.seconds / 4))  # warm-up (caches, GL buffers)
            win.frame_shown.disconnect(next_frame)
            self.pump.until(lambda: not win.loader.busy, 10.0)
            planview = win.planview.view2d if view == "2d" else win.planview.view3d
            self.sizes[f"planview_{view}"] = _size(planview)
            self.sizes["camera"] = _size(win.camera.widget)

            advanced = [0]
            last = [win.current]

            def on_shown(index: int) -> None:
                advanced[0] += index - last[0] if index >= last[0] else index + 1
                last[0] = index

            win.frame_shown.connect(on_shown)
            mark = probe.mark()
            shown0, painted0, skipped0 = win.frames_shown, probe.painted, win.skipped_ticks
            cpu = _Cpu()
            if mode == "flat out":
                win.frame_shown.connect(next_frame)
                win.go_to((win.current + 1) % count)
                elapsed = self.pump.run_for(self.seconds)
                win.frame_shown.disconnect(next_frame)
            else:
                from redrive.gui.timeline import SPEEDS

                win.timeline.speed_box.setCurrentIndex(SPEEDS.index(_TIMER_SPEED))

                def keep_playing() -> None:
                    if not win.timeline.playing:  # the end of the log: again from the start
                        win.go_to(0)
                        win.timeline.set_playing(True)

                win.timeline.set_playing(True)
                elapsed = self.pump.run_for(self.seconds, keep_playing)
                win.timeline.set_playing(False)
            shown = win.frames_shown - shown0
            painted = probe.painted - painted0
            cpu_used = cpu.stop()
            win.frame_shown.disconnect(on_shown)
            samples = probe.since(mark)
            self.pump.until(lambda: not win.loader.busy, 10.0)
            keep = self.scenes_2d if view == "2d" else self.scenes_3d
            if len(keep) < 4 and win.scene is not None:
                keep.append(win.scene)
            if view == "3d" and not self.gl_renderer:
                self.gl_renderer = _gl_renderer(win.planview.view3d)
        return _playback_result(
            view=view,
            mode=mode,
            elapsed=elapsed,
            shown=shown,
            painted=painted,
            advanced=advanced[0],
            skipped=win.skipped_ticks - skipped0 if mode != "flat out" else None,
            samples=samples,
            cpu=cpu_used,
            planview_size=self.sizes[f"planview_{view}"],
            camera_size=self.sizes["camera"],
        )

    def collect_scenes(self, log: BenchLog) -> None:
        """A few more of the window's scenes (3D and 2D) for the ceilings."""
        with self.window() as (win, probe):
            self._open_and_settle(win, probe, log.path)
            for view, keep in (("3d", self.scenes_3d), ("2d", self.scenes_2d)):
                win.planview.convert_button.setChecked(view == "2d")
                for i in range(1, 5):
                    if len(keep) >= 4:
                        break
                    keep.append(self._show(win, i % max(1, win.frame_count), raster=view == "2d"))
            self.sizes.setdefault("planview_3d", _size(win.planview.view3d))
            self.sizes.setdefault("planview_2d", _size(win.planview.view2d))
            self.sizes.setdefault("camera", _size(win.camera.widget))
            if not self.gl_renderer:
                self.gl_renderer = _gl_renderer(win.planview.view3d)

    def _show(self, win: Any, index: int, *, raster: bool) -> Any:
        """Frame ``index`` shown (with its 2D raster when ``raster``): its scene."""

        def shown() -> bool:
            scene = win.scene
            return bool(
                scene is not None
                and scene.index == index
                and (not raster or scene.raster is not None)
            )

        win.go_to(index)
        self.pump.until(shown)
        return win.scene

    # -- ceilings -----------------------------------------------------------------------------------

    def _ceiling_loop(
        self,
        name: str,
        what: str,
        widget: QtWidgets.QWidget,
        paint_name: str,
        feed: Callable[[int], None],
    ) -> CeilingResult:
        self.progress(f"ceiling: {what} ({self.seconds:g} s)")
        set_data: list[float] = []
        paints: list[float] = []
        updates: list[float] = []
        painted = [0]
        _wrap(widget, paint_name, paints, lambda: painted.__setitem__(0, painted[0] + 1))
        _wrap_event(widget, QtCore.QEvent.Type.UpdateRequest, updates)
        widget.show()
        self.pump.until(lambda: widget.windowHandle() is not None and widget.isVisible())
        self.pump.run_for(0.2)

        def frame(k: int) -> None:
            before = painted[0]
            t = time.perf_counter()
            feed(k)
            set_data.append(time.perf_counter() - t)
            self.pump.until(lambda: painted[0] > before, 10.0)

        for k in range(10):  # warm-up
            frame(k)
        mark = len(paints), len(set_data), len(updates)
        cpu = _Cpu()
        t0 = time.perf_counter()
        k = 0
        while time.perf_counter() - t0 < self.seconds:
            frame(k)
            k += 1
        elapsed = time.perf_counter() - t0
        used = cpu.stop()
        size = _size(widget)
        widget.close()
        widget.deleteLater()
        self.pump.run_for(0.1)
        return CeilingResult(
            name=name,
            what=what,
            size=size,
            seconds=elapsed,
            frames=k,
            fps=k / elapsed,
            timings={
                "set_data": _ms(set_data[mark[1] :]),
                "paint": _ms(paints[mark[0] :]),
                "window_update": _ms(updates[mark[2] :]),
            },
            cpu_ms_per_frame={
                "gui_thread": used.gui_thread_s * 1e3 / k if k else None,
                "process": used.process_s * 1e3 / k if k else None,
            },
            machine_busy_fraction=used.machine_busy_fraction,
        )

    def ceiling_gl(self) -> CeilingResult:
        import pyqtgraph.opengl as gl

        scenes = [s for s in self.scenes_3d if len(s.points)] or self.scenes_3d
        view = gl.GLViewWidget()
        view.setBackgroundColor((16, 16, 20))
        view.setCameraPosition(
            pos=QtGui.QVector3D(8, 0, 0), distance=55, elevation=35, azimuth=180
        )  # as the planview's
        scatter = gl.GLScatterPlotItem(pos=np.zeros((1, 3)), size=2.0, pxMode=True)
        scatter.setGLOptions("opaque")
        view.addItem(scatter)
        view.resize(*self.sizes.get("planview_3d", (1000, 800)))
        points = scenes[0].points.shape[0] if scenes else 0

        def feed(k: int) -> None:
            s = scenes[k % len(scenes)]
            scatter.setData(pos=s.points, color=s.colors)

        return self._ceiling_loop(
            "gl_scatter",
            f"bare GLViewWidget + GLScatterPlotItem, {points:,} points",
            view,
            "paintGL",
            feed,
        )

    def _ceiling_image(
        self, name: str, what: str, images: list[npt.NDArray[np.uint8]], size: tuple[int, int]
    ) -> CeilingResult:
        import pyqtgraph as pg

        widget = pg.GraphicsLayoutWidget()
        widget.setBackground((16, 16, 20))
        box = widget.addViewBox(lockAspect=True, invertY=True)
        item = pg.ImageItem(axisOrder="row-major")
        box.addItem(item)
        item.setImage(images[0], autoLevels=False, levels=(0, 255))
        box.autoRange(padding=0)
        widget.resize(*size)

        def feed(k: int) -> None:
            item.setImage(images[k % len(images)], autoLevels=False, levels=(0, 255))

        h, w = images[0].shape[:2]
        return self._ceiling_loop(name, f"{what}, {w}×{h}", widget, "paintEvent", feed)

    def ceiling_raster(self) -> CeilingResult:
        images = [s.raster for s in self.scenes_2d if s.raster is not None]
        return self._ceiling_image(
            "raster_image",
            "bare ImageItem in a ViewBox: the 2D raster",
            images,
            self.sizes.get("planview_2d", (1000, 800)),
        )

    def ceiling_camera(self) -> CeilingResult | None:
        images = [c.image for s in self.scenes_3d for c in s.cameras.values()]
        if not images:
            return None
        return self._ceiling_image(
            "camera_image",
            "bare ImageItem in a ViewBox: the camera image",
            images,
            self.sizes.get("camera", (600, 340)),
        )

    # -- open ---------------------------------------------------------------------------------------

    def _open_once(self, log: BenchLog) -> dict[str, Any]:
        with self.window() as (win, probe):
            state: dict[str, float] = {}

            def indexed(_count: int, done: bool) -> None:
                if done:
                    state.setdefault("indexed", time.perf_counter())

            win.loader.indexed.connect(indexed)
            win.loader.series_ready.connect(
                lambda _s: state.setdefault("series", time.perf_counter())
            )
            mark = probe.mark()
            painted0 = probe.painted
            t0 = time.perf_counter()
            win.open_path(log.path)
            if not self.pump.until(lambda: win.frames_shown >= 1):
                msg = f"{log.path}: no frame shown within {_WAIT_S:.0f} s"
                raise RuntimeError(msg)
            t_shown = time.perf_counter()
            self.pump.until(lambda: probe.painted > painted0, 10.0)
            t_paint = time.perf_counter()
            requests = len(probe.since(mark)["loader_request"])
            self.pump.until(lambda: "series" in state)  # the background reads are done
            return {
                "first_frame_s": t_shown - t0,
                "first_paint_s": t_paint - t0,
                "open_s": None if win.summary is None else win.summary.open_s,
                "indexed_s": state["indexed"] - t0 if "indexed" in state else None,
                "requests": requests,
            }

    def open_time(self, log: BenchLog, repeats: int) -> OpenResult:
        runs = []
        for r in range(repeats):
            self.progress(f"open → first frame, {log.file_bytes / 1e9:.2f} GB, {r + 1}/{repeats}")
            runs.append(self._open_once(log))
        self.progress(f"baseline: reading all of {log.file_bytes / 1e9:.2f} GB once")
        t0 = time.perf_counter()
        with open_log(log.path) as reader:
            for _message in reader.messages():
                pass
        full_read = time.perf_counter() - t0
        return OpenResult(
            log=log,
            first_frame_s=[r["first_frame_s"] for r in runs],
            first_paint_s=[r["first_paint_s"] for r in runs],
            open_s=[r["open_s"] for r in runs],
            indexed_s=[r["indexed_s"] for r in runs],
            requests_before_first=[r["requests"] for r in runs],
            full_read_s=full_read,
        )
