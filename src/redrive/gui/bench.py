"""``redrive bench gui``: how fast the main window plays a log and opens a big one, against
pyqtgraph's own ceiling measured in the same run (issue 7).

The logs are written by redrive's own :class:`~redrive.io.writer.McapWriter` (ROS 2 CDR, zstd
chunks, as ``redrive synth`` writes them), one frame every 100 ms (10 Hz):

=============================  ==========================================  ========================
topic                          type                                        what
=============================  ==========================================  ========================
``/lidar_top``                 ``sensor_msgs/msg/PointCloud2``             ``points`` (120,000)
                                                                           x, y, z + intensity; a
                                                                           64-beam sweep of
                                                                           :mod:`redrive.bench.
                                                                           synth_log` (ground and
                                                                           walls 10–60 m)
``/camera_front/image_raw``    ``sensor_msgs/msg/Image``                   1280 × 720 rgb8
``/camera_front/camera_info``  ``sensor_msgs/msg/CameraInfo``              fx = fy = 900 px
``/ground_truth/objects``      ``redrive_msgs/msg/GroundTruthObjectArray`` ``boxes`` (50) moving
                                                                           cars in base_link
``/ground_truth/ego_state``    ``nav_msgs/msg/Odometry``                   the ego, 10 m/s
``/tf``, ``/tf_static``        ``tf2_msgs/msg/TFMessage``                  map → base_link;
                                                                           base_link → LiDAR and
                                                                           camera (so the camera
                                                                           is calibrated and the
                                                                           window projects boxes
                                                                           and splats points)
=============================  ==========================================  ========================

A playback log of ``frames`` (100) frames and, unless skipped, a "1 GB" log of the same frames
repeated until the file is about ``big_bytes``; both are cached in a directory by their
parameters, so a rerun does not write them again.

Measures, each in a fresh :class:`~redrive.gui.mainwindow.MainWindow` of ``window_size``
(1600 × 1000), driven by a ``QApplication.processEvents`` loop (blocking for events, woken at
least every 10 ms; no sleeps):

- **flat out** (3D, then 2D after "Convert 2D Planview"): each ``frame_shown`` asks for the next
  frame (``go_to(i + 1)``, wrapping to 0 at the end), for ``seconds``.  The frame rate is the
  number of *distinct frames the planview painted* per second (a scene handed to the views but
  replaced before a paint does not count); frames handed to the views per second are reported too.
- **timer 8×**: the window's own playback (Replay at 8×: 80 log frames/s wanted, the timer skips
  ticks while a frame is on its way); frames painted per second, ticks skipped, and how fast the
  log advanced.
- **ceilings** (the same-run baselines): a bare top-level ``GLViewWidget`` with one
  ``GLScatterPlotItem`` (same camera, point size and GL options as the planview) fed the window's
  own scenes (same points and colours), ``setData`` then wait for the paint, in a loop, at the
  planview's size; a bare ``ImageItem`` in a ``ViewBox`` fed the window's 2D rasters at the 2D
  view's size; the same fed the 1280 × 720 camera images at the camera view's size.  The window's
  frame rate is reported as a fraction of its ceiling.
- **open → first frame** on the big log: wall time from ``open_path`` to the first
  ``frame_shown`` and to the planview's first paint of it (median of ``open_repeats`` fresh
  windows; the page cache is warm: the log was just written or read).  Baseline: one full read
  of the log (``for m in open_log(p).messages(): pass``).

Where the time goes (per frame, from wrappers installed on the window's objects: the window's code
is not changed): the loader thread's ``LogSession.frame`` (read + decode + assemble) and the rest
of its request (``build_scene``); the GUI thread's hand-over of the scene to the views
(``show_scene`` and friends), the planview's and the camera's paint, and the top-level window's
updates (every dirty widget painted, then the window composed through GL and flushed); the CPU
time of the GUI thread and of the process, and the machine's busy share (``/proc/stat``).
"""

from __future__ import annotations

import contextlib
import math
import os
import platform
import statistics
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from PySide6 import QtCore, QtGui, QtWidgets

