"""Record-only live sessions, as ``rosbag record`` does: which topics, when to stop, what happened.

:class:`TopicSelection` chooses topics as ``rosbag record`` users know it (named topics, ``-a``,
``-e REGEX``, ``-x REGEX``). :class:`Recording` watches a running session and its
:class:`~redrive.live.recorder.DataLogger`: :meth:`Recording.step`, called a few times a second,

* asks the ROS master for its topics — new ones that match ``--all``/``--regex`` get a scraper and
  join the recording; when the master stops answering it says so once and recording goes on (open
  connections keep delivering); when a master answers again it says so (the scrapers register
  again with it by themselves);
* for a ROS 2 session (:class:`~redrive.live.ros2.Ros2Session`), looks at the topics the ROS 2
  scraper found published on the DDS domain instead: new ones that match join the recording
  (types redrive has no definition of are named once and left out: ROS 2 sends no definitions);
* says why the session ends: every publisher of the recorded topics gone for ``idle_timeout_s``
  (a ROS 1 publisher is there while it is registered with the master or a scraper is connected
  to it; the master's own ``/rosout`` node and redrive's scrapers do not count; a ROS 2 publisher
  while the scraper's DDS reader is matched with its writer, the ``/rosout`` and
  ``/parameter_events`` every ROS 2 node publishes not counting; with ``--all``/``--regex`` the
  clock starts once a first publisher was there), the recording full (``--max-size``), or — for
  replay and synthetic sources — the source finished.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from redrive.errors import ConfigError, TransportError
from redrive.live.recorder import DataLogger
from redrive.live.ros1 import TopicInfo, list_topics
from redrive.live.ros2 import Ros2Session
from redrive.live.ros2_dds import QosProfile
from redrive.live.session import LiveSession

__all__ = ["Recording", "TopicSelection", "TopicStatus"]

logger = logging.getLogger(__name__)

#: publishers that never go away by themselves, left out when telling whether data can still come
_NOT_A_SOURCE = re.compile(r"^/(rosout|redrive_scraper_[^/]*)$")
#: ROS 2 topics every node publishes (a long-lived ``ros2 daemon`` too): their publishers do not
#: tell whether data can still come
_NOT_A_SOURCE_TOPIC = frozenset({"/rosout", "/parameter_events"})


@dataclass(frozen=True, slots=True, kw_only=True)
class TopicSelection:
    """Which topics to record.

    Attributes:
        topics: named topics (recorded whatever ``exclude`` says).
        all: every topic, including those that appear later.
        regex: topics matching any of these (``re.fullmatch``), including those that appear later.
        exclude: topics matching this are left out of ``all``/``regex``.
    """

    topics: tuple[str, ...] = ()
    all: bool = False
    regex: tuple[str, ...] = ()
    exclude: str | None = None

    def __post_init__(self) -> None:
        for pattern in (*self.regex, *([self.exclude] if self.exclude else [])):
            try:
                re.compile(pattern)
            except re.error as err:
                msg = f"the regular expression {pattern!r} does not compile ({err}); quote it for the shell"
                raise ConfigError(msg) from err

    @property
    def grows(self) -> bool:
        """True when topics that appear later are recorded too."""
        return self.all or bool(self.regex)

    @property
    def empty(self) -> bool:
        return not (self.topics or self.grows)

    def matches(self, topic: str) -> bool:
        if topic in self.topics:
            return True
        if not self.grows or (self.exclude and re.fullmatch(self.exclude, topic)):
            return False
        return self.all or any(re.fullmatch(p, topic) for p in self.regex)

    def chosen(self, available: Sequence[TopicInfo]) -> dict[str, str]:
        """Topic → ROS 1 type of the ``available`` topics this selection records (typed ones)."""
        return {t.name: t.msg_type for t in available if t.msg_type != "*" and self.matches(t.name)}


@dataclass(frozen=True, slots=True, kw_only=True)
class TopicStatus:
    """One topic of a recording, now: ``recorded`` messages and ``recorded_bytes`` of them,
    ``dropped`` (received from ROS but not recorded), ``publishers`` connected."""

    topic: str
    msg_type: str
    recorded: int
    recorded_bytes: int
    dropped: int
    publishers: int


class Recording:
    """A running record-only session (see the module text)."""

    def __init__(
        self,
        session: LiveSession,
        recorder: DataLogger,
        *,
        selection: TopicSelection,
        master_uri: str | None,
        idle_timeout_s: float = 5.0,
        say: Callable[[str], None] | None = None,
    ) -> None:
        self.session = session
        self.recorder = recorder
        self.selection = selection
        self.master_uri = master_uri
        self.idle_timeout_s = idle_timeout_s
        self.say = say or (lambda text: logger.warning("%s", text))
        self.started_s = time.monotonic()
        self.master_up = True
        self._seen_publisher = False
        self._idle_since: float | None = None
        self._registered: dict[str, tuple[str, ...]] = {}
        self._refused: set[str] = set()

    @property
    def wall_s(self) -> float:
        return time.monotonic() - self.started_s

    def step(self) -> str | None:
        """Look at the master and the sources once; the reason the session ends, or None."""
        if self.recorder.full.is_set():
            size = sum(self.recorder.recorded_bytes.values())
            return f"the recording reached --max-size ({size / 1e6:.1f} MB of messages)"
        if isinstance(self.session, Ros2Session):
            if not self.session.alive():
                return "the ROS 2 scraper exited (its errors are above)"
            self._watch_dds(self.session)
            return self._idle()
        if self.master_uri is None:  # a replay or synthetic source: it ends by itself
            return None if self.session.alive() else "the source finished"
        self._watch_master()
        return self._idle()

    def _watch_dds(self, session: Ros2Session) -> None:
        from redrive.live.ros2_dds import Publication

        if not self.selection.grows:
            return
        new = {}
        for topic, offered in list(session.offered.items()):
            if topic in session.scrapers or topic in self._refused:
                continue
            if not self.selection.matches(topic):
                continue
            if not session.known_type(offered.msgtype):
                self._refused.add(topic)
                self.say(
                    f"not recording {topic}: redrive has no definition of {offered.msgtype}, and "
                    "ROS 2 publishers send none (ROS 1 ones do); add its .msg to redrive/io/ros/msgs"
                )
                continue
            qos = QosProfile(
                reliability="best_effort" if offered.reliability == "best_effort" else "reliable",
                durability="transient_local" if offered.durability == "transient_local" else "volatile",
            )  # fmt: skip
            new[topic] = Publication(topic=topic, msgtype=offered.msgtype, qos=qos)
        for topic, pub in sorted(new.items()):
            try:
                session.add_ros2({topic: pub}, on_stream=self.recorder.add)
            except TransportError as err:
                self._refused.add(topic)
                self.say(f"not recording {topic}: {err}")
                continue
            self.say(f"recording {topic} (published on the DDS domain)")

    def _watch_master(self) -> None:
        assert self.master_uri is not None
        try:
            topics = list_topics(self.master_uri, timeout_s=1.0)
        except TransportError as err:
            if self.master_up:
                self.master_up = False
                self.say(
                    f"the ROS master at {self.master_uri} is gone ({err}); recording what still "
                    "flows on open connections, and subscribing again when a master is back there"
                )
            self._registered = {}
            return
        if not self.master_up:
            self.master_up = True
            self.say(f"a ROS master is back at {self.master_uri}: the scrapers register again")
        self._registered = {t.name: t.publishers for t in topics}
        if not self.selection.grows:
            return
        new = {
            name: msg_type
            for name, msg_type in self.selection.chosen(topics).items()
            if name not in self.session.scrapers
            and any(not _NOT_A_SOURCE.match(p) for p in self._registered.get(name, ()))
        }
        if not new:
            return
        try:
            self.session.add_ros1(new, on_stream=self.recorder.add)
        except TransportError as err:
            self.say(f"not recording {', '.join(sorted(new))}: {err}")
            return
        self.say(f"recording {', '.join(sorted(new))} too (new on the master)")

    def _publishers(self, topic: str) -> set[str]:
        state = self.session.scrapers.get(topic)
        connected = set(state.publishers) if state is not None else set()
        nodes = connected | set(self._registered.get(topic, ()))
        return {n for n in nodes if not _NOT_A_SOURCE.match(n)}

    def _idle(self) -> str | None:
        ros2 = isinstance(self.session, Ros2Session)
        present = any(
            self._publishers(t)
            for t in list(self.session.scrapers)
            if not (ros2 and t in _NOT_A_SOURCE_TOPIC)
        )
        now = time.monotonic()
        if present:
            self._seen_publisher = True
            self._idle_since = None
            return None
        if self.selection.grows and not self._seen_publisher:
            return None  # -a/-e before anything is published: wait for the first publisher
        if self._idle_since is None:
            self._idle_since = now
        if now - self._idle_since >= self.idle_timeout_s:
            return (
                f"every publisher of the recorded topics has been gone for "
                f"{self.idle_timeout_s:g} s (--idle-timeout)"
            )
        return None

    def status(self) -> list[TopicStatus]:
        """Every recorded topic, now."""
        out = []
        for spec in list(self.recorder.specs):
            state = self.session.scrapers.get(spec.topic)
            out.append(
                TopicStatus(
                    topic=spec.topic,
                    msg_type=spec.msgtype,
                    recorded=self.recorder.recorded.get(spec.topic, 0),
                    recorded_bytes=self.recorder.recorded_bytes.get(spec.topic, 0),
                    # received from ROS, but not handed to the recorder in time (lossless
                    # back-pressure timed out)
                    dropped=state.failed if state is not None else 0,
                    publishers=len(self._publishers(spec.topic)),
                )
            )
        return out
