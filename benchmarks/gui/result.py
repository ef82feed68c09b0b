"""What :func:`~benchmarks.gui.bench_gui` measured: the results of each measure (a playback
result made from the probe's samples), the targets and verdicts, and the JSON."""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from benchmarks.gui.logs import BenchLog
from benchmarks.gui.probe import _CpuUsed

__all__ = [
    "TARGET_FPS_2D",
    "TARGET_FPS_3D",
    "TARGET_OPEN_S",
    "CeilingResult",
    "GuiBenchResult",
    "OpenResult",
    "PlaybackResult",
]

TARGET_FPS_3D = 15.0
TARGET_FPS_2D = 30.0
TARGET_OPEN_S = 1.0


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