from redrive.bench.synth_log import _SweepMaker
from redrive.geometry.se3 import quaternion_from_rotation_matrix
from redrive.io import open_log
from redrive.io.writer import McapWriter
from redrive.types import (
    Box3D,
    CameraInfo,
    DetectedObject,
    Image,
    ObjectClass,
    PointCloud,
    Transform,
    VehicleState,
)

__all__ = [
    "TARGET_FPS_2D",
    "TARGET_FPS_3D",
    "TARGET_OPEN_S",
    "BenchLog",
    "CeilingResult",
    "GuiBenchResult",
    "OpenResult",
    "PlaybackResult",
    "bench_gui",
    "bench_log",
    "write_bench_log",
]

TARGET_FPS_3D = 15.0
TARGET_FPS_2D = 30.0
TARGET_OPEN_S = 1.0

LIDAR_TOPIC = "/lidar_top"
CAMERA_TOPIC = "/camera_front/image_raw"
CAMERA_INFO_TOPIC = "/camera_front/camera_info"
GROUND_TRUTH_TOPIC = "/ground_truth/objects"  # as redrive.sim.synth writes it
EGO_STATE_TOPIC = "/ground_truth/ego_state"
_PERIOD_NS = 100_000_000  # 10 Hz
_START_NS = 1_700_000_000_000_000_000
_TIMER_SPEED = 8.0
_WAIT_S = 120.0

Progress = Callable[[str], None]


# -- the logs -------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class BenchLog:
    """A benchmark log: where, what, and whether this run wrote it."""

    path: Path
    frames: int
    points: int
    boxes: int
    image_size: tuple[int, int]  # width, height
    file_bytes: int
    written: bool  # False: found in the cache
    write_s: float


