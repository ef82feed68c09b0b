"""ROS 1 topic discovery through the master's XML-RPC API (stdlib only: no rospy).

The ROS master answers every call with ``[code, status_message, value]``; ``code`` 1 is success.
:func:`list_topics` asks it ``getTopicTypes`` (topic → ``pkg/Type``) and ``getSystemState``
(topic → publishing and subscribing nodes), and says for each topic which redrive decoder — and so
which sensor type — would handle its messages, from the same decoder registry the log readers use
(:func:`redrive.io.ros.decoders.active_decoders`).

>>> from redrive.live.ros1 import list_topics, master_alive
>>> master_alive("http://127.0.0.1:11311")                      # doctest: +SKIP
True
>>> [t.name for t in list_topics("http://127.0.0.1:11311") if t.decodable]  # doctest: +SKIP
['/camera/image_raw', '/imu/data', '/velodyne_points']
"""

from __future__ import annotations

import http.client
import logging
import os
import socket
import xmlrpc.client
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit
from xml.parsers.expat import ExpatError

from redrive.errors import ConfigError, TransportError
from redrive.io.ros.decoders import DecodedKind, decoder_for
from redrive.types import SensorType

__all__ = [
    "CALLER_ID",
    "DEFAULT_MASTER_URI",
    "UNKNOWN_TYPE",
    "TopicInfo",
    "check_master_uri",
    "default_master_uri",
    "list_topics",
    "master_alive",
]

logger = logging.getLogger(__name__)

#: The master ROS tools use when ``ROS_MASTER_URI`` is not set (as an address, not ``localhost``).
DEFAULT_MASTER_URI = "http://127.0.0.1:11311"

#: The caller id redrive gives the master (it is not a registered node).
CALLER_ID = "/redrive"

#: ``msg_type`` of a topic the master knows no type of (only subscribers to any type).
UNKNOWN_TYPE = "*"

_WHAT_TO_DO = (
    "start a master (`roscore`, or `rosmaster --core -p PORT`) or point ROS_MASTER_URI / "
    "--master at the running one"
)


