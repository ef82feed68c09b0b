"""The live feed: ROS 1 topics drawn in a window as they arrive (what the **Live** menu starts).

:class:`LiveFeed` runs what ``redrive live`` runs — scraper processes feeding shared memory
(:class:`~redrive.live.session.LiveSession`), optionally the Data Logger recording them to MCAP,
the live Sensor Dispatcher (:class:`~redrive.live.dispatcher.LiveLog`) and the frame assembler
with no lookahead — in a worker thread, and turns each frame into a
:class:`~redrive.gui.scene.Scene` there.  Scenes are never queued: while the window has not shown
the previous one, newly assembled frames are dropped (counted in :attr:`LiveFeed.skipped`), so a
slow GUI always gets the newest frame next.  It draws into any :class:`LiveWindow`.

>>> feed = LiveFeed(window, "http://127.0.0.1:11311", ["/velodyne_points"])  # doctest: +SKIP
>>> feed.start()                                                           # doctest: +SKIP
>>> feed.stop()            # scrapers stopped, recording complete, segments gone  # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import subprocess
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from PySide6 import QtCore, QtWidgets

from redrive.assembly.frames import FrameAssembler
from redrive.errors import RedriveError, TransportError
from redrive.gui.loader import FrameLoader, LogSummary, ViewOptions, build_scene
from redrive.gui.scene import Scene
from redrive.live.dispatcher import LiveLog
from redrive.live.recorder import DataLogger
from redrive.live.session import LiveSession
from redrive.types import SensorType

if TYPE_CHECKING:
    from redrive.gui.camera import CameraView
    from redrive.gui.logbox import LogBox
    from redrive.gui.planview import Planview
    from redrive.gui.session import RunData
    from redrive.gui.timeline import Timeline

__all__ = ["LiveFeed", "LiveWindow"]

logger = logging.getLogger(__name__)

_SESSIONS = iter(range(1, 1 << 30))
#: how long an ended feed waits for a dying scraper to be collected, to say it exited
_COLLECT_S = 2.0


@runtime_checkable
class LiveWindow(Protocol):
    """The window a :class:`LiveFeed` draws into and the Live menu's dialogs work on.

    :class:`~redrive.gui.mainwindow.MainWindow` is one; it imports this module, never the other
    way round (an import-linter contract in ``pyproject.toml`` keeps it so).
    """

    timeline: Timeline
    loader: FrameLoader
    planview: Planview
    camera: CameraView
    logbox: LogBox
    settings: QtCore.QSettings
    status: QtWidgets.QStatusBar
    #: the log (or live stream) shown, the run over it, the frame shown and how many there are
    summary: LogSummary | None
    run: RunData | None
    current: int
    frame_count: int
    time_origin_ns: int | None
    #: the feed drawing into the window, if any
    live_feed: LiveFeed | None

    # Qt's own: the top-level widget (the parent of the feed and of the dialogs), its title and
    # dynamic properties
    def window(self) -> QtWidgets.QWidget: ...
    def setWindowTitle(self, title: str, /) -> None: ...
    def property(self, name: str, /) -> Any: ...
    def setProperty(self, name: str, value: Any, /) -> bool: ...

    def view_options(self) -> ViewOptions:
        """What the views want drawn now."""
        ...

    def show_scene(self, scene: Scene) -> None:
        """Draw ``scene`` in every view."""
        ...

    def show_error(self, title: str, message: str) -> None:
        """Log ``message`` and show it in a (non-blocking) message box."""
        ...

    def restart_first_frame_clock(self) -> None:
        """Time the next first frame from now (logged as "first frame shown … after opening")."""
        ...

    def disconnect_live(self) -> None:
        """Stop the window's live feed, if any."""
        ...

    def refresh(self) -> None:
        """Request the current frame of the open log again."""
        ...


def _session_name() -> str:
    """Unique per feed: a restarted feed never meets the segments of the one before."""
    return f"gui-{os.getpid()}-{next(_SESSIONS)}"


