"""The one progress display: a rich bar with counts, rate and ETA, drawn only on a terminal.

``redrive run``, ``batch``, ``synth``, ``convert`` and ``bench read`` show their long work
through :class:`ProgressBar`::

    with ProgressBar("converting", unit="messages") as bar:
        for done in ...:
            bar.update(done, total=total)

It draws on stderr (stdout stays for results and JSON) and only when stderr is a terminal:
piped into a file or a CI log it is silent (``quiet=True`` silences it anywhere); the bar is
removed when the work ends.  The line reads ``LABEL ━━━━ DONE/TOTAL UNIT · FIELDS · RATE · ETA``;
the rate (``UNIT/s`` over the time since the bar started) and the ETA (what is left at that
rate) are worked out unless the caller gives its own (a batch knows its workers).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, TextIO

if TYPE_CHECKING:
    from rich.console import Console
    from rich.progress import Progress, TaskID

__all__ = ["ProgressBar", "fmt_s", "is_terminal"]


def fmt_s(seconds: float | None) -> str:
    """``42s``, ``3m05s``; ``?`` when not known yet."""
    if seconds is None:
        return "?"
    whole = round(seconds)
    return f"{whole // 60}m{whole % 60:02d}s" if whole >= 60 else f"{whole}s"


def is_terminal(stream: TextIO | None = None) -> bool:
    """Whether ``stream`` (stderr by default) is a terminal a bar can be drawn on."""
    stream = stream or sys.stderr
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # a closed or file-like stream
        return False


class ProgressBar:
    """One bar on stderr (or ``console``) while a piece of work runs.

    Args:
        label: what is being done (bold, before the bar).
        total: how much there is (None: not known yet; give it to :meth:`update` later).
        unit: what is counted ("frames", "messages", "s", "cells").
        decimals: digits after the point of the counts.
        fields: names of extra text fields shown after the counts (:meth:`update` sets them).
        show_rate: show ``UNIT/s``.
        quiet: draw nothing.
        console: draw on this console (if it is a terminal, or forced to be one); default a
            console on stderr, drawn only if stderr is a terminal.
    """

    def __init__(
        self,
        label: str,
        *,
        total: float | None = None,
        unit: str = "",
        decimals: int = 0,
        fields: Sequence[str] = (),
        show_rate: bool = True,
        quiet: bool = False,
        console: Console | None = None,
    ) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn

        self.unit, self.decimals, self.show_rate = unit, decimals, show_rate
        shown_on = console.is_terminal if console is not None else is_terminal()
        self.enabled = not quiet and shown_on
        parts = ["{task.fields[count]}", *(f"{{task.fields[{f}]}}" for f in fields)]
        if show_rate:
            parts.append("{task.fields[rate]}")
        parts.append("ETA {task.fields[eta]}")
        self.progress: Progress = Progress(
            TextColumn(f"[bold]{label}"),
            BarColumn(),
            TextColumn(" · ".join(parts)),
            console=console or Console(stderr=True),
            transient=True,
            disable=not self.enabled,
        )
        self.task: TaskID = self.progress.add_task(label, total=total, count="", rate="", eta="?")
        blank: dict[str, Any] = dict.fromkeys(fields, "")
        self.progress.update(self.task, **blank)
        self._started = time.perf_counter()
        self._total = total
        self._done = 0.0
        self._shown = False

    def __enter__(self) -> ProgressBar:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.progress.stop()

    def start(self, total: float | None = None) -> None:
        """Show the bar; the rate and ETA count from now (``total``: now known)."""
        self._started = time.perf_counter()
        if total is not None:
            self.update(0, total=total)
        if not self._shown:
            self._shown = True
            self.progress.start()

    def _num(self, value: float) -> str:
        return f"{value:.{self.decimals}f}"

    def update(
        self,
        completed: float,
        *,
        total: float | None = None,
        rate: str | None = None,
        eta_s: float | None = None,
        **fields: Any,
    ) -> None:
        """``completed`` of ``total`` done (``total`` None: as before); ``rate`` and ``eta_s``
        replace the worked-out ones; ``fields`` set the extra text fields."""
        if total is not None:
            self._total = total
        self._done = completed
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self._started
        per_s = completed / elapsed if elapsed > 0 else 0.0
        of = f"/{self._num(self._total)}" if self._total is not None else ""
        count = f"{self._num(completed)}{of} {self.unit}".rstrip()
        if rate is None:
            rate = f"{per_s:.1f} {self.unit}/s" if per_s > 0 else f"? {self.unit}/s"
        if eta_s is None and self._total is not None and per_s > 0:
            eta_s = max(self._total - completed, 0.0) / per_s
        self.progress.update(
            self.task,
            completed=completed,
            total=self._total,
            count=count,
            rate=rate,
            eta=fmt_s(eta_s),
            **fields,
        )

    def print(self, text: str) -> None:
        """A line above the bar (stays when the bar goes; nothing when the bar is not drawn)."""
        if self.enabled:
            self.progress.console.print(text)
