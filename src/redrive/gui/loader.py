"""The frame loader: opens logs, decodes frames and builds :class:`~redrive.gui.scene.Scene`s in
worker threads, so the GUI thread never decodes.

Requests do not queue: :meth:`FrameLoader.request` replaces whatever request is waiting, so
when playback asks faster than frames decode, the frames in between are skipped — never piled
up.  :attr:`FrameLoader.busy` tells the playback timer a frame is still on its way.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from PySide6 import QtCore

from redrive.assembly.calibration import camera_calibrations, static_transforms
from redrive.errors import RedriveError
from redrive.gui.closedloop import (
    EGO_BOX,
    RunFrames,
    driven_from_frame,
    ghost_segments,
)
from redrive.gui.map_layers import map_layers
from redrive.gui.scene import (
    CameraScene,
    ColorMode,
    Layer,
    LayerLines,
    RasterSpec,
    Scene,
    box_edge_segments,
    color_points,
    decimate,
    path_points,
    project_segments,
    rasterize_top_down,
    splat_points,
    transform_xyz,
)
from redrive.gui.session import LogSession, RunData, series_from_log
from redrive.types import (
    Box3D,
    DetectedObject,
    Frame,
    Image,
    PointCloud,
    SensorType,
    VehicleState,
)

__all__ = ["PALETTE", "FrameLoader", "LogSummary", "ViewOptions", "build_scene", "to_rgb8"]

logger = logging.getLogger(__name__)

GT_COLOR = (60, 220, 90)
EGO_COLOR = (230, 230, 230)
GHOST_COLOR = (120, 200, 255)
GHOST_ALPHA = 0.45
#: colours of the algorithms' detections, in manifest order.
PALETTE = ((255, 80, 80), (80, 160, 255), (255, 140, 0), (200, 90, 255), (0, 220, 220))
_EGO_BOX: Box3D = EGO_BOX


@dataclass(frozen=True, slots=True, kw_only=True)
class ViewOptions:
    """What the views want drawn; part of every frame request."""

    color_mode: ColorMode = ColorMode.DISTANCE
    layers: frozenset[Layer] = frozenset(Layer)
    planview_2d: bool = False
    camera: str | None = None
    max_points_3d: int = 150_000
    raster: RasterSpec = field(default_factory=RasterSpec)
    #: sensor ids drawn (the topic picker's choice); None: all of them.
    sensors: frozenset[str] | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class LogSummary:
    """What :attr:`FrameLoader.opened` tells the window about a freshly opened log."""

    path: Path
    format: str
    topics: Mapping[str, Any]
    driver_topic: str
    expected_frames: int
    start_ns: int
    end_ns: int
    cameras: tuple[str, ...]
    open_s: float
    #: sensor id → its topic
    sensor_topics: Mapping[str, str] = field(default_factory=dict)
    #: the damaged parts found while opening (skipped; more may turn up while reading)
    damage: tuple[str, ...] = ()


def to_rgb8(image: Image) -> npt.NDArray[np.uint8]:
    """An (H, W, 3) uint8 rgb copy of any supported encoding (mono16 scaled by its max)."""
    px = image.pixels
    enc = image.encoding.lower()
    if px.dtype != np.uint8:
        top = float(px.max()) or 1.0
        px = (px.astype(np.float32) * (255.0 / top)).astype(np.uint8)
    if px.ndim == 2:
        return np.repeat(px[:, :, None], 3, axis=2)
    if enc.startswith("bgr"):
        return np.ascontiguousarray(px[:, :, 2::-1])
    return np.ascontiguousarray(px[:, :, :3])


class _Static:
    """Static transforms of a log (sensor mounts), read once."""

    def __init__(self, session: LogSession) -> None:
        self.tf = static_transforms(session.log)
        self._cache: dict[str, npt.NDArray[np.float64] | None] = {}

    def base_from(self, frame_id: str) -> npt.NDArray[np.float64] | None:
        """``base_from_<frame_id>``; None when unknown or the identity (nothing to apply)."""
        if frame_id not in self._cache:
            try:
                mat = self.tf.lookup("base_link", frame_id, 0)
            except (RedriveError, LookupError):
                mat = None
            self._cache[frame_id] = None if mat is None or np.allclose(mat, np.eye(4)) else mat
        return self._cache[frame_id]


def _lidar_in_base(
    frame: Frame, static: _Static | None, shown: frozenset[str] | None = None
) -> tuple[Any, Any]:
    """(xyz float32 (N,3) in base_link, intensity or None) of the frame's (first shown) 3D
    LiDAR."""
    for data in frame.sensors.values():
        if shown is not None and data.sensor_id not in shown:
            continue
        if data.sensor_type is SensorType.LIDAR and isinstance(data.data, PointCloud):
            xyz: npt.NDArray[Any] = data.data.xyz
            known = static is not None and data.frame_id.lstrip("/") in static.tf.frames
            mat = static.base_from(data.frame_id) if static is not None else None
            if mat is not None:
                xyz = transform_xyz(mat, xyz)
            elif not known and any(data.sensor_location):
                xyz = xyz + np.asarray(data.sensor_location, dtype=np.float32)
            # aligned too: a decoded xyz may be an unaligned view of its chunk
            return np.require(xyz, np.float32, ("C", "A")), data.data.channels.get("intensity")
    return np.zeros((0, 3), np.float32), None


def build_scene(
    frame: Frame,
    options: ViewOptions,
    *,
    run: RunData | None = None,
    static: _Static | None = None,
    calibrations: Mapping[str, npt.NDArray[np.float64]] | None = None,
) -> Scene:
    """Everything the views draw for ``frame`` (pure numpy; runs in the loader thread).

    ``calibrations`` maps a camera's sensor id to its 3×4 ``image_from_base``.
    """
    xyz, intensity = _lidar_in_base(frame, static, options.sensors)
    # the run's frame shown with this log frame (the same stamp; see _run_frame)
    at = _run_frame(frame, run, options.sensors)
    driven = None if run is None or at is None or not run.closed_loop else run.ego.get(at)
    if driven is not None and run is not None and run.closed_loop_level == "log":
        # A closed loop on a recorded log: the log's cloud is in the logged ego's base_link;
        # the algorithms saw it re-expressed from the driven pose, and so does the view.
        mat = (
            None if frame.vehicle_state is None else driven_from_frame(driven, frame.vehicle_state)
        )
        if mat is not None and len(xyz):
            xyz = transform_xyz(mat, xyz).astype(np.float32)
    layers_on = options.layers
    raster = None
    keep = decimate(len(xyz), options.max_points_3d)
    if options.planview_2d:
        shown = len(xyz) if Layer.POINTS in layers_on else 0
        raster = rasterize_top_down(
            xyz[:shown], options.color_mode, options.raster, intensity=intensity
        )
        colors = np.zeros((0, 4), np.float32)  # the 2D view draws the raster, not points
        keep = slice(0, 0)
    else:
        kept_intensity = None if intensity is None else intensity[keep]
        colors = color_points(xyz[keep], options.color_mode, intensity=kept_intensity)
    layers: list[LayerLines] = []
    road = None if run is None else run.road_map
    if Layer.ROAD_MAP in layers_on and road is not None and run is not None:
        # the map in the pose the view is drawn from: the driven ego (closed loop), else the
        # run's ego (the logged one), else the log's
        pose = driven or (run.ego.get(at) if at is not None else None) or frame.vehicle_state
        if pose is not None:
            lights = run.lights.get(at, {}) if at is not None else {}
            layers += [
                LayerLines(name=m.name, color=m.color, segments=m.segments)
                for m in map_layers(road, pose, lights=lights)
            ]
    gt = frame.ground_truth
    if run is not None and at is not None and (not gt or driven is not None):
        # closed loop: the run's ground truth is in the driven ego's base_link, as the view
        gt = run.ground_truth.get(at, gt)
    if Layer.GROUND_TRUTH in layers_on and gt:
        layers.append(
            LayerLines(name="ground truth", color=GT_COLOR, segments=box_edge_segments(gt))
        )
    if run is not None and Layer.DETECTIONS in layers_on:
        for n, (name, per_frame) in enumerate(run.detections.items()):
            objects = per_frame.get(at, ()) if at is not None else ()
            labels: tuple[tuple[str, float, float, float], ...] = ()
            if Layer.TRACK_IDS in layers_on and n == len(run.detections) - 1:  # the last stage
                labels = tuple(
                    (
                        str(o.object_id),
                        float(o.box.center[0]),
                        float(o.box.center[1]),
                        float(o.box.center[2] + o.box.size[2] / 2),
                    )
                    for o in objects
                    if o.object_id >= 0  # -1: no id known (an untracked box) — no "-1" label
                )
            layers.append(
                LayerLines(
                    name=name,
                    color=PALETTE[n % len(PALETTE)],
                    segments=box_edge_segments(objects),
                    labels=labels,
                )
            )
    if Layer.EGO in layers_on:
        ego = DetectedObject(object_id=-1, box=_EGO_BOX)
        layers.append(LayerLines(name="ego", color=EGO_COLOR, segments=box_edge_segments([ego])))
    logged = None if driven is None or run is None or at is None else run.logged_ego.get(at)
    if Layer.LOGGED_EGO in layers_on and driven is not None and logged is not None:
        layers.append(
            LayerLines(
                name="logged ego",
                color=GHOST_COLOR,
                segments=ghost_segments(driven, logged),
                alpha=GHOST_ALPHA,
            )
        )
    path = None
    if run is not None and at is not None and Layer.PATH in layers_on:
        for paths in run.paths.values():
            path = path_points(paths.get(at))
            if path is not None:
                break
    cameras = {}
    if options.camera is not None and options.camera in frame.sensors:
        cameras[options.camera] = _camera_scene(
            frame, options, xyz=xyz, layers=layers, calibrations=calibrations or {}
        )
    points = xyz[keep] if Layer.POINTS in layers_on else np.zeros((0, 3), np.float32)
    return Scene(
        index=frame.index,
        stamp_ns=frame.stamp_ns,
        points=points,
        colors=colors if Layer.POINTS in layers_on else np.zeros((0, 4), np.float32),
        point_count=len(xyz),
        layers=tuple(layers),
        path=path,
        raster=raster,
        cameras=cameras,
        pose=_pose(frame, None if run is None or at is None else run.ego.get(at), driven),
    )


def _run_frame(frame: Frame, run: RunData | None, shown: frozenset[str] | None) -> int | None:
    """The run frame drawn over ``frame``: the one of the same stamp — except in a sensor-level
    closed loop, whose recording stamps a LiDAR sweep at its start while the algorithms' frame
    at t had the sweep that *ended* at t: there, the first run frame after the sweep's start,
    one LiDAR period later (the frame whose algorithms saw that cloud)."""
    if run is None:
        return None
    if run.closed_loop_level == "sensor":
        for data in frame.sensors.values():
            if shown is not None and data.sensor_id not in shown:
                continue
            if data.sensor_type is SensorType.LIDAR:
                # (the log's rate is estimated from its counts, not exact: it only bounds the
                # lag, the frame is the first one after the sweep's start)
                rate = data.frame_rate_hz
                within = round(1.5e9 / rate) if rate > 0 else None
                return run.frame_after(data.stamp_ns, within_ns=within)
    return run.frame_at(frame.stamp_ns)


def _pose(
    frame: Frame, run_ego: VehicleState | None, driven: VehicleState | None = None
) -> tuple[float, float, float] | None:
    """The ego pose of the frame: a closed loop's driven ego, else the log's, else the run's."""
    state = driven if driven is not None else frame.vehicle_state
    state = state if state is not None else run_ego
    if state is None:
        return None
    return (float(state.position[0]), float(state.position[1]), float(state.heading_rad))


