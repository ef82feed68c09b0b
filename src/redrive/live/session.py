"""A live session: source processes feeding shared-memory streams, stopped together.

>>> with LiveSession.ros1(["/velodyne_points"], master_uri="http://127.0.0.1:11311") as live:
...     log = LiveLog(live.specs, live.name)            # doctest: +SKIP

The ROS 1 scrapers run under ``/usr/bin/python3`` (Debian's rospy) as scripts with only
redrive's own package on their path, one process per topic.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

from redrive.errors import ConfigError, TransportError
from redrive.live.ros1 import list_topics
from redrive.live.scraper_state import Ros1Definition, ScraperState
from redrive.live.streams import StreamSpec, ring_slots, ros2_type, stream_name
from redrive.transport import remove_stale

__all__ = [
    "DEFAULT_CAPACITY",
    "ROS_PYTHON",
    "LiveSession",
    "default_session_name",
    "wait_for_topics",
]

logger = logging.getLogger(__name__)

ROS_PYTHON = Path("/usr/bin/python3")
_SCRAPER = Path(__file__).with_name("ros1_scraper.py")

#: the largest message a stream takes, by ROS 2 type (``--capacity`` overrides per topic):
#: PointCloud2 fits a 128-beam sweep, Image a 4K rgb8 frame; the fixed-size ego-state types
#: (a header's frame id the only string) 16 KiB, so their streams get rings of seconds
#: (:func:`~redrive.live.streams.ring_slots`).
DEFAULT_CAPACITY: Mapping[str, int] = {
    "sensor_msgs/msg/PointCloud2": 32 << 20,
    "sensor_msgs/msg/Image": 32 << 20,
    "sensor_msgs/msg/CompressedImage": 16 << 20,
    "sensor_msgs/msg/LaserScan": 1 << 20,
    "nav_msgs/msg/Odometry": 16 << 10,
    "sensor_msgs/msg/Imu": 16 << 10,
    "sensor_msgs/msg/NavSatFix": 16 << 10,
    "geometry_msgs/msg/PoseStamped": 16 << 10,
    "geometry_msgs/msg/PoseWithCovarianceStamped": 16 << 10,
    "geometry_msgs/msg/TwistStamped": 16 << 10,
}
_OTHER_CAPACITY = 1 << 20


@dataclass(frozen=True, slots=True, kw_only=True)
class _Ros1Options:
    master_uri: str
    capacity: dict[str, int]
    slots: int
    ready_timeout_s: float


def default_session_name() -> str:
    return f"live-{os.getpid()}"


class LiveSession:
    """Source processes and the streams they write (see the module text). Use :meth:`ros1`."""

    def __init__(
        self, name: str, specs: Sequence[StreamSpec], processes: Sequence[subprocess.Popen[str]]
    ) -> None:
        self.name = name
        self.specs = list(specs)
        self.processes = list(processes)
        #: topic → what its ROS 1 scraper reports (publishers, counts, the definition)
        self.scrapers: dict[str, ScraperState] = {}
        self._shim: Path | None = None
        self._ros1: _Ros1Options | None = None

    @classmethod
    def ros1(
        cls,
        topics: Sequence[str],
        *,
        master_uri: str,
        name: str | None = None,
        capacity: Mapping[str, int] | None = None,
        slots: int = 6,
        ready_timeout_s: float = 20.0,
        wait_for_topics_s: float = 0.0,
    ) -> LiveSession:
        """Start one scraper per ROS 1 topic (types from the master, waiting up to
        ``wait_for_topics_s`` for topics nobody publishes yet) and wait until each is subscribed.

        Raises:
            ConfigError: a topic is not on the master.
            TransportError: rospy is not available, or a scraper failed to start.
        """
        if not ROS_PYTHON.is_file():
            msg = (
                f"{ROS_PYTHON} is missing: the ROS 1 scraper runs under Debian's python3 with rospy"
            )
            raise TransportError(msg)
        name = name or default_session_name()
        remove_stale()  # segments of killed earlier sessions
        types = wait_for_topics(topics, master_uri=master_uri, wait_s=wait_for_topics_s)
        session = cls(name, [], [])
        session._ros1 = _Ros1Options(
            master_uri=master_uri, capacity=dict(capacity or {}), slots=slots,
            ready_timeout_s=ready_timeout_s,
        )  # fmt: skip
        try:
            session.add_ros1(types)
        except BaseException:
            session.close()
            raise
        return session

    @classmethod
    def source(
        cls,
        kind: str,
        target: str | Path,
        *,
        name: str | None = None,
        rate: float | None = 1.0,
        topics: Sequence[str] | None = None,
        duration_s: float | None = None,
        lossless: bool = False,
        ready_timeout_s: float = 60.0,
    ) -> LiveSession:
        """Start a replay (``kind="replay"``, ``target`` a log) or synthetic (``"synthetic"``,
        ``target`` a scenario) source process (:mod:`redrive.live.sources`), a stand-in for a
        sensor rig, and wait until its streams exist."""
        from redrive.live.sources import replay_streams, synthetic_streams

        name = name or default_session_name()
        remove_stale()  # segments of killed earlier sessions
        if kind == "replay":
            specs = replay_streams(Path(target), name, topics=topics)
            extra = ["--topics", *topics] if topics else []
        elif kind == "synthetic":
            specs = synthetic_streams(str(target), name)
            extra = [] if duration_s is None else ["--duration", str(duration_s)]
        else:
            msg = f"unknown live source {kind!r}: replay or synthetic"
            raise ConfigError(msg)
        argv = [
            sys.executable, "-m", "redrive.live.sources", kind, str(target), "--session", name,
            "--rate", str(rate or 0), *extra, *(["--lossless"] if lossless else []),
        ]  # fmt: skip
        proc = subprocess.Popen(
            argv,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        session = cls(name, specs, [proc])
        try:
            _wait_ready(proc, f"{kind} source", time.monotonic() + ready_timeout_s)
        except BaseException:
            session.close()
            raise
        return session

    def add_ros1(
        self,
        topics: Mapping[str, str],
        *,
        on_stream: Callable[[StreamSpec], None] | None = None,
    ) -> list[StreamSpec]:
        """Start a scraper for each of ``topics`` (topic → ROS 1 type) and wait until each is
        subscribed; returns their streams (also appended to :attr:`specs`).

        With ``on_stream`` (a recorder's ``add``), each scraper waits until ``on_stream`` was
        called with its stream, and a lossless reader attached, before it subscribes: no message
        is published before the recorder reads the stream.

        Raises:
            TransportError: a scraper failed to start (those of this call are stopped).
        """
        opts = self._ros1
        if opts is None:
            msg = "add_ros1 on a session that was not started with LiveSession.ros1"
            raise TransportError(msg)
        if self._shim is None:
            self._shim = Path(tempfile.mkdtemp(prefix="redrive-shim-"))
            package = Path(__file__).resolve().parents[1]
            (self._shim / "redrive").symlink_to(package, target_is_directory=True)
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONHOME",)}
        env["PYTHONPATH"] = str(self._shim)
        env["ROS_MASTER_URI"] = opts.master_uri
        started: list[tuple[StreamSpec, subprocess.Popen[str]]] = []
        try:
            for topic, ros_type in topics.items():
                msgtype = ros2_type(ros_type)
                size = opts.capacity.get(topic) or DEFAULT_CAPACITY.get(msgtype, _OTHER_CAPACITY)
                spec = StreamSpec(
                    topic=topic,
                    msgtype=msgtype,
                    stream=stream_name(self.name, topic),
                    payload="ros1",
                    capacity_bytes=size,
                )
                argv = [
                    str(ROS_PYTHON), str(_SCRAPER), "--topic", spec.topic, "--stream", spec.stream,
                    "--capacity", str(spec.capacity_bytes),
                    "--slots", str(ring_slots(spec.capacity_bytes, opts.slots)),
                ]  # fmt: skip
                if on_stream is not None:
                    argv += ["--await-lossless", str(opts.ready_timeout_s)]
                proc = subprocess.Popen(
                    argv,
                    env=env,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                    text=True,
                    start_new_session=True,
                )
                started.append((spec, proc))
            deadline = time.monotonic() + opts.ready_timeout_s
            if on_stream is not None:
                for spec, proc in started:
                    _wait_ready(proc, f"the scraper of {spec.topic}", deadline, word="STREAM")
                    on_stream(spec)
            for spec, proc in started:
                _wait_ready(proc, f"the scraper of {spec.topic}", deadline)
        except BaseException:
            for spec, proc in started:
                _stop([proc], timeout_s=2.0)
                remove_stale(spec.stream)
            raise
        for spec, proc in started:
            self.specs.append(spec)
            self.processes.append(proc)
            self.scrapers[spec.topic] = ScraperState(proc)
            threading.Thread(
                target=self.scrapers[spec.topic].follow, name=f"scraper-{spec.topic}", daemon=True
            ).start()
        return [spec for spec, _ in started]

    def definition(self, topic: str, *, timeout_s: float = 5.0) -> Ros1Definition | None:
        """The type, md5sum and full definition of ``topic`` from its publisher's connection
        header, once its scraper received a message (waits up to ``timeout_s``); None for a
        topic of no scraper, or when it did not come in time."""
        state = self.scrapers.get(topic)
        if state is None or not state.defined.wait(timeout_s):
            return None
        return state.definition

    def alive(self) -> bool:
        return all(p.poll() is None for p in self.processes)

    def close(self, *, timeout_s: float = 5.0) -> None:
        """Stop every source (SIGTERM, then SIGKILL) and remove what a killed one left."""
        _stop(self.processes, timeout_s=timeout_s)
        for state in self.scrapers.values():
            state.ended.wait(1.0)  # its reader saw the end of the output
        for proc in self.processes:
            if proc.stdout is not None:
                with contextlib.suppress(OSError, ValueError):
                    proc.stdout.close()
        for spec in self.specs:
            remove_stale(spec.stream)
        if self._shim is not None:
            shutil.rmtree(self._shim, ignore_errors=True)
            self._shim = None

    def __enter__(self) -> LiveSession:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _stop(processes: Sequence[subprocess.Popen[str]], *, timeout_s: float) -> None:
    for proc in processes:
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGTERM)
    deadline = time.monotonic() + timeout_s
    for proc in processes:
        try:
            proc.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        if proc.stderr is not None:
            proc.stderr.close()


def wait_for_topics(topics: Sequence[str], *, master_uri: str, wait_s: float) -> dict[str, str]:
    """Topic → ROS 1 type of ``topics``, waiting up to ``wait_s`` for those not yet published.

    Raises:
        ConfigError: a topic is not on the master by then.
        TransportError: no master answers.
    """
    deadline = time.monotonic() + wait_s
    while True:
        known = {t.name: t for t in list_topics(master_uri) if t.msg_type != "*"}
        missing = [t for t in topics if t not in known]
        if not missing or time.monotonic() >= deadline:
            break
        time.sleep(0.2)
    if missing:
        msg = (
            f"not on the ROS master {master_uri}: {', '.join(missing)}; "
            f"it has {', '.join(sorted(known)) or 'no topics'} (`redrive topics` lists them)"
        )
        raise ConfigError(msg)
    return {topic: known[topic].msg_type for topic in topics}


def _wait_ready(
    proc: subprocess.Popen[str], topic: str, deadline: float, *, word: str = "READY"
) -> None:
    import select

    assert proc.stdout is not None
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            msg = f"{topic} did not start within the timeout"
            raise TransportError(msg)
        ready, _, _ = select.select([proc.stdout], [], [], left)
        if not ready:
            continue
        line = proc.stdout.readline()
        if line.strip() == word:
            return
        if not line:
            err = proc.stderr.read() if proc.stderr else ""
            last = "\n".join(err.strip().splitlines()[-5:])
            msg = f"{topic} exited (status {proc.wait()}): {last}"
            raise TransportError(msg)