def _stderr_tail(proc: subprocess.Popen[str], lines: int = 3) -> str:
    """The last lines a dead process wrote to its stderr pipe (without blocking)."""
    stream = proc.stderr
    if stream is None:
        return ""
    try:
        if not select.select([stream], [], [], 0)[0]:
            return ""
        data = os.read(stream.fileno(), 1 << 16).decode(errors="replace")
    except (OSError, ValueError):  # closed meanwhile
        return ""
    return " / ".join(data.strip().splitlines()[-lines:])


class LiveFeed(QtCore.QObject):
    """Live ROS 1 topics as scenes, from a worker thread (see the module text).

    Args:
        window_or_callbacks: a :class:`LiveWindow` (the main window) — the feed then
            draws into it (planview, camera, timeline label, plots cursor), disables its playback
            controls while live and reports failures and the recording there — or a callable
            returning the :class:`ViewOptions` to build scenes with, or None (defaults).
        uri: the ROS master, ``http://HOST:PORT``.
        topics: the ROS 1 topics to subscribe to.
        record: record the topics to this MCAP file (complete once :meth:`stop` returned).

    Signals:
        scene_ready(Scene): a frame's scene, emitted in the GUI thread; indices increase.
        failed(str): the feed could not start or broke off (no master, a scraper died, …); it
            tears itself down.
        stats(dict): once a second and at the end: ``frames`` (assembled), ``shown``,
            ``skipped``, ``rate_hz`` (shown), ``received``/``dropped``/``recorded`` by topic.
        stopped(dict): the final stats, after teardown.
    """

    scene_ready = QtCore.Signal(object)
    failed = QtCore.Signal(str)
    stats = QtCore.Signal(dict)
    stopped = QtCore.Signal(dict)

    # worker → GUI thread (queued: the feed lives in the GUI thread)
    _scene_out = QtCore.Signal(object, object)  # Scene, LogSummary | None (with the first)
    _worker_failed = QtCore.Signal(str)
    _worker_done = QtCore.Signal()

    def __init__(
        self,
        window_or_callbacks: LiveWindow | Callable[[], ViewOptions] | None,
        uri: str,
        topics: Sequence[str],
        *,
        record: str | Path | None = None,
        stats_interval_s: float = 1.0,
    ) -> None:
        target = window_or_callbacks
        window: LiveWindow | None = None
        options_fn: Callable[[], ViewOptions] = ViewOptions
        if isinstance(target, LiveWindow):
            window = target
            options_fn = window.view_options
        elif callable(target):
            options_fn = target
        super().__init__(None if window is None else window.window())
        #: the window drawn into (None: only the signals)
        self.window = window
        self._options_fn = options_fn
        self.uri = uri
        self.topics = list(topics)
        self.record = None if record is None else Path(record)
        self.session_name = _session_name()
        #: frames assembled / handed to the window / dropped because the window was still busy
        self.frames = 0
        self.shown = 0
        self.skipped = 0
        self.error: str | None = None
        self.summary: LogSummary | None = None
        #: after stop: the recording and how many messages it holds
        self.recorded_path: Path | None = None
        self.recorded_messages: dict[str, int] = {}
        self._options = ViewOptions()
        self._lock = threading.Lock()
        self._in_flight = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._worker_finished = False
        self._session: LiveSession | None = None
        self._log: LiveLog | None = None
        self._recorder: DataLogger | None = None
        self._detached = True
        self._reported = False
        self._t0 = 0.0
        self._last = (0.0, 0)  # (time, shown) at the last stats
        self._scene_out.connect(self._deliver)
        self._worker_failed.connect(self._on_failed)
        self._worker_done.connect(self._on_worker_done)
        self._timer = QtCore.QTimer(self)
        self._timer.setInterval(round(stats_interval_s * 1000))
        self._timer.timeout.connect(self._tick)

    # -- control ------------------------------------------------------------------------------

    @property
    def running(self) -> bool:
        """Started, and neither stopped nor failed."""
        return self._thread is not None and self._thread.is_alive() and not self._stop.is_set()

    def start(self) -> None:
        """Start the session in a worker thread (returns at once)."""
        if self._thread is not None:
            return
        self._options = self._options_fn()
        if self.window is not None:
            self._attach(self.window)
        self._t0 = time.perf_counter()
        self._last = (self._t0, 0)
        self._thread = threading.Thread(target=self._run, name="redrive-gui-live", daemon=True)
        self._thread.start()
        self._timer.start()
        logger.info(
            "live: connecting to %s for %s%s",
            self.uri,
            ", ".join(self.topics),
            f", recording to {self.record}" if self.record else "",
        )

    def stop(self, *, timeout_s: float = 15.0) -> None:
        """Stop the scrapers and the recorder and remove the session's shared memory; blocks until
        done (normally under a second; with a recording, until the file is complete).  A feed
        whose scrapers are still starting is waited for at most 3 s; its worker finishes the
        teardown in the background."""
        self._stop.set()
        if self.window is not None:
            self._detach(self.window)  # first: the window's own frames show again at once
        if self._thread is not None:
            # still starting (scrapers not subscribed yet): the worker finishes the teardown
            self._thread.join(timeout=timeout_s if self._session is not None else 3.0)
            if self._thread.is_alive():
                logger.warning(
                    "live: session %s still stopping in the background", self.session_name
                )
        self._finish()

    # -- worker thread ------------------------------------------------------------------------

    def _emit(self, signal: Any, *args: object) -> None:
        with contextlib.suppress(RuntimeError):  # the feed (or its window) is gone
            signal.emit(*args)

    def _run(self) -> None:
        try:
            self._serve()
        except Exception as err:  # everything ends up as `failed`, the window stays usable
            if not self._stop.is_set():
                if not isinstance(err, RedriveError | OSError):
                    logger.exception("live feed from %s", self.uri)
                text = (
                    f"{type(err).__name__}: {err}"
                    if not isinstance(err, RedriveError)
                    else str(err)
                )
                self._emit(self._worker_failed, f"live feed from {self.uri}: {text}")
        finally:
            self._teardown()
            self._worker_finished = True
            self._emit(self._worker_done)

    def _serve(self) -> None:
        t0 = time.perf_counter()
        self._session = LiveSession.ros1(self.topics, master_uri=self.uri, name=self.session_name)
        if self._stop.is_set():
            return
        if self.record is not None:
            self._recorder = DataLogger(
                self._session.specs, self.record, definitions=self._session.definition
            )
        self._log = LiveLog(self._session.specs, self._session.name, stop=self._stop)
        assembler = FrameAssembler(self._log, lookahead_ns=0)
        smap = assembler.sensor_map
        driver = smap.sensor(smap.driver or "")
        cameras = tuple(s.sensor_id for s in smap.sensors if s.sensor_type is SensorType.CAMERA)
        logger.info(
            "live: session %s subscribed in %.1f s; frames driven by %s (%s)",
            self._session.name,
            time.perf_counter() - t0,
            driver.topic,
            driver.sensor_id,
        )
        first = True
        for frame in assembler.frames():
            if self._stop.is_set():
                return
            self.frames += 1
            with self._lock:
                if self._in_flight:  # never queue: the window gets the newest frame next
                    self.skipped += 1
                    continue
                self._in_flight = True
            try:
                scene = build_scene(frame, self._options)
            except (RedriveError, ValueError) as err:
                logger.warning("live frame %d: %s", frame.index, err)
                with self._lock:
                    self._in_flight = False
                continue
            summary = None
            if first:
                first = False
                summary = LogSummary(
                    path=Path(f"live:{self.uri}"),
                    format="live",
                    topics=dict(self._log.topics),
                    driver_topic=driver.topic,
                    expected_frames=0,
                    start_ns=frame.stamp_ns,
                    end_ns=frame.stamp_ns,
                    cameras=cameras,
                    open_s=time.perf_counter() - t0,
                )
            self._emit(self._scene_out, scene, summary)
        if not self._stop.is_set():
            raise TransportError(self._ended_text())

    def _ended_text(self) -> str:
        session = self._session
        dead = []
        if session is not None:
            pairs = list(zip(session.specs, session.processes, strict=False))
            # the streams end as their writer's process dies, a moment before the kernel lets it
            # be collected: wait for that (briefly) so the message names the cause
            deadline = time.monotonic() + _COLLECT_S
            while not any(p.poll() is not None for _, p in pairs) and time.monotonic() < deadline:
                time.sleep(0.02)
            for spec, proc in pairs:
                code = proc.poll()
                if code is not None:
                    tail = _stderr_tail(proc)
                    dead.append(
                        f"the scraper of {spec.topic} exited (status {code})"
                        + (f": {tail}" if tail else "")
                    )
        return "; ".join(dead) or "the session's streams ended"

    def _teardown(self) -> None:
        """As ``redrive live``: dispatcher, then the sources, then the recorder drains and closes
        the file."""
        log, session, recorder = self._log, self._session, self._recorder
        self._log = self._session = self._recorder = None
        if log is not None:
            log.close()
        if session is not None:
            try:
                session.close()
            except Exception:
                logger.exception("live: closing session %s", session.name)
        if recorder is not None:
            try:
                self.recorded_path = recorder.stop(timeout_s=10.0)
                self.recorded_messages = dict(recorder.recorded)
            except Exception:
                logger.exception("live: finishing the recording %s", recorder.path)
            for err in recorder.errors[:5]:
                logger.warning("live recording: %s", err)

    # -- GUI thread ---------------------------------------------------------------------------

    @QtCore.Slot(object, object)
    def _deliver(self, scene: Scene, summary: LogSummary | None) -> None:
        try:
            if self._stop.is_set():
                return
            if summary is not None:
                self.summary = summary
                if self.window is not None:
                    self._first_scene(self.window, summary)
            self._options = self._options_fn()
            self.shown += 1
            if self.window is not None:
                self._show(self.window, scene)
            self.scene_ready.emit(scene)
        finally:
            with self._lock:
                self._in_flight = False

    def current_stats(self) -> dict[str, Any]:
        now = time.perf_counter()
        then, shown_then = self._last
        log, recorder = self._log, self._recorder
        return {
            "session": self.session_name,
            "uri": self.uri,
            "elapsed_s": now - self._t0 if self._t0 else 0.0,
            "frames": self.frames,
            "shown": self.shown,
            "skipped": self.skipped,
            "rate_hz": (self.shown - shown_then) / (now - then) if now > then else 0.0,
            "received": dict(log.received) if log is not None else {},
            "dropped": dict(log.dropped) if log is not None else {},
            "recorded": (
                dict(recorder.recorded) if recorder is not None else dict(self.recorded_messages)
            ),
        }

    def _tick(self) -> None:
        stats = self.current_stats()
        self._last = (time.perf_counter(), self.shown)
        self.stats.emit(stats)
        if self.window is not None and self.shown:
            self.window.status.showMessage(
                f"live {stats['rate_hz']:.1f} Hz: {self.shown} frames shown, "
                f"{self.skipped} skipped (window busy)",
                3000,
            )
        session = self._session
        if session is not None and not self._stop.is_set() and not session.alive():
            self._on_failed(f"live feed from {self.uri}: {self._ended_text()}")

    @QtCore.Slot(str)
    def _on_failed(self, text: str) -> None:
        if self.error is not None:
            return
        self.error = text
        self._stop.set()  # the worker tears down; `_worker_done` finishes here
        if self.window is not None:
            self.window.status.showMessage("live feed failed", 10_000)
            self.window.show_error("Live feed failed", text)
        else:
            logger.error("%s", text)
        self.failed.emit(text)

    @QtCore.Slot()
    def _on_worker_done(self) -> None:
        self._finish()

    def _finish(self) -> None:
        self._timer.stop()
        if self.window is not None:
            self._detach(self.window)
        if not self._worker_finished or self._reported:
            return
        self._reported = True
        if self.recorded_path is not None:
            total = sum(self.recorded_messages.values())
            per_topic = ", ".join(f"{t} {n}" for t, n in self.recorded_messages.items())
            text = f"live: recorded {total} messages ({per_topic}) to {self.recorded_path}"
            logger.info("%s", text)
            if self.window is not None:
                self.window.status.showMessage(text, 10_000)
        elif self.record is not None and self.error is not None:
            logger.warning("live: nothing recorded to %s", self.record)
        final = self.current_stats()
        logger.info(
            "live: session %s ended: %d frames assembled, %d shown, %d skipped",
            self.session_name,
            self.frames,
            self.shown,
            self.skipped,
        )
        self.stats.emit(final)
        self.stopped.emit(final)

    # -- the window -----------------------------------------------------------------------------

    def _playback_controls(self, window: LiveWindow) -> list[QtWidgets.QWidget]:
        t = window.timeline
        return [t.play_button, t.step_back, t.step_over, t.speed_box, t.slider]

    def _attach(self, window: LiveWindow) -> None:
        """Live: playback stops, its controls are disabled, the log loader's scenes are not shown."""
        self._detached = False
        window.timeline.set_playing(False)
        for widget in self._playback_controls(window):
            widget.setEnabled(False)
        window.timeline.prev_bookmark.setEnabled(False)
        window.timeline.next_bookmark.setEnabled(False)
        with contextlib.suppress(RuntimeError, TypeError):
            window.loader.scene_ready.disconnect(window.show_scene)
        window.timeline.play_toggled.connect(self._no_playback)
        window.loader.opened.connect(self._log_opened)
        window.planview.options_changed.connect(self._refresh_options)
        window.camera.camera_changed.connect(self._refresh_options)
        # the window times the first frame from opening; live, from connecting
        window.restart_first_frame_clock()

    def _detach(self, window: LiveWindow) -> None:
        if self._detached:
            return
        self._detached = True
        for sig, slot in (
            (window.timeline.play_toggled, self._no_playback),
            (window.loader.opened, self._log_opened),
            (window.planview.options_changed, self._refresh_options),
            (window.camera.camera_changed, self._refresh_options),
        ):
            with contextlib.suppress(RuntimeError, TypeError):
                sig.disconnect(slot)
        window.loader.scene_ready.connect(window.show_scene)
        for widget in self._playback_controls(window):
            widget.setEnabled(True)
        has_bookmarks = bool(window.timeline.bookmark_frames)
        window.timeline.prev_bookmark.setEnabled(has_bookmarks)
        window.timeline.next_bookmark.setEnabled(has_bookmarks)
        if self.summary is not None and window.summary is self.summary:
            # the last live frame stays on screen; there is nothing to play or step through
            window.summary = None
            window.frame_count = 0
        if window.live_feed is self and self.error is not None:
            window.live_feed = None

    def _first_scene(self, window: LiveWindow, summary: LogSummary) -> None:
        window.camera.set_cameras(summary.cameras)  # before the summary: no loader request
        window.summary = summary
        window.time_origin_ns = None  # the live stream's first frame is time zero
        window.run = None
        window.setWindowTitle(f"redrive — live {self.uri}")
        logger.info(
            "live: first frame %.2f s after connecting; cameras: %s",
            summary.open_s,
            ", ".join(summary.cameras) or "none",
        )

    def _show(self, window: LiveWindow, scene: Scene) -> None:
        window.current = scene.index
        window.frame_count = scene.index + 1
        window.timeline.set_frame_count(scene.index + 1)
        window.show_scene(scene)

    @QtCore.Slot(bool)
    def _no_playback(self, on: bool) -> None:
        if on and self.window is not None:
            self.window.timeline.set_playing(False)

    @QtCore.Slot(object)
    def _log_opened(self, _summary: object) -> None:
        """A log was opened while live: it replaces the live view."""
        window = self.window
        if window is not None and window.live_feed is self:
            window.disconnect_live()
        else:
            self.stop()
        if window is not None:
            window.refresh()  # the log's first frame may have been built while live

    @QtCore.Slot()
    def _refresh_options(self) -> None:
        self._options = self._options_fn()
