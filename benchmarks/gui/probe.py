"""The benchmark's instruments: the Qt event loop run from Python, CPU time, and timers wrapped
around a main window's loader, views and paints (the window's code is not changed)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtWidgets

_WAIT_S = 120.0


# -- the event loop -------------------------------------------------------------------------------


class _Pump:
    """Runs the Qt event loop from Python: ``processEvents(WaitForMoreEvents)`` (which releases
    the GIL while it waits) with a 10 ms heartbeat timer so conditions are checked."""

    def __init__(self, app: QtWidgets.QApplication) -> None:
        self.app = app
        self._heartbeat = QtCore.QTimer()
        self._heartbeat.setInterval(10)
        self._heartbeat.timeout.connect(lambda: None)
        self._heartbeat.start()

    def close(self) -> None:
        self._heartbeat.stop()

    def step(self) -> None:
        self.app.processEvents(QtCore.QEventLoop.ProcessEventsFlag.WaitForMoreEvents)

    def until(self, cond: Callable[[], bool], timeout_s: float = _WAIT_S) -> bool:
        """Run events until ``cond()``; False on timeout."""
        deadline = time.perf_counter() + timeout_s
        while not cond():
            if time.perf_counter() > deadline:
                return False
            self.step()
        return True

    def run_for(self, seconds: float, each: Callable[[], None] | None = None) -> float:
        """Run events for ``seconds`` (calling ``each`` after every wake-up); the time taken."""
        t0 = time.perf_counter()
        end = t0 + seconds
        while time.perf_counter() < end:
            self.step()
            if each is not None:
                each()
        return time.perf_counter() - t0


def _machine_jiffies() -> tuple[int, int]:
    """(busy, total) jiffies of all CPUs since boot, from /proc/stat ((0, 0) without it)."""
    try:
        fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:9]
    except (OSError, IndexError):
        return 0, 0
    values = [int(v) for v in fields]
    total = sum(values)
    return total - values[3] - values[4], total  # minus idle and iowait


@dataclass(frozen=True, slots=True)
class _CpuUsed:
    gui_thread_s: float
    process_s: float
    machine_busy_fraction: float | None


class _Cpu:
    """CPU time over a measure: the GUI thread's, this process's (loader, GL rasteriser
    threads …), and the whole machine's busy share (X server included)."""

    def __init__(self) -> None:
        self.thread0 = time.thread_time()
        self.process0 = time.process_time()
        self.machine0 = _machine_jiffies()

    def stop(self) -> _CpuUsed:
        busy0, total0 = self.machine0
        busy1, total1 = _machine_jiffies()
        return _CpuUsed(
            gui_thread_s=time.thread_time() - self.thread0,
            process_s=time.process_time() - self.process0,
            machine_busy_fraction=(busy1 - busy0) / (total1 - total0) if total1 > total0 else None,
        )


# -- instrumenting the window ---------------------------------------------------------------------


def _wrap(obj: Any, name: str, sink: list[float], after: Callable[[], None] | None = None) -> None:
    """Replace ``obj.name`` by a wrapper appending its duration to ``sink`` (an instance
    attribute: Qt virtuals such as ``paintGL`` / ``paintEvent`` are looked up there too)."""
    original = getattr(obj, name)

    def timed(*args: Any, **kwargs: Any) -> Any:
        t = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            sink.append(time.perf_counter() - t)
            if after is not None:
                after()

    setattr(obj, name, timed)


def _wrap_event(obj: Any, kind: QtCore.QEvent.Type, sink: list[float]) -> None:
    """Time ``obj``'s handling of events of ``kind`` (an instance-level ``event`` override)."""
    original = obj.event

    def timed(event: QtCore.QEvent) -> bool:
        if event.type() != kind:
            return bool(original(event))
        t = time.perf_counter()
        try:
            return bool(original(event))
        finally:
            sink.append(time.perf_counter() - t)

    obj.event = timed


class _Probe:
    """Timers on one MainWindow's loader, views and paints (the window's code is unchanged)."""

    def __init__(self, win: Any) -> None:
        self.win = win
        self.samples: dict[str, list[float]] = {
            k: []
            for k in (
                "loader_request",
                "loader_read",
                "loader_build",
                "loader_cpu",
                "gui_show",
                "paint_planview",
                "paint_camera",
                "window_update",
            )
        }
        self.painted = 0  # distinct scenes the planview painted
        self._last_painted: int | None = None
        show = self.samples["gui_show"]
        self._read_s = 0.0
        do_frame = win.loader._do_frame

        def timed_do_frame(*args: Any) -> Any:  # in the loader thread
            self._read_s = 0.0
            wall, cpu = time.perf_counter(), time.thread_time()
            try:
                return do_frame(*args)
            finally:
                total = time.perf_counter() - wall
                self.samples["loader_cpu"].append(time.thread_time() - cpu)
                self.samples["loader_read"].append(self._read_s)
                self.samples["loader_build"].append(total - self._read_s)
                self.samples["loader_request"].append(total)

        win.loader._do_frame = timed_do_frame
        for obj, name in (
            (win.planview, "show_scene"),
            (win.camera, "show_camera"),
            (win.timeline, "show_frame"),
            (win.plots, "set_cursor"),
        ):
            _wrap(obj, name, show)
        planview = win.planview
        _wrap(planview.view3d, "paintGL", self.samples["paint_planview"], self._painted)
        _wrap(planview.view2d, "paintEvent", self.samples["paint_planview"], self._painted)
        _wrap(win.camera.widget, "paintEvent", self.samples["paint_camera"])
        # The top-level repaint: every dirty widget painted, then the window composed and flushed
        # (through GL, as it holds a QOpenGLWidget).
        _wrap_event(win, QtCore.QEvent.Type.UpdateRequest, self.samples["window_update"])
        self._session: Any = None

    def _painted(self) -> None:
        scene = self.win.planview.scene
        if scene is not None and scene.index != self._last_painted:
            self._last_painted = scene.index
            self.painted += 1

    def attach_session(self) -> None:
        """Time ``LogSession.frame`` of the session the loader has open now."""
        session = self.win.loader.session
        if session is None or session is self._session:
            return
        frame = session.frame

        def timed_frame(*args: Any) -> Any:
            t = time.perf_counter()
            try:
                return frame(*args)
            finally:
                self._read_s += time.perf_counter() - t

        session.frame = timed_frame
        self._session = session

    def mark(self) -> dict[str, int]:
        return {k: len(v) for k, v in self.samples.items()}

    def since(self, mark: dict[str, int]) -> dict[str, list[float]]:
        return {k: v[mark[k] :] for k, v in self.samples.items()}


def _size(widget: QtWidgets.QWidget) -> tuple[int, int]:
    return (int(widget.width()), int(widget.height()))
