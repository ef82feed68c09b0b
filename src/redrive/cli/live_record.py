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
    from redrive.live.recorder import DataLogger
    from redrive.live.recording import Recording, TopicSelection
    from redrive.live.ros1 import list_topics
    from redrive.live.ros2 import Ros2Session
    from redrive.live.session import LiveSession, wait_for_topics

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
    split_size = (
        None if args.split_size is None else parse_size(args.split_size, option="--split-size")
    )
    max_size = None if args.max_size is None else parse_size(args.max_size, option="--max-size")
    ros2 = bool(getattr(args, "ros2", False))
    ros = args.replay is None and args.synthetic is None and not ros2
    if (ros or ros2) and selection.empty:
        print("redrive live: name topics, or give -a/--all or -e/--regex (or --replay/--synthetic)")
        return 2
    warn_orphans(args.record, console)
    session: LiveSession
    if ros2:
        from redrive.live.ros2 import find_publications, ros2_session
        from redrive.live.ros2_dds import default_domain_id

        domain = default_domain_id() if args.domain is None else args.domain
        publications = find_publications(
            list(selection.topics), domain_id=domain, wait_for_topics_s=args.wait
        )
        # the scraper starts reading nothing; each topic is added once the recorder reads it
        session = ros2_session(
            [], domain_id=domain, capacity=args.capacities, discover_new=selection.grows
        )
        source_text = f"ROS 2 (DDS domain {domain})"
    elif ros:
        types = wait_for_topics(list(selection.topics), master_uri=master, wait_s=args.wait)
        if selection.grows:
            types.update(selection.chosen(list_topics(master)))
        session = LiveSession.ros1([], master_uri=master, capacity=args.capacities)
        source_text = master
    else:
        kind = "replay" if args.replay is not None else "synthetic"
        session = LiveSession.source(
            kind,
            args.replay if args.replay is not None else args.synthetic,
            rate=args.rate,
            topics=args.topics,
            duration_s=args.duration,
            lossless=True,
        )
        source_text = f"{kind} source {args.replay or args.synthetic}"
    stop = threading.Event()
    handlers = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    reason = "Ctrl-C"
    feed = None
    try:
        with session:
            recorder = DataLogger(
                session.specs,
                args.record,
                definitions=session.definition if ros else None,
                split_size_bytes=split_size,
                split_duration_s=args.split_duration,
                max_size_bytes=max_size,
                compression=args.compression,
                native=ros2,
                on_failure=stop.set,
            )
            try:
                if ros:  # each scraper subscribes once the recorder reads its stream
                    session.add_ros1(types, on_stream=recorder.add)
                elif isinstance(session, Ros2Session):  # the same: the scraper reads it then
                    session.add_ros2(publications, on_stream=recorder.add)
                feed = open_feed(args, session.name, session.specs)
                recording = Recording(
                    session,
                    recorder,
                    selection=selection,
                    master_uri=master if ros else None,
                    idle_timeout_s=args.idle_timeout,
                    say=lambda text: console.print(
                        f"[yellow]{text}[/]", highlight=False, soft_wrap=True
                    ),
                )
                console.print(
                    f"live: recording {len(session.specs)} topic(s) from {source_text} to "
                    f"{args.record}; Ctrl-C stops",
                    highlight=False,
                )
                deadline = None if args.duration is None else time.monotonic() + args.duration
                status = _Status(recording, console)
                try:
                    while not stop.wait(0.25):
                        if recorder.failed.is_set():
                            break
                        if deadline is not None and time.monotonic() >= deadline:
                            reason = f"--duration {args.duration:g} s"
                            break
                        found = recording.step()
                        if found is not None:
                            reason = found
                            break
                        if feed is not None:
                            feed.follow(session.specs)  # topics that appeared (-a/-e)
                        status.update()
                finally:
                    status.close()
            except BaseException:
                recorder.abort()
                raise
            finally:
                if feed is not None:
                    feed.close()
            wall_s = recording.wall_s
    finally:
        for sig, previous in handlers.items():
            signal.signal(sig, previous)
    recorder.stop()
    if recorder.failure is not None:
        reason = "the recording could not go on (below)"
    _summary(recording, recorder, wall_s=wall_s, reason=reason)
    if feed is not None:
        print(feed.summary())
    return recording_status(recorder.failure)


def recording_status(failure: str | None) -> int:
    """0, or — a recording ended by a full disk (``failure``) — :data:`EXIT_DISK_FULL` after
    saying why on stderr (what was recorded is kept; the message says where)."""
    from redrive.cli.main import EXIT_DISK_FULL

    if failure is None:
        return 0
    print(f"redrive: error: {failure}", file=sys.stderr)
    return EXIT_DISK_FULL


def _summary(recording: Any, recorder: Any, *, wall_s: float, reason: str) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=None if sys.stdout.isatty() else 120)
    rows = recording.status()
    table = Table(
        title=f"recorded {wall_s:.1f} s of wall time; stopped: {reason}", title_justify="left"
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
    for path in recorder.files:
        console.print(f"recorded: {path}", highlight=False)
    chunks, behind = recorder.chunks
    if behind:
        console.print(
            f"[yellow]{behind} of {chunks} chunks were written uncompressed: the compressor "
            "did not keep up with the data (nothing was lost for it); --compression lz4 costs "
            "less CPU, none the least[/]",
            highlight=False,
        )
    for err in recorder.errors[:5]:
        console.print(f"[yellow]recording: {err}[/]", highlight=False)
