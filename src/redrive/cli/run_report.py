"""What ``redrive run`` prints: the progress lines when piped, the run's table of algorithms with
its speed and warnings, and a closed loop's deviation and collision lines."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

__all__ = ["ProgressLines", "print_deviation", "print_run_report"]


class ProgressLines:
    """Progress as plain lines when stderr is not a terminal (a pipe, a CI log, a batch
    worker): one line at every tenth of the frames (every 100 frames when the total is not
    known), with frames/s and the estimated time left."""

    def __init__(self, name: str, stream: Any) -> None:
        self.name, self.stream = name, stream
        self.total: int | None = None
        self._next = 0

    def start(self, total: int | None) -> None:
        self.total = total
        self._next = self._step()

    def _step(self) -> int:
        return max(1, self.total // 10) if self.total else 100

    def update(self, done: int, elapsed_s: float) -> None:
        if done < self._next and done != self.total:
            return
        while self._next <= done:
            self._next += self._step()
        rate = done / elapsed_s if elapsed_s > 0 else 0.0
        of = f"/{self.total}" if self.total else ""
        eta = (
            f", ETA {(self.total - done) / rate:.0f} s"
            if self.total and rate > 0 and done < self.total
            else ""
        )
        print(
            f"{self.name}: {done}{of} frames, {rate:.1f} frames/s{eta}",
            file=self.stream,
            flush=True,
        )


def print_run_report(report: Any, out: Path, *, live: bool = False) -> None:
    """The run's table of algorithms and its speed; ``live``: wall time only, no real-time factor
    (a live session's log stamps say nothing of how long it ran)."""
    from rich.console import Console
    from rich.table import Table

    from redrive.assembly.non_finite import NON_FINITE_WARN_FRACTION

    console = Console(width=None if sys.stdout.isatty() else 120)
    table = Table(title=f"run {out}", title_justify="left")
    table.add_column("algorithm")
    table.add_column("stage")
    for col in ("ok", "err", "t/o", "outputs", "mean ms", "p95 ms", "max ms"):
        table.add_column(col, justify="right")
    for a in report.algorithms:
        table.add_row(
            a.name,
            a.stage,
            str(a.ok),
            str(a.error),
            str(a.timeout),
            str(a.outputs),
            f"{a.latency_mean_ms:.2f}",
            f"{a.latency_p95_ms:.2f}",
            f"{a.latency_max_ms:.2f}",
        )
    console.print(table)
    # one frame (the Ouster bag's single scan) spans no log time: no real-time factor to give
    pace = (
        f"{report.realtime_factor:.1f}x real time ({report.log_span_s:.1f} s of log)"
        if report.log_span_s > 0
        else "one stamp of log, so no real-time factor"
    )
    speed = (
        f"{report.frames} frames in {report.wall_s:.1f} s of wall time: "
        f"{report.frames_per_s:.1f} frames/s"
        if live
        else f"{report.frames} frames in {report.wall_s:.1f} s: {report.frames_per_s:.1f} "
        f"frames/s, {pace}"
    )
    console.print(speed + (f", {report.late_frames} late" if report.late_frames else ""))
    damage = getattr(report, "damage", ())
    if damage:
        known = sum(d.messages_lost or 0 for d in damage)
        unknown = any(d.messages_lost is None for d in damage)
        console.print(
            f"[bold yellow]the log is damaged: {len(damage)} part{'s' if len(damage) != 1 else ''} "
            f"skipped ({known} messages lost{' and an unknown number more' if unknown else ''}); "
            "the run covers the intact part — `redrive info LOG` lists the damage, --strict "
            "refuses damaged logs",
            highlight=False,
        )
    for name, why in getattr(report, "skipped", {}).items():
        console.print(
            f"[bold yellow]skipped {name}, {why}; the other stages ran (--strict refuses a "
            "pipeline the log cannot feed whole)",
            highlight=False,
        )
    for topic, counts in sorted(getattr(report, "non_finite_points", {}).items()):
        if not counts.get("clouds_over"):
            continue
        console.print(
            f"[bold yellow]{topic}: {counts['clouds_over']} of {counts['clouds']} clouds had more "
            f"than {NON_FINITE_WARN_FRACTION:.0%} NaN or infinite points[/bold yellow] (up to "
            f"{counts['max_fraction']:.0%} in one; {counts['non_finite']:,} of {counts['points']:,} "
            "points in all): the algorithms got them as they are — the manifest's summary "
            "counts them (non_finite_points)",
            highlight=False,
        )
    for name, count in sorted(report.missing_inputs.items()):
        console.print(
            f"[bold yellow]{count} of {report.frames} frames had no {name} within the tolerance"
            "[/bold yellow] (stale or absent there; the frames table's missing_inputs says which "
            "frames; `--sensor-map` sets tolerance_ms)",
            highlight=False,
        )
    if report.failed_frames:
        console.print(
            f"[bold red]{report.failed_frames} of {report.frames} frames had a failed step[/bold red]"
            " (the err and t/o columns; each failure is stored in the steps table)"
        )
    for a in report.algorithms:
        if a.first_error:
            console.print(f"[yellow]{a.name}: first failure at {a.first_error}[/yellow]")
    console.print(f"results: {out}  (manifest.json, *.parquet; `redrive export {out}`)")


def print_deviation(out: Path) -> None:
    """One line: how many frames the driven ego was past the deviation thresholds."""
    import math

    from redrive.results import open_run

    manifest = open_run(out).manifest
    paced_by = manifest.closed_loop.get("paced_by")
    if paced_by:
        print(f"frames paced by {paced_by}: {manifest.closed_loop.get('pace_reason', '')}")
    summary = manifest.summary
    if summary is None or "deviated_frames" not in summary.closed_loop:
        return
    dev = dict(summary.closed_loop)
    worst = dev.get("max_deviation_m")
    print(
        f"deviation from the logged ego: {dev['deviated_frames']} of {summary.frames} "
        f"frames past {dev['deviation_threshold_m']:g} m / "
        f"{math.degrees(dev['deviation_threshold_rad']):g}°"
        + (f", at most {worst:.2f} m" if worst is not None else "")
        + (
            f" (first: frame {dev['first_deviated_frame']})"
            if dev.get("first_deviated_frame") is not None
            else ""
        )
    )
    if dev.get("collision_frames"):
        print(
            f"collisions: the ego touched an object in {dev['collision_frames']} frame(s), "
            f"first in frame {dev['first_collision_frame']}"
        )
    stopped = dev.get("stopped")
    if isinstance(stopped, dict):
        print(f"stopped: {stopped.get('detail', 'at the first collision')}")