def write_bench_log(
    path: str | Path,
    *,
    frames: int,
    points: int = 120_000,
    boxes: int = 50,
    image_size: tuple[int, int] = (1280, 720),
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> BenchLog:
    """Write the benchmark log (see the module text) to ``path`` (atomically: a failure leaves
    nothing).  Memory stays bounded: one frame at a time."""
    if frames < 1 or points < 1 or boxes < 0:
        msg = f"frames ({frames}) and points ({points}) must be ≥ 1, boxes ({boxes}) ≥ 0"
        raise ValueError(msg)
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    sweeps = _SweepMaker(points, "xyzi", seed)
    width, height = image_size
    rows, cols = np.mgrid[0:height, 0:width]
    base_image = np.stack(
        [cols * 255 // width, rows * 255 // height, (rows + cols) * 255 // (width + height)],
        axis=2,
    ).astype(np.uint8)
    info = CameraInfo(
        width=width,
        height=height,
        k=np.array([[900.0, 0.0, width / 2], [0.0, 900.0, height / 2], [0.0, 0.0, 1.0]]),
    )
    # Optical frame: z forward (base x), x right (base −y), y down (base −z).
    base_from_optical = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    static = (
        Transform(
            parent_frame="base_link", child_frame="lidar_top", translation=np.array([0.0, 0.0, 1.8])
        ),
        Transform(
            parent_frame="base_link",
            child_frame="camera_front_optical",
            translation=np.array([1.5, 0.0, 1.5]),
            rotation=quaternion_from_rotation_matrix(base_from_optical),
        ),
    )
    angle = rng.uniform(0.0, 2 * math.pi, boxes)
    radius = rng.uniform(8.0, 55.0, boxes)
    start_xy = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)
    yaw = rng.uniform(-math.pi, math.pi, boxes)
    velocity = rng.uniform(-3.0, 3.0, (boxes, 2))
    with McapWriter(path) as out:
        out.write("/tf_static", _START_NS, static)
        for k in range(frames):
            stamp = _START_NS + k * _PERIOD_NS
            sweep = sweeps.sweep()
            cloud = PointCloud(
                xyz=np.stack([sweep["x"], sweep["y"], sweep["z"]], axis=1),
                channels={"intensity": sweep["intensity"].copy()},
            )
            xy = start_xy + velocity * (k * _PERIOD_NS / 1e9)
            objects = tuple(
                DetectedObject(
                    object_id=i,
                    object_class=ObjectClass.VEHICLE,
                    box=Box3D(
                        center=np.array([xy[i, 0], xy[i, 1], 0.8]),
                        size=np.array([4.5, 1.9, 1.6]),
                        yaw_rad=float(yaw[i]),
                    ),
                    velocity=np.array([velocity[i, 0], velocity[i, 1], 0.0]),
                    num_lidar_points=100,  # ground-truth facts: written as GroundTruthObjectArray
                    visible=True,
                )
                for i in range(boxes)
            )
            pixels = np.roll(base_image, 8 * k, axis=1) + rng.integers(
                0, 6, base_image.shape, dtype=np.uint8
            )
            ego_x = 10.0 * k * _PERIOD_NS / 1e9
            out.write(
                "/tf",
                stamp,
                (
                    Transform(
                        parent_frame="map",
                        child_frame="base_link",
                        translation=np.array([ego_x, 0.0, 0.0]),
                        stamp_ns=stamp,
                    ),
                ),
            )
            out.write(
                EGO_STATE_TOPIC,
                stamp,
                VehicleState(
                    stamp_ns=stamp,
                    position=np.array([ego_x, 0.0, 0.0]),
                    velocity=np.array([10.0, 0.0, 0.0]),
                ),
            )
            out.write(LIDAR_TOPIC, stamp, cloud, frame_id="lidar_top")
            out.write(GROUND_TRUTH_TOPIC, stamp, objects, frame_id="base_link")
            out.write(
                CAMERA_TOPIC,
                stamp,
                Image(pixels=pixels, encoding="rgb8"),
                frame_id="camera_front_optical",
            )
            out.write(CAMERA_INFO_TOPIC, stamp, info, frame_id="camera_front_optical")
            if progress is not None:
                progress(k + 1, frames)
    path = Path(path)
    return BenchLog(
        path=path,
        frames=frames,
        points=points,
        boxes=boxes,
        image_size=(width, height),
        file_bytes=path.stat().st_size,
        written=True,
        write_s=time.perf_counter() - t0,
    )


def bench_log(
    cache: str | Path,
    *,
    frames: int,
    points: int = 120_000,
    boxes: int = 50,
    image_size: tuple[int, int] = (1280, 720),
    progress: Callable[[int, int], None] | None = None,
) -> BenchLog:
    """The benchmark log of these parameters in ``cache`` (created), written only if missing."""
    cache = Path(cache)
    cache.mkdir(parents=True, exist_ok=True)
    width, height = image_size
    path = cache / f"gui-{frames}f-{points}p-{boxes}b-{width}x{height}.mcap"
    if path.is_file():
        return BenchLog(
            path=path,
            frames=frames,
            points=points,
            boxes=boxes,
            image_size=(width, height),
            file_bytes=path.stat().st_size,
            written=False,
            write_s=0.0,
        )
    return write_bench_log(
        path, frames=frames, points=points, boxes=boxes, image_size=image_size, progress=progress
    )


# -- results --------------------------------------------------------------------------------------


def _ms(samples: Sequence[float]) -> dict[str, float | int | None]:
    """Count, mean, p50, p90 and max of ``samples`` (seconds) in ms."""
    if not samples:
        return {"count": 0, "mean_ms": None, "p50_ms": None, "p90_ms": None, "max_ms": None}
    arr = np.asarray(samples, dtype=np.float64) * 1e3
    return {
        "count": len(arr),
        "mean_ms": float(arr.mean()),
        "p50_ms": float(np.percentile(arr, 50)),
        "p90_ms": float(np.percentile(arr, 90)),
        "max_ms": float(arr.max()),
    }


@dataclass(frozen=True, slots=True, kw_only=True)
class PlaybackResult:
    """One playback measure of the main window.

    Attributes:
        view: ``3d`` or ``2d``.
        mode: ``flat out`` or ``timer 8x``.
        fps: distinct frames the planview painted per second (the frame rate).
        shown_per_s: scenes handed to the views per second (``frame_shown``).
        log_frames_per_s: timer mode: how fast the log advanced (80 at 8× when nothing lags).
        skipped_ticks: timer mode: playback-timer ticks skipped while a frame was on its way.
        timings: stage → :func:`_ms` statistics of its calls: ``loader_request`` (one frame
            request in the loader thread) = ``loader_read`` (``LogSession.frame``: read, decode,
            assemble) + ``loader_build`` (``build_scene``), and ``loader_cpu``, the loader
            thread's CPU time in the request (wall ≫ CPU: it waited for the GIL or a CPU);
            ``gui_show`` (each view's
            ``show_*`` call in the GUI thread); ``paint_planview``, ``paint_camera`` (their paint
            events); ``window_update`` (the top-level window's UpdateRequest: the dirty widgets
            painted, then the window composed through GL and flushed to the X server).
        updates_per_frame: window updates per frame painted.
        window_other_ms_per_frame: window update time per frame minus the planview's and the
            camera's paints (other widgets, composing and flushing the 1600 × 1000 window).
        loader_busy_fraction: share of the wall time the loader thread spent serving requests.
        cpu_ms_per_frame: CPU time per frame painted: ``gui_thread``, ``process`` (every thread
            of this process: GUI, loader, Mesa's rasteriser threads).
        machine_busy_fraction: busy share of all the machine's CPUs (the X server included).
    """

    view: str
    mode: str
    seconds: float
    frames_shown: int
    frames_painted: int
    fps: float
    shown_per_s: float
    log_frames_per_s: float | None
    skipped_ticks: int | None
    timings: dict[str, dict[str, float | int | None]]
    updates_per_frame: float | None
    window_other_ms_per_frame: float | None
    loader_busy_fraction: float
    cpu_ms_per_frame: dict[str, float | None]
    machine_busy_fraction: float | None
    planview_size: tuple[int, int]
    camera_size: tuple[int, int]


@dataclass(frozen=True, slots=True, kw_only=True)
class CeilingResult:
    """A bare pyqtgraph item fed the window's own data as fast as it paints."""

    name: str  # gl_scatter | raster_image | camera_image
    what: str
    size: tuple[int, int]
    seconds: float
    frames: int
    fps: float
    timings: dict[str, dict[str, float | int | None]]  # set_data, paint, window_update
    cpu_ms_per_frame: dict[str, float | None]  # gui_thread, process
    machine_busy_fraction: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class OpenResult:
    """Open → first frame on the big log (each repeat a fresh window; page cache warm)."""

    log: BenchLog
    first_frame_s: list[float]  # open_path → first frame_shown
    first_paint_s: list[float]  # open_path → the planview's first paint of that frame
    open_s: list[float | None]  # the loader's open (index + static transforms + calibration)
    indexed_s: list[float | None]  # open_path → timeline fully indexed
    requests_before_first: list[int]  # frame requests the loader served up to the first frame
    full_read_s: float  # baseline: every message of the log read once

    @property
    def median_first_paint_s(self) -> float:
        return float(statistics.median(self.first_paint_s))

    @property
    def median_first_frame_s(self) -> float:
        return float(statistics.median(self.first_frame_s))

    @property
    def ratio(self) -> float:
        """Median open → first paint over the full read (≪ 1: streaming, not loading)."""
        return self.median_first_paint_s / self.full_read_s if self.full_read_s > 0 else math.nan


@dataclass(frozen=True, slots=True, kw_only=True)
class GuiBenchResult:
    """Everything :func:`bench_gui` measured."""

    machine: dict[str, str]
    seconds: float
    window_size: tuple[int, int]
    playback_log: BenchLog
    playback: list[PlaybackResult]
    ceilings: list[CeilingResult]
    open: OpenResult | None
    targets: dict[str, float] = field(
        default_factory=lambda: {
            "fps_3d": TARGET_FPS_3D,
            "fps_2d": TARGET_FPS_2D,
            "open_first_frame_s": TARGET_OPEN_S,
        }
    )

    def playback_of(self, view: str, mode: str = "flat out") -> PlaybackResult | None:
        return next((p for p in self.playback if p.view == view and p.mode == mode), None)

    def ceiling(self, name: str) -> CeilingResult | None:
        return next((c for c in self.ceilings if c.name == name), None)

    def verdicts(self) -> dict[str, dict[str, Any]]:
        """Target → measured value, target, met, and the fraction of the ceiling."""
        out: dict[str, dict[str, Any]] = {}
        for view, target, ceiling in (
            ("3d", TARGET_FPS_3D, "gl_scatter"),
            ("2d", TARGET_FPS_2D, "raster_image"),
        ):
            p = self.playback_of(view)
            c = self.ceiling(ceiling)
            if p is not None:
                out[f"fps_{view}"] = {
                    "value": p.fps,
                    "target": target,
                    "met": p.fps >= target,
                    "ceiling_fps": None if c is None else c.fps,
                    "of_ceiling": None if c is None or c.fps <= 0 else p.fps / c.fps,
                }
        if self.open is not None:
            value = self.open.median_first_paint_s
            out["open_first_frame_s"] = {
                "value": value,
                "target": TARGET_OPEN_S,
                "met": value <= TARGET_OPEN_S,
                "full_read_s": self.open.full_read_s,
                "of_full_read": self.open.ratio,
            }
        return out

    def to_json(self) -> dict[str, Any]:
        def log_json(log: BenchLog) -> dict[str, Any]:
            d = asdict(log)
            d["path"] = str(log.path)
            return d

        open_json = None
        if self.open is not None:
            open_json = {k: v for k, v in asdict(self.open).items() if k != "log"}
            open_json["log"] = log_json(self.open.log)
            open_json["median_first_frame_s"] = self.open.median_first_frame_s
            open_json["median_first_paint_s"] = self.open.median_first_paint_s
            open_json["ratio_to_full_read"] = self.open.ratio
        return {
            "machine": self.machine,
            "seconds": self.seconds,
            "window_size": list(self.window_size),
            "playback_log": log_json(self.playback_log),
            "playback": [asdict(p) for p in self.playback],
            "ceilings": [asdict(c) for c in self.ceilings],
            "open": open_json,
            "targets": self.targets,
            "verdicts": self.verdicts(),
        }


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


def _playback_result(
    *,
    view: str,
    mode: str,
    elapsed: float,
    shown: int,
    painted: int,
    advanced: int,
    skipped: int | None,
    samples: dict[str, list[float]],
    cpu: _CpuUsed,
    planview_size: tuple[int, int],
    camera_size: tuple[int, int],
) -> PlaybackResult:
    request = samples["loader_request"]
    timings = {
        "loader_request": _ms(request),
        "loader_read": _ms(samples["loader_read"]),
        "loader_build": _ms(samples["loader_build"]),
        "loader_cpu": _ms(samples["loader_cpu"]),
        "gui_show": _ms(samples["gui_show"]),
        "paint_planview": _ms(samples["paint_planview"]),
        "paint_camera": _ms(samples["paint_camera"]),
        "window_update": _ms(samples["window_update"]),
    }
    per_frame = 1e3 / painted if painted else math.nan
    other = (
        sum(samples["window_update"])
        - sum(samples["paint_planview"])
        - sum(samples["paint_camera"])
    )
    return PlaybackResult(
        view=view,
        mode=mode,
        seconds=elapsed,
        frames_shown=shown,
        frames_painted=painted,
        fps=painted / elapsed,
        shown_per_s=shown / elapsed,
        log_frames_per_s=advanced / elapsed if mode != "flat out" else None,
        skipped_ticks=skipped,
        timings=timings,
        updates_per_frame=len(samples["window_update"]) / painted if painted else None,
        window_other_ms_per_frame=other * per_frame if painted else None,
        loader_busy_fraction=sum(request) / elapsed if elapsed > 0 else 0.0,
        cpu_ms_per_frame={
            "gui_thread": cpu.gui_thread_s * per_frame if painted else None,
            "process": cpu.process_s * per_frame if painted else None,
        },
        machine_busy_fraction=cpu.machine_busy_fraction,
        planview_size=planview_size,
        camera_size=camera_size,
    )


def _gl_renderer(view: Any) -> str:
    try:
        from OpenGL import GL

        view.makeCurrent()
        text = GL.glGetString(GL.GL_RENDERER)
        view.doneCurrent()
    except Exception:  # pragma: no cover - informational only
        return ""
    return text.decode() if isinstance(text, bytes) else str(text or "")


def _machine(app: QtWidgets.QApplication) -> dict[str, str]:
    import pyqtgraph as pg
    import PySide6

    model = platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    load = ""
    with contextlib.suppress(OSError):
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    screen = app.primaryScreen()
    geometry = screen.geometry() if screen is not None else None
    return {
        "cpu": model,
        "cpus": str(os.cpu_count()),
        "system": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "numpy": np.__version__,
        "pyside6": PySide6.__version__,
        "pyqtgraph": str(pg.__version__),
        "qt_platform": app.platformName(),
        "screen": "" if geometry is None else f"{geometry.width()}x{geometry.height()}",
        "gl_renderer": "",
        # numpy's OpenBLAS threads spin after each matmul: this changes the figures (BENCHMARKS.md)
        "openblas_num_threads": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
        "load_average_at_start": load,
    }


def default_cache() -> Path:
    """Where the logs are kept between runs by default: ``$TMPDIR/redrive-bench-gui``."""
    return Path(tempfile.gettempdir()) / "redrive-bench-gui"


def bench_gui(
    *,
    seconds: float = 10.0,
    cache: str | Path | None = None,
    big: bool = True,
    points: int = 120_000,
    boxes: int = 50,
    frames: int = 100,
    big_bytes: int = 1_000_000_000,
    open_repeats: int = 3,
    timer_mode: bool = True,
    window_size: tuple[int, int] = (1600, 1000),
    progress: Progress | None = None,
) -> GuiBenchResult:
    """Run the GUI benchmark (see the module text) in this process's QApplication (created if
    there is none; it needs a display — Xvfb under ``xvfb-run``).

    Args:
        seconds: length of each playback measure and each ceiling.
        cache: directory of the logs (default :func:`default_cache`); they are reused.
        big: also write (or reuse) the big log and time open → first frame on it.
        points, boxes, frames: the playback log's LiDAR points, ground-truth boxes and frames.
        big_bytes: about how big the big log is (its frames: this over the playback log's bytes
            per frame).
        open_repeats: fresh windows opening the big log (the median is reported).
        timer_mode: also measure the window's own playback timer at 8×.
        window_size: the main window's size.
        progress: called with a line of text as the run goes.
    """
    if seconds <= 0:
        msg = f"seconds must be > 0, got {seconds}"
        raise ValueError(msg)
    from redrive.gui.app import ensure_app

    say = progress or (lambda _text: None)
    cache_dir = Path(cache) if cache is not None else default_cache()

    def write_progress(what: str) -> Callable[[int, int], None]:
        return lambda done, total: say(f"writing {what}: frame {done}/{total}")

    playback_log = bench_log(
        cache_dir,
        frames=frames,
        points=points,
        boxes=boxes,
        progress=write_progress("the playback log"),
    )
    big_log = None
    if big:
        per_frame = playback_log.file_bytes / playback_log.frames
        big_log = bench_log(
            cache_dir,
            frames=max(1, math.ceil(big_bytes / per_frame)),
            points=points,
            boxes=boxes,
            progress=write_progress(f"the {big_bytes / 1e9:g} GB log"),
        )
    app = ensure_app()
    machine = _machine(app)
    bench = _Bench(app, seconds=seconds, window_size=window_size, progress=say)
    try:
        playback = []
        for view in ("3d", "2d"):
            playback.append(bench.playback(playback_log, view, "flat out"))
            if timer_mode:
                playback.append(bench.playback(playback_log, view, f"timer {_TIMER_SPEED:g}x"))
        if len(bench.scenes_3d) < 4 or len(bench.scenes_2d) < 4:
            bench.collect_scenes(playback_log)
        ceilings = [bench.ceiling_gl(), bench.ceiling_raster()]
        camera = bench.ceiling_camera()
        if camera is not None:
            ceilings.append(camera)
        opened = bench.open_time(big_log, open_repeats) if big_log is not None else None
        machine["gl_renderer"] = bench.gl_renderer
    finally:
        bench.close()
    return GuiBenchResult(
        machine=machine,
        seconds=seconds,
        window_size=window_size,
        playback_log=playback_log,
        playback=playback,
        ceilings=ceilings,
        open=opened,
    )
