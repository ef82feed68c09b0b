"""What ``redrive batch`` shows while it works: one bar over the batch on a terminal (cells
done / failed / running, frames/s, ETA), plain lines on stderr otherwise."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, TextIO

from redrive.output.progress import ProgressBar, fmt_s, is_terminal

if TYPE_CHECKING:
    from rich.console import Console

    from redrive.batch import BatchProgress, CellRecord

__all__ = ["BatchBar", "BatchLines", "batch_progress", "fmt_s"]


def _rate(counts: BatchProgress) -> str:
    rate = counts.frames_per_s()
    return "? frames/s" if rate is None else f"{rate:.1f} frames/s"


class BatchLines:
    """One line per cell event (for output that is not a terminal, such as a CI log)."""

    def __init__(self, workers: int, stream: TextIO | None = None) -> None:
        self.workers = workers
        self.stream = stream

    def __call__(self, event: str, record: CellRecord, counts: BatchProgress) -> None:
        line = f"batch: {event:11s} {record.cell_id}"
        if event in ("complete", "failed") and record.wall_s is not None:
            line += f" ({record.wall_s:.1f} s"
            line += f", {record.step_errors} failed steps)" if record.step_errors else ")"
        if event == "failed" and record.error:
            line += f": {record.error.splitlines()[0]}"
        line += (
            f" | {counts.finished}/{counts.total} done ({counts.failed} failed, {counts.skipped} "
            f"skipped), {counts.running} running, {_rate(counts)}, "
            f"ETA {fmt_s(counts.eta_s(self.workers))}"
        )
        print(line, file=self.stream or sys.stderr, flush=True)


class BatchBar:
    """The one progress bar (:class:`redrive.output.progress.ProgressBar`) over the whole batch,
    redrawn at every cell event; failed cells are also printed above it as they happen, so
    their reasons stay on screen."""

    def __init__(self, workers: int, total: int, console: Console | None = None) -> None:
        self.workers = workers
        self.bar = ProgressBar(
            "batch", total=total, unit="cells", fields=("states",), console=console, quiet=False
        )
        self.progress = self.bar.progress
        self.bar.update(0, states="0 running", rate="? frames/s")

    def __enter__(self) -> BatchBar:
        self.bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.__exit__(*exc)

    def __call__(self, event: str, record: CellRecord, counts: BatchProgress) -> None:
        if event == "failed":
            reason = (record.error or "").splitlines()[0] if record.error else "no reason recorded"
            self.progress.console.print(f"[red]failed[/] {record.cell_id}: {reason}")
        states = f"{counts.done} done, {counts.failed} failed, {counts.running} running"
        if counts.skipped:
            states += f", {counts.skipped} skipped"
        self.bar.update(
            counts.finished,
            states=states,
            rate=_rate(counts),
            eta_s=counts.eta_s(self.workers),
        )


def batch_progress(
    workers: int, total: int, *, quiet: bool, stream: TextIO | None = None
) -> BatchBar | BatchLines | None:
    """The bar on a terminal, lines when ``stream`` (stderr by default) is not one, nothing when
    ``quiet``."""
    if quiet:
        return None
    stream = stream or sys.stderr
    if is_terminal(stream):
        return BatchBar(workers, total)
    return BatchLines(workers, stream)
