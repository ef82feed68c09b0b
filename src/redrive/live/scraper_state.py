"""What a ROS 1 scraper process reports on its stdout, as the core sees it.

After ``READY`` a scraper (:mod:`redrive.live.ros1_scraper`) prints ``DEF {json}`` — the type,
md5sum and full message definition of its topic from the publisher's connection header — before
it forwards the first message, and ``STATE {json}`` — the publishers it is connected to and its
counts — whenever they change. :class:`ScraperState` follows those lines in a thread.
"""

from __future__ import annotations

import json
import logging
import subprocess
import threading
from dataclasses import dataclass

__all__ = ["Ros1Definition", "ScraperState"]

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