@dataclass(frozen=True, slots=True, kw_only=True)
class TopicInfo:
    """One topic a ROS 1 master knows, and how redrive would decode it.

    Attributes:
        name: the topic, ``/velodyne_points``.
        msg_type: the ROS 1 type as the master reports it, ``sensor_msgs/PointCloud2``;
            ``"*"`` when nobody registered a type (only subscribers to any type, ``rospy.AnyMsg``).
        publishers: the nodes publishing it, sorted.
        subscribers: the nodes subscribed to it, sorted.
        decoder: the name of the redrive decoder of ``msg_type`` (``"pointcloud2"``), or None.
        kind: what that decoder produces (sensor data, vehicle state, objects, transforms).
        sensor_type: the sensor the decoded messages feed (LIDAR, CAMERA, IMU, …), or None.
    """

    name: str
    msg_type: str
    publishers: tuple[str, ...] = ()
    subscribers: tuple[str, ...] = ()
    decoder: str | None = None
    kind: DecodedKind | None = None
    sensor_type: SensorType | None = None

    @property
    def decodable(self) -> bool:
        """True when a redrive decoder handles ``msg_type``."""
        return self.decoder is not None

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (enums as their values)."""
        return {
            "topic": self.name,
            "type": self.msg_type,
            "publishers": list(self.publishers),
            "subscribers": list(self.subscribers),
            "decodable": self.decodable,
            "decoder": self.decoder,
            "kind": self.kind.value if self.kind else None,
            "sensor_type": self.sensor_type.value if self.sensor_type else None,
        }


def default_master_uri(environ: Mapping[str, str] | None = None) -> str:
    """``$ROS_MASTER_URI`` when set and not empty, else :data:`DEFAULT_MASTER_URI`."""
    env = os.environ if environ is None else environ
    return env.get("ROS_MASTER_URI", "").strip() or DEFAULT_MASTER_URI


def check_master_uri(uri: str) -> str:
    """The URI without surrounding blanks or trailing slash, when it looks like ``http://HOST:PORT``.

    Raises:
        ConfigError: the URI is not an http URL with a host and a port.
    """
    clean = uri.strip().rstrip("/")
    try:
        parts = urlsplit(clean)
        port = parts.port
    except ValueError as err:
        msg = f"ROS master URI {uri!r} is not a URL ({err}); give it as http://HOST:PORT"
        raise ConfigError(msg) from err
    if parts.scheme != "http" or not parts.hostname or port is None:
        msg = (
            f"ROS master URI {uri!r} is not of the form http://HOST:PORT "
            f"(for example {DEFAULT_MASTER_URI}); check ROS_MASTER_URI or --master"
        )
        raise ConfigError(msg)
    return clean


class _TimeoutTransport(xmlrpc.client.Transport):
    """An XML-RPC transport whose socket operations give up after ``timeout_s``."""

    def __init__(self, timeout_s: float) -> None:
        super().__init__()
        self._timeout_s = timeout_s

    def make_connection(self, host: str | tuple[str, dict[str, str]]) -> http.client.HTTPConnection:
        conn = super().make_connection(host)
        conn.timeout = self._timeout_s
        return conn


def _call(uri: str, method: str, *, timeout_s: float) -> Any:
    """``value`` of the master's ``[code, status, value]`` answer to ``method(CALLER_ID)``.

    Raises:
        TransportError: the master cannot be reached, does not answer in time, does not answer
            as a ROS master, or reports a failure.
    """
    logger.debug("ROS master %s: %s", uri, method)
    try:
        with xmlrpc.client.ServerProxy(
            uri, transport=_TimeoutTransport(timeout_s), allow_none=True
        ) as proxy:
            answer = getattr(proxy, method)(CALLER_ID)
    except ConnectionRefusedError as err:
        msg = f"no ROS master at {uri} (connection refused); {_WHAT_TO_DO}"
        raise TransportError(msg) from err
    except TimeoutError as err:
        msg = (
            f"the ROS master at {uri} did not answer {method} within {timeout_s:g} s; check that "
            f"the address is right and the master is not stuck, or {_WHAT_TO_DO}"
        )
        raise TransportError(msg) from err
    except socket.gaierror as err:
        host = urlsplit(uri).hostname
        msg = f"cannot resolve the host {host!r} of ROS master URI {uri} ({err}); {_WHAT_TO_DO}"
        raise TransportError(msg) from err
    except OSError as err:
        msg = f"cannot reach the ROS master at {uri} ({err}); {_WHAT_TO_DO}"
        raise TransportError(msg) from err
    except (xmlrpc.client.Error, http.client.HTTPException, ExpatError) as err:
        msg = (
            f"{uri} answered {method}, but not as a ROS master ({type(err).__name__}: {err}); "
            "check that ROS_MASTER_URI / --master names the master's port"
        )
        raise TransportError(msg) from err
    if not (isinstance(answer, list | tuple) and len(answer) == 3):
        msg = f"{uri} answered {method} with {answer!r:.200}, not [code, status, value]; is it a ROS master?"
        raise TransportError(msg)
    code, status, value = answer
    if code != 1:
        msg = f"the ROS master at {uri} refused {method} (code {code}): {status}"
        raise TransportError(msg)
    return value


def master_alive(uri: str, *, timeout_s: float = 1.0) -> bool:
    """True when a ROS master answers ``getSystemState`` at ``uri`` within ``timeout_s``.

    Raises:
        ConfigError: ``uri`` is not of the form ``http://HOST:PORT``.
    """
    clean = check_master_uri(uri)
    try:
        _call(clean, "getSystemState", timeout_s=timeout_s)
    except TransportError as err:
        logger.debug("%s", err)
        return False
    return True


def _pairs(value: Any, *, what: str, uri: str) -> list[tuple[str, Any]]:
    """``[[name, x], …]`` as a list of tuples; TransportError when the answer has another shape."""
    if not isinstance(value, list | tuple) or not all(
        isinstance(item, list | tuple) and len(item) == 2 and isinstance(item[0], str)
        for item in value
    ):
        msg = f"the ROS master at {uri} sent malformed {what}: {value!r:.200}"
        raise TransportError(msg)
    return [(str(item[0]), item[1]) for item in value]


def _nodes(value: Any, *, what: str, uri: str) -> tuple[str, ...]:
    if not isinstance(value, list | tuple) or not all(isinstance(n, str) for n in value):
        msg = f"the ROS master at {uri} sent malformed {what}: {value!r:.200}"
        raise TransportError(msg)
    return tuple(sorted(value))


def list_topics(
    master_uri: str,
    *,
    timeout_s: float = 2.0,
) -> list[TopicInfo]:
    """Every topic with a publisher or a subscriber on the ROS 1 master at ``master_uri``, by name.

    Args:
        master_uri: ``http://HOST:PORT`` of the master (see :func:`default_master_uri`).
        timeout_s: how long each of the two XML-RPC calls may take.

    Raises:
        ConfigError: ``master_uri`` is not of the form ``http://HOST:PORT``.
        TransportError: no master answers at ``master_uri``, or its answer is not a master's.
    """
    uri = check_master_uri(master_uri)
    types = dict(
        _pairs(_call(uri, "getTopicTypes", timeout_s=timeout_s), what="topic types", uri=uri)
    )
    state = _call(uri, "getSystemState", timeout_s=timeout_s)
    if not (isinstance(state, list | tuple) and len(state) == 3):
        msg = f"the ROS master at {uri} sent a malformed system state: {state!r:.200}"
        raise TransportError(msg)
    publishers = {
        topic: _nodes(nodes, what=f"publishers of {topic}", uri=uri)
        for topic, nodes in _pairs(state[0], what="publishers", uri=uri)
    }
    subscribers = {
        topic: _nodes(nodes, what=f"subscribers of {topic}", uri=uri)
        for topic, nodes in _pairs(state[1], what="subscribers", uri=uri)
    }
    topics = []
    # The master never forgets a type, so topics come from the system state (as `rostopic list`):
    # a topic whose last publisher and subscriber are gone is not listed.
    for name in sorted(set(publishers) | set(subscribers)):
        msg_type = str(types.get(name) or UNKNOWN_TYPE)
        decoder = decoder_for(msg_type) if msg_type != UNKNOWN_TYPE else None
        topics.append(
            TopicInfo(
                name=name,
                msg_type=msg_type,
                publishers=publishers.get(name, ()),
                subscribers=subscribers.get(name, ()),
                decoder=decoder.name if decoder else None,
                kind=decoder.kind if decoder else None,
                sensor_type=decoder.sensor_type if decoder else None,
            )
        )
    logger.debug("ROS master %s: %d topics", uri, len(topics))
    return topics
