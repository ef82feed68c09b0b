"""``redrive live --record`` without a pipeline: record topics as ``rosbag record`` does."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

__all__ = ["parse_size", "record_only", "warn_orphans"]

_STATUS_EVERY_S = 5.0  # plain lines when stderr is not a terminal


def parse_size(text: str, *, option: str) -> int:
    """``100M`` → bytes (K, M, G: KiB, MiB, GiB; no suffix: bytes)."""
    from redrive.errors import ConfigError

    scale = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}.get(text[-1:].upper(), 1)
    number = text[:-1] if scale > 1 else text
    try:
        value = int(float(number) * scale)
    except ValueError as err:
        msg = f"{option} {text!r}: expected a size such as 500M, 2G or 1048576 (bytes)"
        raise ConfigError(msg) from err
    if value <= 0:
        msg = f"{option} {text!r}: must be more than 0 bytes"
        raise ConfigError(msg)
    return value


def warn_orphans(record: Path, console: Any) -> None:
    """Tell about unfinished recordings a killed session left in ``record``'s folder."""
    from redrive.io.partfiles import orphaned_parts, part_target

    for part in orphaned_parts(record.parent):
        fixed = part.with_name(f"recovered-{part_target(part) or 'recording.mcap'}")
        console.print(
            f"[yellow]found {part}: an unfinished recording left by a session that was killed; "
            f"recover what it holds with `redrive repair {part} -o {fixed}`, then delete it[/]",
            highlight=False,
            soft_wrap=True,
        )


class _Status:
    """A line per topic: a live table on a terminal (≤ 1 Hz), plain lines every few s when piped."""

    def __init__(self, recording: Any, console: Any) -> None:
        self.recording = recording
        self.console = console
        self.tty = console.is_terminal
        self._last: dict[str, tuple[float, int, int]] = {}
        self._printed_s = time.monotonic()
        self._live: Any = None
        if self.tty:
            from rich.live import Live

            self._live = Live(self._table(), console=console, refresh_per_second=1, transient=True)
            self._live.start()

    def _rows(self) -> list[tuple[str, str, str, str, str]]:
        now = time.monotonic()
        rows = []
        for s in self.recording.status():
            then, count, size = self._last.get(s.topic, (self.recording.started_s, 0, 0))
            dt = max(now - then, 1e-3)
            rows.append(
                (
                    s.topic,
                    f"{(s.recorded - count) / dt:.1f}",
                    f"{(s.recorded_bytes - size) / dt / 1e6:.2f}",
                    str(s.recorded),
                    str(s.dropped),
                )
            )
            self._last[s.topic] = (now, s.recorded, s.recorded_bytes)
        return rows

    def _table(self) -> Any:
        from rich.table import Table

        table = Table(title=f"recording, {self.recording.wall_s:.0f} s", title_justify="left")
        for col in ("topic", "msg/s", "MB/s", "recorded", "dropped"):
            table.add_column(col, justify="left" if col == "topic" else "right")
        for row in self._rows():
            table.add_row(*row)
        return table

    def update(self) -> None:
        now = time.monotonic()
        if self.tty:
            if now - self._printed_s >= 1.0:
                self._printed_s = now
                self._live.update(self._table())
            return
        if now - self._printed_s >= _STATUS_EVERY_S:
            self._printed_s = now
            for topic, rate, mbs, recorded, dropped in self._rows():
                self.console.print(
                    f"recording {self.recording.wall_s:.0f} s: {topic} {rate} msg/s "
                    f"{mbs} MB/s, {recorded} recorded, {dropped} dropped",
                    highlight=False,
                )

    def close(self) -> None:
        if self._live is not None:
            self._live.stop()


