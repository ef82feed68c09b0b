"""A live session run through a pipeline: :func:`run_live` is to live data what
:func:`redrive.engine.run_log` is to a log.

>>> source = LiveSource(kind="replay", target="drive.mcap", rate=2.0)         # doctest: +SKIP
>>> report = run_live(LiveRequest(source=source, pipeline=reference_pipeline(),
...                               out=Path("runs/live1"), record=Path("copy.mcap")))

The session (ROS 1 topics through scrapers, ROS 2 topics over DDS, or a log or scenario played
as a sensor rig) hands its messages over through shared memory; frames are assembled as the data
arrives and run in realtime mode (a frame that comes while the pipeline is busy is skipped and
counted) into ``out``; with ``record`` the Data Logger writes every message to MCAP (lossless).
The session ends at ``frames`` frames, after ``duration_s``, when a replay or synthetic source
has finished, when ``stop`` is set (the CLI's Ctrl-C), or when the recording cannot go on (a
full disk: :attr:`LiveReport.failure`; what was recorded is kept).

What watches the session from outside the core (the CLI's Foxglove view, which lives in
:mod:`redrive.interop` and so cannot be imported here) comes in as ``feed``: called once the
session is up, it returns an object with ``on_frame`` and ``close``, or None.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Protocol

from redrive.config import PipelineConfig
from redrive.engine import RealtimeMode, RunRequest, run_reader
from redrive.engine.stats import RunReport
from redrive.io.mcap.writer import Compression
from redrive.live.dispatcher import LiveLog
from redrive.live.recorder import DataLogger
from redrive.live.ros1 import DEFAULT_MASTER_URI
from redrive.live.streams import StreamSpec
from redrive.results import SourceLog
from redrive.results.records import FrameRecord

__all__ = ["LiveReport", "LiveRequest", "LiveSource", "SessionFeed", "SourceKind", "run_live"]

SourceKind = Literal["ros1", "ros2", "replay", "synthetic"]


@dataclass(frozen=True, slots=True, kw_only=True)
class LiveSource:
    """Where a live session's data comes from.

    Attributes:
        kind: ``ros1`` (topics on a ROS master), ``ros2`` (topics on a DDS domain), ``replay``
            (a log played at its rate as a sensor rig) or ``synthetic`` (a scenario simulated in
            real time).
        topics: the topics (ROS 1 and ROS 2: required; replay/synthetic: a subset, or all).
        target: the log (replay) or the scenario (synthetic).
        master_uri: ROS 1: the master.
        domain_id: ROS 2: the DDS domain (None: ``ROS_DOMAIN_ID`` or 0).
        rate: replay/synthetic: the playback rate.
        duration_s: replay/synthetic: seconds of the source.
        capacities: topic → bytes of its shared-memory slots.
        wait_s: ROS: how long to wait for topics not yet published.
    """

    kind: SourceKind
    topics: tuple[str, ...] = ()
    target: str | None = None
    master_uri: str = DEFAULT_MASTER_URI
    domain_id: int | None = None
    rate: float = 1.0
    duration_s: float | None = None
    capacities: Mapping[str, int] = field(default_factory=dict)
    wait_s: float = 5.0

    def describe(self) -> str:
        """What the manifest and the CLI call the source."""
        if self.kind in ("replay", "synthetic"):
            return f"{self.kind} source {self.target}"
        if self.kind == "ros2":
            return f"ROS 2 (DDS domain {self.domain()})"
        return self.master_uri

    def domain(self) -> int:
        from redrive.live.ros2_dds import default_domain_id

        return default_domain_id() if self.domain_id is None else self.domain_id

    def open(self, *, lossless: bool) -> Any:
        """The session (a context manager); ``lossless``: replay/synthetic sources wait for a
        recorder rather than drop (a recording must hold every message).

        Raises:
            ConfigError: ROS topics were not given.
        """
        from redrive.errors import ConfigError
        from redrive.live.session import LiveSession

        if self.kind in ("replay", "synthetic"):
            assert self.target is not None
            return LiveSession.source(
                self.kind,
                self.target,
                rate=self.rate,
                topics=list(self.topics) or None,
                duration_s=self.duration_s,
                lossless=lossless,
            )
        if not self.topics:
            hint = (
                "--topics" if self.kind == "ros2" else "--topics (ROS 1), --replay or --synthetic"
            )
            raise ConfigError(f"a live {self.kind} session needs topics: give {hint}")
        if self.kind == "ros2":
            from redrive.live.ros2 import ros2_session

            return ros2_session(
                list(self.topics),
                domain_id=self.domain(),
                capacity=dict(self.capacities),
                wait_for_topics_s=self.wait_s,
            )
        return LiveSession.ros1(
            list(self.topics),
            master_uri=self.master_uri,
            capacity=dict(self.capacities),
            wait_for_topics_s=self.wait_s,
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class LiveRequest:
    """A live run: the source, the pipeline, the run directory, and what ends and records it.

    Attributes:
        frames: end after this many assembled frames.
        duration_s: end after this many seconds of wall time.
        record: record every message of the session to this MCAP file.
        compression: the recording's chunk compression.
        sensor_map: a sensor-map TOML file, as ``redrive run --sensor-map``.
        publish_ros2: ROS 2: publish the results back on the domain.
    """

    source: LiveSource
    pipeline: PipelineConfig
    out: Path
    frames: int | None = None
    duration_s: float | None = None
    record: Path | None = None
    compression: Compression = "zstd"
    sensor_map: Path | None = None
    publish_ros2: bool = True


@dataclass(frozen=True, slots=True, kw_only=True)
class LiveReport:
    """What a live run did.

    Attributes:
        run: the engine's report of the frames.
        received_frames: frames assembled; ``skipped_frames`` of them came while the pipeline
            was busy and were never processed.
        received: topic → messages handed to the pipeline; ``dropped`` those it missed.
        recorded: topic → messages in the recording (None without one).
        files: the recording's files.
        recording_errors: topics the recorder could not record, with why.
        failure: why the recording ended early (a full disk), else None.
        published: ROS 2 topic → results published.
    """

    run: RunReport
    received_frames: int
    skipped_frames: int
    received: Mapping[str, int]
    dropped: Mapping[str, int]
    recorded: Mapping[str, int] | None = None
    files: tuple[Path, ...] = ()
    recording_errors: tuple[str, ...] = ()
    failure: str | None = None
    published: Mapping[str, int] = field(default_factory=dict)


class SessionFeed(Protocol):
    """Something outside the core that follows the session's frames (the Foxglove view)."""

    def on_frame(self, record: FrameRecord) -> None: ...

    def close(self) -> None: ...


