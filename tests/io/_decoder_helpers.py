"""Build real serialised ROS messages (rosbags' serialisers) for the decoder tests."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from functools import cache
from typing import Any, Literal

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

from redrive.io.base import LogMessage
from redrive.io.ros.typestore import typestore_for

RosVersion = Literal[1, 2]

_FLOATS = {"float32", "float64"}


@cache
def store(ros_version: RosVersion) -> Typestore:
    """The typestore redrive builds for a log without embedded definitions."""
    return typestore_for(ros_version)[0]


def _base_default(name: str) -> Any:
    if name == "string":
        return ""
    if name == "bool":
        return False
    return 0.0 if name in _FLOATS else 0


def _np_dtype(name: str) -> Any:
    return {"bool": np.bool_, "octet": np.uint8, "char": np.uint8, "byte": np.uint8}.get(name, name)


def _value(ts: Typestore, node: tuple[Any, Any], given: Any) -> Any:
    kind, detail = node
    if kind == Nodetype.BASE:
        return _base_default(detail[0]) if given is None else given
    if kind == Nodetype.NAME:
        if given is None:
            return make(ts, detail)
        return make(ts, detail, **given) if isinstance(given, Mapping) else given
    (sub_kind, sub_detail), size = detail
    if sub_kind == Nodetype.BASE:
        if sub_detail[0] == "string":
            return (
                list(given) if given is not None else [""] * (size if kind == Nodetype.ARRAY else 0)
            )
        count = size if kind == Nodetype.ARRAY else 0
        dtype = _np_dtype(sub_detail[0])
        if given is None:
            return np.zeros(count, dtype=dtype)
        return np.asarray(given, dtype=dtype)
    if given is None:
        return [make(ts, sub_detail) for _ in range(size if kind == Nodetype.ARRAY else 0)]
    return [_value(ts, (sub_kind, sub_detail), item) for item in given]


def make(ts: Typestore, typename: str, **values: Any) -> Any:
    """A message object of ``typename``; unspecified fields default, nested fields as dicts."""
    _, fields = ts.fielddefs[typename]
    unknown = set(values) - {name for name, _ in fields}
    if unknown:
        msg = f"{typename} has no fields {sorted(unknown)}"
        raise TypeError(msg)
    kwargs = {name: _value(ts, node, values.get(name)) for name, node in fields}
    return ts.types[typename](**kwargs)


def header(ros_version: RosVersion, stamp_ns: int, frame_id: str) -> dict[str, Any]:
    """Header fields (with ``seq`` for ROS 1)."""
    out: dict[str, Any] = {
        "stamp": {"sec": stamp_ns // 1_000_000_000, "nanosec": stamp_ns % 1_000_000_000},
        "frame_id": frame_id,
    }
    if ros_version == 1:
        out["seq"] = 7
    return out


def serialize(
    ros_version: RosVersion,
    msg: Any,
    typename: str,
    *,
    little_endian: bool = True,
    ts: Typestore | None = None,
) -> bytes:
    ts = ts or store(ros_version)
    if ros_version == 1:
        return bytes(ts.serialize_ros1(msg, typename))
    return bytes(ts.serialize_cdr(msg, typename, little_endian=little_endian))


def log_message(
    ros_version: RosVersion,
    typename: str,
    *,
    topic: str = "/topic",
    log_time_ns: int = 1_700_000_000_000_000_000,
    little_endian: bool = True,
    ts: Typestore | None = None,
    **values: Any,
) -> LogMessage:
    """A LogMessage holding a real serialised ``typename`` message built from ``values``."""
    ts = ts or store(ros_version)
    msg = make(ts, typename, **values)
    raw = serialize(ros_version, msg, typename, little_endian=little_endian, ts=ts)
    return LogMessage(
        topic=topic,
        msgtype=typename,
        log_time_ns=log_time_ns,
        encoding="ros1" if ros_version == 1 else "cdr",
        raw=raw,
    )


def deserializer(stores: Mapping[int, Typestore] | None = None) -> Callable[[LogMessage], object]:
    """``deserialize(message)`` with redrive's default typestores (or the given ones)."""

    def deserialize(message: LogMessage) -> object:
        if message.encoding == "ros1":
            ts = (stores or {}).get(1) or store(1)
            return ts.deserialize_ros1(bytes(message.raw), message.msgtype)
        ts = (stores or {}).get(2) or store(2)
        return ts.deserialize_cdr(bytes(message.raw), message.msgtype)

    return deserialize
