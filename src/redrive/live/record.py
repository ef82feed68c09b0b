"""A record-only live session, as ``rosbag record`` makes one: :func:`record_live` is the library
call behind ``redrive live --record`` without a pipeline.

>>> report = record_live(RecordRequest(                                   # doctest: +SKIP
...     source=LiveSource(kind="ros1", master_uri="http://127.0.0.1:11311"),
...     path=Path("all.mcap"), selection=TopicSelection(all=True, exclude="/rosout.*")))
>>> report.reason, report.files

Which topics (:class:`~redrive.live.recording.TopicSelection`), when to stop and what happened
(:class:`~redrive.live.recording.Recording`) are in :mod:`redrive.live.recording`; this module
wires the session, the Data Logger and that watch together. The session ends at the first of:
``duration_s``; ``max_size_bytes`` of messages recorded; every publisher gone for
``idle_timeout_s``; the replay/synthetic source finished; ``stop`` set (the CLI's Ctrl-C or
SIGTERM); the recording unable to go on (a full disk: :attr:`RecordReport.failure`, what was
recorded is kept).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from redrive.errors import ConfigError
from redrive.io.mcap.writer import Compression
from redrive.live.recorder import DataLogger
from redrive.live.recording import Recording, TopicSelection, TopicStatus
from redrive.live.run import LiveSource
from redrive.live.streams import StreamSpec

__all__ = ["RecordReport", "RecordRequest", "record_live"]


@dataclass(frozen=True, slots=True, kw_only=True)
class RecordRequest:
    """A record-only session.

    Attributes:
        source: where the data comes from (ROS 1 and ROS 2 take their topics from
            ``selection``; a replay/synthetic source from its own ``topics``, or all).
        path: the MCAP file (with a split limit: the name the numbered files are made from).
        selection: which ROS topics.
        duration_s, max_size_bytes, idle_timeout_s: when to stop (see the module text).
        split_size_bytes, split_duration_s: split into numbered files.
        compression: chunk compression.
    """

    source: LiveSource
    path: Path
    selection: TopicSelection = field(default_factory=TopicSelection)
    duration_s: float | None = None
    max_size_bytes: int | None = None
    idle_timeout_s: float = 5.0
    split_size_bytes: int | None = None
    split_duration_s: float | None = None
    compression: Compression = "zstd"


@dataclass(frozen=True, slots=True, kw_only=True)
class RecordReport:
    """What a recording did: per topic (``topics``), its ``files``, ``wall_s``, why it stopped
    (``reason``), its chunks (all, written uncompressed), what could not be recorded
    (``errors``) and why it had to end early (``failure``, a full disk; else None)."""

    topics: tuple[TopicStatus, ...]
    files: tuple[Path, ...]
    wall_s: float
    reason: str
    chunks: tuple[int, int]
    errors: tuple[str, ...] = ()
    failure: str | None = None


class Follower(Protocol):
    """Something outside the core that shows the session's streams (the Foxglove view): it is
    told the streams again whenever topics joined."""

    def follow(self, specs: Sequence[StreamSpec]) -> None: ...

    def close(self) -> None: ...


def _session(request: RecordRequest) -> tuple[Any, dict[str, str] | None, Any]:
    """The session, the ROS 1 types to add once the recorder reads, the ROS 2 publications."""
    from redrive.live.ros1 import list_topics
    from redrive.live.session import LiveSession, wait_for_topics

    source, selection = request.source, request.selection
    if source.kind in ("replay", "synthetic"):
        return source.open(lossless=True), None, None
    if selection.empty:
        msg = "name topics, or give -a/--all or -e/--regex (or --replay/--synthetic)"
        raise ConfigError(msg)
    if source.kind == "ros2":
        from redrive.live.ros2 import find_publications, ros2_session

        publications = find_publications(
            list(selection.topics), domain_id=source.domain(), wait_for_topics_s=source.wait_s
        )
        # the scraper starts reading nothing; each topic is added once the recorder reads it
        session: Any = ros2_session(
            [],
            domain_id=source.domain(),
            capacity=dict(source.capacities),
            discover_new=selection.grows,
        )
        return session, None, publications
    types = wait_for_topics(
        list(selection.topics), master_uri=source.master_uri, wait_s=source.wait_s
    )
    if selection.grows:
        types.update(selection.chosen(list_topics(source.master_uri)))
    session = LiveSession.ros1([], master_uri=source.master_uri, capacity=dict(source.capacities))
    return session, types, None


def record_live(
    request: RecordRequest,
    *,
    stop: threading.Event | None = None,
    on_session: Callable[[Any], None] | None = None,
    on_tick: Callable[[Recording], None] | None = None,
    follower: Callable[[str, Sequence[StreamSpec]], Follower | None] | None = None,
    say: Callable[[str], None] | None = None,
    stop_reason: str = "stopped",
) -> RecordReport:
    """Record ``request`` (see the module text) and return its report.

    Args:
        stop: set it to end the recording (what was recorded is kept).
        on_session: called with the session once it exists (the CLI installs its Ctrl-C and
            SIGTERM handlers then, so a refused start leaves them untouched).
        on_tick: called a few times a second while recording (the CLI's status lines).
        follower: makes what shows the streams (see :class:`Follower`).
        say: what the recording has to say while it runs (master gone and back, topics left
            out); default: a warning in the log.
        stop_reason: the report's reason when ``stop`` ended it (the CLI: "Ctrl-C").

    Raises:
        ConfigError: no topics chosen; ProducerGoneError, TransportError: the session cannot
            start.
    """
    stop = stop if stop is not None else threading.Event()
    source = request.source
    ros = source.kind == "ros1"
    session, types, publications = _session(request)
    if on_session is not None:
        on_session(session)
    reason = stop_reason
    watcher: Follower | None = None
    with session:
        recorder = DataLogger(
            session.specs,
            request.path,
            definitions=session.definition if ros else None,
            split_size_bytes=request.split_size_bytes,
            split_duration_s=request.split_duration_s,
            max_size_bytes=request.max_size_bytes,
            compression=request.compression,
            native=source.kind == "ros2",
            on_failure=stop.set,
        )
        try:
            if types is not None:  # each scraper subscribes once the recorder reads its stream
                session.add_ros1(types, on_stream=recorder.add)
            elif publications is not None:  # the same: the scraper reads it then
                session.add_ros2(publications, on_stream=recorder.add)
            watcher = follower(session.name, session.specs) if follower is not None else None
            recording = Recording(
                session,
                recorder,
                selection=request.selection,
                master_uri=source.master_uri if ros else None,
                idle_timeout_s=request.idle_timeout_s,
                say=say,
            )
            deadline = None if request.duration_s is None else time.monotonic() + request.duration_s
            while not stop.wait(0.25):
                if recorder.failed.is_set():
                    break
                if deadline is not None and time.monotonic() >= deadline:
                    reason = f"--duration {request.duration_s:g} s"
                    break
                found = recording.step()
                if found is not None:
                    reason = found
                    break
                if watcher is not None:
                    watcher.follow(session.specs)  # topics that appeared (-a/-e)
                if on_tick is not None:
                    on_tick(recording)
        except BaseException:
            recorder.abort()  # what was recorded stays; an empty part does not
            raise
        finally:
            if watcher is not None:
                watcher.close()
        wall_s = recording.wall_s
    recorder.stop()
    if recorder.failure is not None:
        reason = "the recording could not go on (below)"
    return RecordReport(
        topics=tuple(recording.status()),
        files=tuple(recorder.files),
        wall_s=wall_s,
        reason=reason,
        chunks=recorder.chunks,
        errors=tuple(recorder.errors),
        failure=recorder.failure,
    )