def _camera_scene(
    frame: Frame,
    options: ViewOptions,
    *,
    xyz: npt.NDArray[np.float32],
    layers: list[LayerLines],
    calibrations: Mapping[str, npt.NDArray[np.float64]],
) -> CameraScene:
    sensor_id = options.camera or ""
    data = frame.sensors[sensor_id].data
    assert isinstance(data, Image)
    image = to_rgb8(data)
    mat = calibrations.get(sensor_id)
    segments: dict[str, tuple[tuple[int, int, int], npt.NDArray[np.float64]]] = {}
    if mat is not None:
        if Layer.POINTS in options.layers:
            image = image.copy() if not image.flags.writeable else image
            splat_points(image, mat, xyz)
        for layer in layers:
            if layer.name not in ("ego", "logged ego", "road map"):
                segments[layer.name] = (layer.color, project_segments(mat, layer.segments))
    return CameraScene(
        sensor_id=sensor_id, image=image, segments=segments, calibrated=mat is not None
    )


class FrameLoader(QtCore.QObject):
    """Opens a log and serves frame requests from a worker thread (signals carry the results)."""

    opened = QtCore.Signal(object)  # LogSummary
    open_failed = QtCore.Signal(str, str)  # path, message
    indexed = QtCore.Signal(int, bool)  # driver samples known so far, done
    series_ready = QtCore.Signal(object)  # redrive.gui.session.Series
    scene_ready = QtCore.Signal(object)  # Scene
    frame_failed = QtCore.Signal(int, str)  # index, message

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self._cond = threading.Condition()
        self._open_path: Path | RunData | None = None
        self._wanted: tuple[int, ViewOptions] | None = None
        self._stop = False
        self._busy = False
        self.session: LogSession | None = None
        #: an object-level run's frames, played from its tables (instead of a log's)
        self.run_frames: RunFrames | None = None
        self.run: RunData | None = None
        self._static: _Static | None = None
        self._calibrations: dict[str, npt.NDArray[np.float64]] = {}
        self._generation = 0
        self._closing = threading.Event()
        self._index_thread: threading.Thread | None = None
        self._thread = threading.Thread(target=self._loop, name="redrive-gui-loader", daemon=True)
        self._thread.start()

    @property
    def busy(self) -> bool:
        """A request is waiting or being served."""
        with self._cond:
            return self._busy or self._wanted is not None or self._open_path is not None

    def open(self, path: str | Path) -> None:
        with self._cond:
            self._open_path = Path(path)
            self._wanted = None
            self._cond.notify()

    def open_run_frames(self, run: RunData) -> None:
        """Play ``run``'s own frames (its stored ego and ground truth; no sensor data) — an
        object-level closed-loop run, which has no log to play."""
        with self._cond:
            self._open_path = run
            self.run = run
            self._wanted = None
            self._cond.notify()

    def set_run(self, run: RunData | None) -> None:
        with self._cond:
            self.run = run

    def request(self, index: int, options: ViewOptions) -> None:
        """Ask for frame ``index``; replaces a request that is still waiting."""
        with self._cond:
            self._wanted = (index, options)
            self._cond.notify()

    def close(self) -> None:
        """Stop both worker threads (before the QObject and the QApplication go away: a thread
        still reading at interpreter exit crashes it)."""
        self._closing.set()
        with self._cond:
            self._stop = True
            self._cond.notify()
        self._thread.join(timeout=5.0)
        if self._index_thread is not None:
            self._index_thread.join(timeout=5.0)
        if self.session is not None:
            self.session.close()

    # -- worker side ----------------------------------------------------------------------------

    def _loop(self) -> None:
        while True:
            with self._cond:
                while not self._stop and self._open_path is None and self._wanted is None:
                    self._cond.wait()
                if self._stop:
                    return
                path, self._open_path = self._open_path, None
                wanted = None if path is not None else self._wanted
                self._wanted = None
                self._busy = True
            try:
                if path is not None:
                    self._do_open(path)
                elif wanted is not None:
                    self._do_frame(*wanted)
            finally:
                with self._cond:
                    self._busy = False

    def _do_open(self, path: Path | RunData) -> None:
        t0 = time.perf_counter()
        if self.session is not None:
            self.session.close()
            self.session = None
        self.run_frames = None
        self._generation += 1
        if isinstance(path, RunData):
            self._open_run_frames(path, t0)
            return
        try:
            session = LogSession(path)
            static = _Static(session)
            calibrations = _calibrations(session)
        except (RedriveError, OSError) as err:
            self.open_failed.emit(str(path), str(err))
            return
        except Exception as err:  # a reader bug must not kill the loader thread
            logger.exception("opening %s", path)
            self.open_failed.emit(str(path), f"{type(err).__name__}: {err}")
            return
        self.session, self._static, self._calibrations = session, static, calibrations
        smap = session.assembler.sensor_map
        cameras = tuple(s.sensor_id for s in smap.sensors if s.sensor_type is SensorType.CAMERA)
        self.opened.emit(
            LogSummary(
                path=path,
                format=session.log.format,
                topics=dict(session.log.topics),
                driver_topic=session.driver_topic,
                expected_frames=session.expected_frames,
                start_ns=session.log.start_ns,
                end_ns=session.log.end_ns,
                cameras=cameras,
                open_s=time.perf_counter() - t0,
                sensor_topics={s.sensor_id: s.topic for s in smap.sensors},
                damage=tuple(str(d) for d in getattr(session.log, "damage_report", ())),
            )
        )
        if self._index_thread is not None:
            self._index_thread.join(timeout=5.0)  # the previous log's: its generation is stale
        self._index_thread = threading.Thread(
            target=self._index,
            args=(session, self._generation),
            daemon=True,
            name="redrive-gui-index",
        )
        self._index_thread.start()

    def _open_run_frames(self, run: RunData, t0: float) -> None:
        frames = RunFrames(run.stamps_ns, ego=run.ego, ground_truth=run.ground_truth)
        self.run_frames, self._static, self._calibrations = frames, None, {}
        stamps = [run.stamps_ns[i] for i in frames.indices]
        self.opened.emit(
            LogSummary(
                path=run.path,
                format="run",
                topics={},
                driver_topic="",
                expected_frames=len(frames),
                start_ns=stamps[0] if stamps else 0,
                end_ns=stamps[-1] if stamps else 0,
                cameras=(),
                open_s=time.perf_counter() - t0,
            )
        )
        self.indexed.emit(len(frames), True)

    def _index(self, session: LogSession, generation: int) -> None:
        # RuntimeError: the window (and this QObject) went away while indexing.
        with contextlib.suppress(RuntimeError):
            try:
                for count in session.index(stop=self._closing):
                    if generation != self._generation or self._closing.is_set():
                        return
                    self.indexed.emit(count, session.indexed)
                series = series_from_log(session.path, session.assembler, stop=self._closing)
                if generation == self._generation and not self._closing.is_set():
                    self.series_ready.emit(series)
            except (RedriveError, OSError) as err:
                logger.warning("indexing %s stopped: %s", session.path, err)
                self.indexed.emit(len(session.driver_times_ns), True)

    def _do_frame(self, index: int, options: ViewOptions) -> None:
        session = self.session
        if session is None and self.run_frames is None:
            return
        try:
            if session is None:
                assert self.run_frames is not None
                frame = self.run_frames.frame(index)
            else:
                frame = session.frame(index)
            if session is not None and session.log.capabilities.calibration_per_frame:
                self._calibrations = _calibrations(session, stamp_ns=frame.stamp_ns)
            scene = build_scene(
                frame, options, run=self.run, static=self._static, calibrations=self._calibrations
            )
        except IndexError:
            self.frame_failed.emit(index, f"frame {index} is past the end of the log")
            return
        except (RedriveError, ValueError) as err:
            self.frame_failed.emit(index, f"frame {index}: {err}")
            return
        except Exception as err:
            logger.exception("frame %d", index)
            self.frame_failed.emit(index, f"frame {index}: {type(err).__name__}: {err}")
            return
        self.scene_ready.emit(scene)


def _calibrations(
    session: LogSession, *, stamp_ns: int | None = None
) -> dict[str, npt.NDArray[np.float64]]:
    """Camera sensor id → 3×4 image_from_base, from the log's camera_info + tf_static (KITTI:
    of the frame at ``stamp_ns``, its calibration changes from frame to frame)."""
    by_topic = {s.topic: s.sensor_id for s in session.assembler.sensor_map.sensors}
    out: dict[str, npt.NDArray[np.float64]] = {}
    try:
        found = camera_calibrations(session.log, stamp_ns=stamp_ns)
    except RedriveError as err:
        logger.warning("camera calibration of %s: %s", session.path, err)
        return out
    for topic, calib in found.items():
        if topic in by_topic:
            out[by_topic[topic]] = calib.image_from_base()
    return out
