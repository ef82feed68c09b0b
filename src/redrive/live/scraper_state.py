"""What a ROS 1 scraper process reports on its stdout, as the core sees it.

After ``READY`` a scraper (:mod:`redrive.live.ros1_scraper`) prints ``DEF {json}`` — the type,
md5sum and full message definition of its topic from the publisher's connection header — before
it forwards the first message, and ``STATE {json}`` — the publishers it is connected to and its
counts — whenever they change. :class:`ScraperState` follows those lines in a thread.

The one ROS 2 scraper of a session (:mod:`redrive.live.ros2_scraper`) reports for all its topics
(``STATE``, ``OFFERED``, ``STREAM``, ``ADDED``, ``FAILED``, each with a ``topic``): :class:`Ros2Reports`
follows them and keeps a :class:`ScraperState` per topic.
"""

from __future__ import annotations

import json
import logging
import subprocess
import threading
from dataclasses import dataclass

__all__ = ["Offered", "Ros1Definition", "Ros2Reports", "ScraperState"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class Ros1Definition:
    """A ROS 1 message type as its publisher declared it.

    Attributes:
        msg_type: ``sensor_msgs/Imu``.
        md5sum: the type's md5sum.
        text: the full definition (``gendeps --cat`` form: the type, then each dependency after
            a ``====`` line and ``MSG: pkg/Type``), as rosbag stores it.
    """

    msg_type: str
    md5sum: str
    text: str


class ScraperState:
    """The newest report of one scraper process (see the module text)."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.proc = proc
        self.definition: Ros1Definition | None = None
        self.defined = threading.Event()
        #: caller ids of the publishers the scraper has an open connection to
        self.publishers: tuple[str, ...] = ()
        self.received = 0
        self.forwarded = 0
        self.failed = 0
        self.ended = threading.Event()

    @property
    def running(self) -> bool:
        return self.proc.poll() is None and not self.ended.is_set()

    def follow(self) -> None:
        """Read the scraper's lines until it exits (run in a thread)."""
        out = self.proc.stdout
        if out is None:
            self.ended.set()
            return
        try:
            for line in out:
                kind, _, body = line.partition(" ")
                if kind not in ("DEF", "STATE"):
                    continue
                try:
                    data = json.loads(body)
                except ValueError:
                    logger.debug("scraper line not understood: %r", line)
                    continue
                if kind == "DEF":
                    self.definition = Ros1Definition(
                        msg_type=str(data["type"]),
                        md5sum=str(data["md5sum"]),
                        text=str(data["definition"]),
                    )
                    self.defined.set()
                else:
                    self.publishers = tuple(data.get("publishers", ()))
                    self.received = int(data.get("received", 0))
                    self.forwarded = int(data.get("forwarded", 0))
                    self.failed = int(data.get("failed", 0))
        except (OSError, ValueError):  # the pipe was closed under us at shutdown
            pass
        finally:
            self.ended.set()
            self.defined.set()  # nobody waits for a definition that cannot come


@dataclass(frozen=True, slots=True, kw_only=True)
class Offered:
    """A ROS 2 topic a publisher offers on the domain, as the ROS 2 scraper found it."""

    topic: str
    msgtype: str
    reliability: str
    durability: str


class Ros2Reports:
    """What the ROS 2 scraper reports, by topic (see the module text); :meth:`follow` in a thread.

    Attributes:
        states: topic → its :class:`ScraperState` (publishers: matched DDS writer handles).
        offered: topic → :class:`Offered`, every ROS 2 topic published on the domain (the
            scraper reports them with ``--discover``).
    """

    def __init__(self, proc: subprocess.Popen[str], states: dict[str, ScraperState]) -> None:
        self.proc = proc
        self.states = states
        self.offered: dict[str, Offered] = {}
        #: topic → None once added, else the scraper's error
        self.answers: dict[str, str | None] = {}
        #: topics whose stream the scraper made (``STREAM``), while they await their reader
        self.streams: set[str] = set()
        self.answered = threading.Condition()
        self.ended = threading.Event()

    def state(self, topic: str) -> ScraperState:
        """The topic's state, made on first use (by the thread that adds topics, never by
        :meth:`follow`: the dict is iterated there); ROS 2 sends no definitions: none is awaited."""
        state = self.states.get(topic)
        if state is None:
            state = ScraperState(self.proc)
            state.defined.set()
            self.states[topic] = state
        return state

    def wait_answer(self, topic: str, timeout_s: float, *, stream: bool = False) -> str | None:
        """None once ``topic`` was added (with ``stream``: once its stream exists); the
        scraper's error, or why no answer came."""
        with self.answered:
            self.answered.wait_for(
                lambda: (
                    topic in self.answers
                    or (stream and topic in self.streams)
                    or self.ended.is_set()
                ),
                timeout=timeout_s,
            )
            if stream and topic in self.streams:
                self.streams.discard(topic)
                return None
            if topic in self.answers:
                return self.answers.pop(topic)
        return "the ROS 2 scraper exited" if self.ended.is_set() else "no answer from the scraper"

    def follow(self) -> None:
        """Read the scraper's lines until it exits (run in a thread)."""
        out = self.proc.stdout
        try:
            for line in out or ():
                kind, _, body = line.partition(" ")
                if kind not in ("STATE", "OFFERED", "STREAM", "ADDED", "FAILED"):
                    continue
                try:
                    data = json.loads(body)
                    topic = str(data["topic"])
                except (ValueError, KeyError):
                    logger.debug("ROS 2 scraper line not understood: %r", line)
                    continue
                if kind == "STATE":
                    state = self.states.get(topic)  # made by the core when it adds the topic
                    if state is None:
                        continue
                    state.publishers = tuple(data.get("publishers", ()))
                    state.received = int(data.get("received", 0))
                    state.forwarded = int(data.get("forwarded", 0))
                    state.failed = int(data.get("failed", 0))
                elif kind == "OFFERED":
                    self.offered[topic] = Offered(
                        topic=topic,
                        msgtype=str(data["msgtype"]),
                        reliability=str(data["reliability"]),
                        durability=str(data["durability"]),
                    )
                elif kind == "STREAM":
                    with self.answered:
                        self.streams.add(topic)
                        self.answered.notify_all()
                else:
                    with self.answered:
                        self.answers[topic] = None if kind == "ADDED" else str(data.get("error"))
                        self.answered.notify_all()
        except (OSError, ValueError):  # the pipe was closed under us at shutdown
            pass
        finally:
            for state in self.states.values():
                state.ended.set()
            with self.answered:
                self.ended.set()
                self.answered.notify_all()
