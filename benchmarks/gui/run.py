"""The driver: write (or reuse) the logs, run every measure in this process's QApplication."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

from benchmarks.gui.logs import bench_log, default_cache
from benchmarks.gui.machine import _machine
from benchmarks.gui.measures import _TIMER_SPEED, Progress, _Bench
from benchmarks.gui.result import GuiBenchResult

__all__ = ["bench_gui"]


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
    """Run the GUI benchmark (see :mod:`benchmarks.gui`) in this process's QApplication
    (created if there is none; it needs a display — Xvfb under ``xvfb-run``).

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