def record_only(args: argparse.Namespace, master: str) -> int:
    """Record the selected topics (or a replay/synthetic source) until a stop condition."""
    from rich.console import Console

    from redrive.cli.live_foxglove import open_feed
    from redrive.errors import ConfigError
    from redrive.live.record import RecordRequest, record_live
    from redrive.live.recording import TopicSelection
    from redrive.live.run import LiveSource, SourceKind

    console = Console(stderr=True)
    if args.frames is not None:
        msg = (
            "--frames counts the frames of a pipeline; a recording without one stops on "
            "--duration, --max-size, --idle-timeout or Ctrl-C"
        )
        raise ConfigError(msg)
    selection = TopicSelection(
        topics=tuple(args.topics or ()),
        all=args.all,
        regex=tuple(args.regex or ()),
        exclude=args.exclude,
    )
    kind: SourceKind
    if args.replay is not None:
        kind = "replay"
    elif args.synthetic is not None:
        kind = "synthetic"
    else:
        kind = "ros2" if getattr(args, "ros2", False) else "ros1"
        if selection.empty:
            print(
                "redrive live: name topics, or give -a/--all or -e/--regex (or "
                "--replay/--synthetic)"
            )
            return 2
    request = RecordRequest(
        source=LiveSource(
            kind=kind,
            topics=tuple(args.topics or ()) if kind in ("replay", "synthetic") else (),
            target=args.replay if args.replay is not None else args.synthetic,
            master_uri=master,
            domain_id=args.domain,
            rate=args.rate,
            duration_s=args.duration,
            capacities=args.capacities,
            wait_s=args.wait,
        ),
        path=args.record,
        selection=selection,
        duration_s=args.duration,
        max_size_bytes=None
        if args.max_size is None
        else parse_size(args.max_size, option="--max-size"),
        idle_timeout_s=args.idle_timeout,
        split_size_bytes=None
        if args.split_size is None
        else parse_size(args.split_size, option="--split-size"),
        split_duration_s=args.split_duration,
        compression=args.compression,
    )
    warn_orphans(args.record, console)
    stop = threading.Event()
    handlers: dict[int, Any] = {}
    status: list[_Status] = []
    feeds: list[Any] = []

    def on_session(session: Any) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            handlers[sig] = signal.signal(sig, lambda *_: stop.set())

    def on_tick(recording: Any) -> None:
        if not status:
            console.print(
                f"live: recording {len(recording.session.specs)} topic(s) from "
                f"{request.source.describe()} to {args.record}; Ctrl-C stops",
                highlight=False,
            )
            status.append(_Status(recording, console))
        status[0].update()

    def follower(name: str, specs: Any) -> Any:
        feeds.append(open_feed(args, name, specs))
        return feeds[-1]

    try:
        report = record_live(
            request,
            stop=stop,
            on_session=on_session,
            on_tick=on_tick,
            follower=follower,
            say=lambda text: console.print(f"[yellow]{text}[/]", highlight=False, soft_wrap=True),
            stop_reason="Ctrl-C",
        )
    finally:
        if status:
            status[0].close()
        for sig, previous in handlers.items():
            signal.signal(sig, previous)
    _summary(report)
    if feeds and feeds[0] is not None:
        print(feeds[0].summary())
    return recording_status(report.failure)


def _summary(report: Any) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=None if sys.stdout.isatty() else 120)
    rows = report.topics
    table = Table(
        title=f"recorded {report.wall_s:.1f} s of wall time; stopped: {report.reason}",
        title_justify="left",
    )
    for col in ("topic", "type", "messages", "MB", "dropped"):
        table.add_column(col, justify="left" if col in ("topic", "type") else "right")
    for s in rows:
        table.add_row(
            s.topic, s.msg_type, str(s.recorded), f"{s.recorded_bytes / 1e6:.2f}", str(s.dropped)
        )
    table.add_row(
        "total",
        "",
        str(sum(s.recorded for s in rows)),
        f"{sum(s.recorded_bytes for s in rows) / 1e6:.2f}",
        str(sum(s.dropped for s in rows)),
    )
    console.print(table)
    for path in report.files:
        console.print(f"recorded: {path}", highlight=False)
    chunks, behind = report.chunks
    if behind:
        console.print(
            f"[yellow]{behind} of {chunks} chunks were written uncompressed: the compressor "
            "did not keep up with the data (nothing was lost for it); --compression lz4 costs "
            "less CPU, none the least[/]",
            highlight=False,
        )
    for err in report.errors[:5]:
        console.print(f"[yellow]recording: {err}[/]", highlight=False)


def recording_status(failure: str | None) -> int:
    """0, or — a recording ended by a full disk (``failure``) — :data:`EXIT_DISK_FULL` after
    saying why on stderr (what was recorded is kept; the message says where)."""
    from redrive.cli.main import EXIT_DISK_FULL

    if failure is None:
        return 0
    print(f"redrive: error: {failure}", file=sys.stderr)
    return EXIT_DISK_FULL