#: ``feed(session name, its streams)``: what watches the session, or None
FeedFactory = Callable[[str, Sequence[StreamSpec]], SessionFeed | None]


def run_live(
    request: LiveRequest,
    *,
    stop: threading.Event | None = None,
    on_receiving: Callable[[Any], None] | None = None,
    feed: FeedFactory | None = None,
) -> LiveReport:
    """Run ``request`` (see the module text) and return its report.

    Args:
        stop: set it to end the session (the frames done so far are stored).
        on_receiving: called with the session once it receives (the CLI says so, and from then
            on Ctrl-C sets ``stop``).
        feed: makes what follows the frames (see :data:`FeedFactory`).

    Raises:
        ConfigError, PluginError, TransportError: the session or the pipeline cannot start.
    """
    stop = stop if stop is not None else threading.Event()
    source = request.source
    recorder: DataLogger | None = None
    log: LiveLog | None = None
    hooks = RealtimeMode()
    with source.open(lossless=request.record is not None) as session, _ending(stop) as later:
        try:
            if request.record is not None:
                recorder = DataLogger(
                    session.specs,
                    request.record,
                    definitions=session.definition if session.scrapers else None,
                    compression=request.compression,
                    on_failure=stop.set,
                )
            log = LiveLog(session.specs, session.name, stop=stop)
            later.append(log.close)
            watcher = feed(session.name, session.specs) if feed is not None else None
            if watcher is not None:
                later.append(watcher.close)
            publisher = None
            if source.kind == "ros2" and request.publish_ros2:
                from redrive.live.ros2 import ResultPublisher

                publisher = ResultPublisher(source.domain())
                later.append(publisher.close)
            if request.duration_s is not None:
                timer = threading.Timer(request.duration_s, stop.set)
                timer.daemon = True
                timer.start()
                later.append(timer.cancel)
            if on_receiving is not None:
                on_receiving(session)
            info = SourceLog(
                path=str(log.path),
                format="live",
                sha256=None,
                source=source.describe(),
                topics={s.topic: s.msgtype for s in session.specs},
                record=None if request.record is None else str(request.record),
            )
            run_request = RunRequest(
                log=log.path,
                pipeline=request.pipeline,
                out=request.out,
                stop_frame=request.frames,
                sensor_map=request.sensor_map,
            )
            callbacks: list[Callable[[FrameRecord], None]] = []
            if publisher is not None:
                callbacks.append(publisher)
            if watcher is not None:
                callbacks.append(watcher.on_frame)
            report = run_reader(
                run_request,
                log,
                hooks=hooks,
                log_info=info,
                lookahead_ns=0,
                on_frame=_all(callbacks),
                probe_clocks=False,
            )
        except BaseException:
            if recorder is not None:
                recorder.abort()  # what was recorded stays; an empty part does not
            raise
    if recorder is not None:
        recorder.stop()
    return LiveReport(
        run=report,
        received_frames=hooks.received_frames,
        skipped_frames=hooks.skipped_frames,
        received=dict(log.received),
        dropped=dict(log.dropped),
        recorded=None if recorder is None else dict(recorder.recorded),
        files=() if recorder is None else tuple(recorder.files),
        recording_errors=() if recorder is None else tuple(recorder.errors),
        failure=None if recorder is None else recorder.failure,
        published={} if publisher is None else dict(publisher.published),
    )


@contextlib.contextmanager
def _ending(stop: threading.Event) -> Iterator[list[Callable[[], None]]]:
    """What to close when the session ends, however it ends (last opened, first closed)."""
    later: list[Callable[[], None]] = []
    try:
        yield later
    finally:
        stop.set()
        for close in reversed(later):
            close()


def _all(
    callbacks: Sequence[Callable[[FrameRecord], None]],
) -> Callable[[FrameRecord], None] | None:
    if not callbacks:
        return None
    if len(callbacks) == 1:
        return callbacks[0]

    def call(record: FrameRecord) -> None:
        for callback in callbacks:
            callback(record)

    return call
