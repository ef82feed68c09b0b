"""``python -m benchmarks gui`` — the main window's playback frame rate and open → first frame time,
against pyqtgraph's own ceiling measured in the same run (needs the ``gui`` extra and a display)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner, verdict
from redrive.errors import ConfigError

__all__ = ["add_gui_parser"]

_DESCRIPTION = """\
Play a synthetic log (10 Hz: a 120,000-point PointCloud2, a 1280x720 rgb8 camera image with its
calibration, 50 ground-truth boxes, ego odometry; written with redrive's MCAP writer) in fresh
1600x1000 main windows: flat out (each frame shown asks for the next) in 3D and in the 2D
planview, and with the window's own playback timer at 8x. The frame rate is distinct frames the
planview painted per second. Same-run ceilings: a bare GLViewWidget + GLScatterPlotItem fed the
window's own points, a bare ImageItem fed its 2D rasters, and one fed its camera images. Then the
time from opening a ~1 GB log to its first frame (page cache warm), against one full read of it.
Per frame it also reports where the time goes: the loader thread (read + decode, build_scene), the
GUI thread (show, the planview's and the camera's paint, the window's updates), CPU time.
Targets (issue 7): >= 15 FPS in 3D, >= 30 FPS in 2D, open -> first frame <= 1 s. Run it under
Xvfb for the software-GL figure: xvfb-run -a -s "-screen 0 1600x1000x24" python -m benchmarks gui.
"""

_EPILOG = """\
examples:
  xvfb-run -a -s "-screen 0 1600x1000x24" python -m benchmarks gui
  xvfb-run -a -s "-screen 0 1600x1000x24" python -m benchmarks gui --seconds 5 --skip-big --json
  python -m benchmarks gui --cache ~/.cache/redrive-bench-gui     on a desktop; logs kept between runs

The logs (about 0.4 GB and 1 GB) are written once into the cache directory (default
$TMPDIR/redrive-bench-gui) and reused. Takes about 2 minutes with the logs cached.
"""


def _fmt(value: float | None, spec: str = ".1f") -> str:
    return "–" if value is None else format(value, spec)


def _print_report(result: Any) -> None:
    from rich.table import Table

    console = report_console(140)
    m = result.machine
    console.print(
        f"[bold]machine[/] {m['cpu']}, {m['cpus']} CPUs, {m['system']}, Python {m['python']}, "
        f"PySide6 {m['pyside6']}, pyqtgraph {m['pyqtgraph']}; Qt platform {m['qt_platform']} "
        f"{m['screen']}; GL {m['gl_renderer'] or '?'}; load average at start "
        f"{m['load_average_at_start']}"
    )
    log = result.playback_log
    w, h = log.image_size
    console.print(
        f"[bold]log[/] {log.path} ({log.file_bytes / 1e6:,.0f} MB, {log.frames} frames at 10 Hz: "
        f"{log.points:,} points, {log.boxes} boxes, {w}x{h} rgb8"
        f"{'' if log.written else ', cached'}); window {result.window_size[0]}x"
        f"{result.window_size[1]}, {result.seconds:g} s per measure"
    )
    ceiling_of = {"3d": result.ceiling("gl_scatter"), "2d": result.ceiling("raster_image")}
    table = Table(title="frame rate (distinct frames the planview painted per second)")
    for col in ("measure", "FPS", "of ceiling", "shown/s", "log frames/s", "skipped ticks"):
        table.add_column(col, justify="left" if col == "measure" else "right")
    for p in result.playback:
        ceiling = ceiling_of.get(p.view)
        table.add_row(
            f"window {p.view.upper()}, {p.mode}",
            f"[bold]{p.fps:.1f}[/]",
            "" if ceiling is None else f"{p.fps / ceiling.fps:.0%}",
            f"{p.shown_per_s:.1f}",
            _fmt(p.log_frames_per_s),
            "" if p.skipped_ticks is None else f"{p.skipped_ticks:,}",
        )
    for c in result.ceilings:
        table.add_row(f"ceiling: {c.name}", f"[bold]{c.fps:.1f}[/]", "", "", "", "")
    console.print(table)
    for c in result.ceilings:
        console.print(f"  {c.name}: {c.what}, {c.size[0]}x{c.size[1]}")
    table = Table(title="where the time goes (mean ms per call; CPU ms per frame painted)")
    for col in (
        "measure", "read", "build", "show", "planview paint", "camera paint", "updates/frame",
        "update", "GUI CPU", "process CPU", "machine busy",
    ):  # fmt: skip
        table.add_column(col, justify="left" if col == "measure" else "right")
    for p in result.playback:
        t = p.timings
        table.add_row(
            f"window {p.view.upper()}, {p.mode}",
            _fmt(t["loader_read"]["mean_ms"]),
            _fmt(t["loader_build"]["mean_ms"]),
            _fmt(t["gui_show"]["mean_ms"]),
            _fmt(t["paint_planview"]["mean_ms"]),
            _fmt(t["paint_camera"]["mean_ms"]),
            _fmt(p.updates_per_frame, ".2f"),
            _fmt(t["window_update"]["mean_ms"]),
            _fmt(p.cpu_ms_per_frame["gui_thread"]),
            _fmt(p.cpu_ms_per_frame["process"]),
            _fmt(p.machine_busy_fraction, ".0%"),
        )
    for c in result.ceilings:
        table.add_row(
            f"ceiling: {c.name}",
            "",
            "",
            _fmt(c.timings["set_data"]["mean_ms"]),
            _fmt(c.timings["paint"]["mean_ms"]),
            "",
            "1.00",
            _fmt(c.timings["window_update"]["mean_ms"]),
            _fmt(c.cpu_ms_per_frame["gui_thread"]),
            _fmt(c.cpu_ms_per_frame["process"]),
            _fmt(c.machine_busy_fraction, ".0%"),
        )
    console.print(table)
    console.print(
        "  read: LogSession.frame (loader thread); build: the rest of the request (build_scene); "
        "show: each view's show call; update: the top-level window's repaint (dirty widgets, then "
        "the window composed through GL and flushed)"
    )
    if result.open is not None:
        o = result.open
        console.print(
            f"[bold]open → first frame[/] {o.log.path.name} ({o.log.file_bytes / 1e9:.2f} GB, "
            f"{o.log.frames} frames, page cache warm): first frame shown "
            f"{', '.join(f'{s:.2f}' for s in o.first_frame_s)} s, first paint "
            f"{', '.join(f'{s:.2f}' for s in o.first_paint_s)} s (median "
            f"{o.median_first_paint_s:.2f} s); the loader's open "
            f"{', '.join(f'{s:.2f}' for s in o.open_s)} s; timeline indexed after "
            f"{', '.join(_fmt(s, '.2f') for s in o.indexed_s)} s"
        )
        console.print(
            f"[bold]baseline[/] one full read of the log: {o.full_read_s:.2f} s "
            f"({o.log.file_bytes / 1e6 / o.full_read_s:,.0f} MB/s); open → first paint is "
            f"{o.ratio:.2f}× of it"
        )
    for name, v in result.verdicts().items():
        if name == "open_first_frame_s":
            console.print(
                f"open → first frame {v['value']:.2f} s — {verdict(v['met'])} the ≤ "
                f"{v['target']:g} s target"
            )
        else:
            ceiling = (
                ""
                if v["of_ceiling"] is None
                else f" ({v['of_ceiling']:.0%} of the {v['ceiling_fps']:.1f} FPS ceiling)"
            )
            console.print(
                f"{name[-2:].upper()} {v['value']:.1f} FPS{ceiling} — {verdict(v['met'])} the "
                f"≥ {v['target']:g} FPS target"
            )


def _run_gui(args: argparse.Namespace) -> int:
    from redrive.gui.preflight import require_gui

    require_gui()
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        msg = (
            "python -m benchmarks gui needs a display: run it under Xvfb, "
            'xvfb-run -a -s "-screen 0 1600x1000x24" python -m benchmarks gui'
        )
        raise ConfigError(msg)
    if args.seconds <= 0 or args.points < 1 or args.boxes < 0:
        msg = (
            f"--seconds must be > 0 (got {args.seconds}), --points ≥ 1 (got {args.points}), "
            f"--boxes ≥ 0 (got {args.boxes})"
        )
        raise ConfigError(msg)
    import logging

    from benchmarks.gui import bench_gui

    # The main window logs every open at INFO; the report says it all.
    logging.getLogger("redrive").setLevel(logging.WARNING)

    with spinner() as progress:
        result = bench_gui(
            seconds=args.seconds,
            cache=args.cache,
            big=not args.skip_big,
            points=args.points,
            boxes=args.boxes,
            progress=progress,
        )
    if args.json:
        print_json(result.to_json())
    else:
        _print_report(result)
    return 0


def add_gui_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "gui",
        help="main-window playback FPS (3D / 2D) and open → first frame, against pyqtgraph",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--seconds",
        type=float,
        default=10.0,
        metavar="S",
        help="length of each playback measure and each ceiling (default 10)",
    )
    parser.add_argument(
        "--cache",
        type=Path,
        default=None,
        metavar="DIR",
        help="where the logs are written once and reused (default $TMPDIR/redrive-bench-gui)",
    )
    parser.add_argument(
        "--skip-big", action="store_true", help="no 1 GB log: skip the open → first frame measure"
    )
    parser.add_argument(
        "--points", type=int, default=120_000, metavar="N", help="LiDAR points (default 120000)"
    )
    parser.add_argument(
        "--boxes", type=int, default=50, metavar="N", help="ground-truth boxes (default 50)"
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of tables")
    parser.set_defaults(func=_run_gui)
