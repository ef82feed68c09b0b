"""The decoders in use: the ones redrive ships plus the installed ``redrive.decoders`` plugins.

A decoder plugin is a class following :class:`~redrive.io.ros.decoders.Decoder` (constructed with no
arguments), declared in its distribution's ``pyproject.toml``::

    [project.entry-points."redrive.decoders"]
    radar-scan = "my_radar.decoders:RadarScanDecoder"

It is loaded by the one plugin loader (:mod:`redrive.plugins`) the first time a message type is
looked up; :func:`reload_decoders` reads the entry points again (after installing one in a running
process).  A plugin that fails to load, or claims a type another decoder has, is reported in a
warning and left out: the other decoders keep working.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any

from redrive.errors import PluginError, UnsupportedMessageError
from redrive.io.base import LogMessage, ReaderCapabilities, TopicInfo, normalize_msgtype
from redrive.io.ros.decoders._common import describe
from redrive.io.ros.decoders.base import Decoded, DecodedKind, Decoder, Deserialize
from redrive.io.ros.decoders.camera_info import CameraInfoDecoder
from redrive.io.ros.decoders.image import CompressedImageDecoder, ImageDecoder
from redrive.io.ros.decoders.lights import TrafficLightStateArrayDecoder
from redrive.io.ros.decoders.motion import OdometryDecoder, PoseDecoder, TwistDecoder
from redrive.io.ros.decoders.objects import (
    Detection3DArrayDecoder,
    GroundTruthObjectArrayDecoder,
    MarkerArrayDecoder,
    ObjectArrayDecoder,
)
from redrive.io.ros.decoders.pointcloud2 import PointCloud2Decoder
from redrive.io.ros.decoders.sensors import ImuDecoder, LaserScanDecoder, NavSatFixDecoder
from redrive.io.ros.decoders.tf import TFMessageDecoder
from redrive.io.ros.decoders.velodyne import VelodyneScanDecoder
from redrive.plugins import DECODERS, forget_entry_points, installed_plugins
from redrive.types import SensorType

__all__ = [
    "DEFAULT_DECODERS",
    "active_decoders",
    "build_registry",
    "capabilities_of",
    "decode",
    "decoder_for",
    "reload_decoders",
    "topic_kind",
]

logger = logging.getLogger(__name__)


def build_registry(decoders: Iterable[Decoder]) -> Mapping[str, Decoder]:
    """A read-only msgtype → decoder mapping.

    Raises:
        PluginError: two decoders claim the same message type.
    """
    out: dict[str, Decoder] = {}
    for decoder in decoders:
        _add(out, decoder)
    return MappingProxyType(out)


def _add(out: dict[str, Decoder], decoder: Decoder) -> None:
    names = [normalize_msgtype(raw) for raw in decoder.msgtypes]
    for msgtype in names:
        if msgtype in out:
            msg = (
                f"decoders {out[msgtype].name!r} and {decoder.name!r} both claim {msgtype}; "
                "give each message type one decoder"
            )
            raise PluginError(msg)
    for msgtype in names:
        out[msgtype] = decoder


#: The decoders redrive ships, by ROS 2 style message type.
DEFAULT_DECODERS: Mapping[str, Decoder] = build_registry(
    [
        PointCloud2Decoder(),
        VelodyneScanDecoder(),
        ImageDecoder(),
        CompressedImageDecoder(),
        CameraInfoDecoder(),
        ImuDecoder(),
        LaserScanDecoder(),
        NavSatFixDecoder(),
        OdometryDecoder(),
        PoseDecoder(),
        TwistDecoder(),
        TFMessageDecoder(),
        MarkerArrayDecoder(),
        Detection3DArrayDecoder(),
        ObjectArrayDecoder(),
        GroundTruthObjectArrayDecoder(),
        TrafficLightStateArrayDecoder(),
    ]
)


def _check_decoder(obj: object) -> str | None:
    """What keeps ``obj`` (a class) from being a decoder plugin, or None."""
    decode_method = getattr(obj, "decode", None)
    if not callable(decode_method):
        return "is not a decoder: it has no decode(message, deserialize) method"
    name = getattr(obj, "name", None)
    msgtypes = getattr(obj, "msgtypes", None)
    if not isinstance(name, str) or not name:
        return ": name must be a non-empty str (class attribute)"
    if not (isinstance(msgtypes, tuple) and msgtypes and all(isinstance(m, str) for m in msgtypes)):
        return (
            f": msgtypes must be a non-empty tuple of message type names "
            f"('my_msgs/msg/RadarScan',), got {msgtypes!r}"
        )
    kind = getattr(obj, "kind", None)
    if not isinstance(kind, DecodedKind):
        return f": kind must be a redrive.io.ros.decoders.DecodedKind, got {kind!r}"
    sensor_type = getattr(obj, "sensor_type", None)
    if kind is DecodedKind.SENSOR and not isinstance(sensor_type, SensorType):
        return f": a SENSOR decoder names its sensor_type (a SensorType), got {sensor_type!r}"
    return None


@functools.cache
def active_decoders() -> Mapping[str, Decoder]:
    """Message type → decoder: the ones redrive ships and the installed decoder plugins."""
    out = dict(DEFAULT_DECODERS)
    registry = installed_plugins(DECODERS, _check_decoder)
    for name, cls in registry.items():
        try:
            decoder: Decoder = cls()
            _add(out, decoder)
        except PluginError as err:
            logger.warning("decoder plugin %s (%s) left out: %s", name, registry.target(name), err)
        except Exception as err:
            logger.warning(
                "decoder plugin %s (%s) left out: constructing it raised %s: %s",
                name,
                registry.target(name),
                type(err).__name__,
                err,
            )
    return MappingProxyType(out)


#: decoder_for's answers by the type name as given: a lookup per message, so the name is not
#: normalised again every time.  Emptied by :func:`reload_decoders`.
_BY_GIVEN_NAME: dict[str, Decoder | None] = {}
_UNKNOWN: Any = object()


def reload_decoders() -> None:
    """Read the ``redrive.decoders`` entry points again at the next lookup."""
    active_decoders.cache_clear()
    forget_entry_points()
    _BY_GIVEN_NAME.clear()


def decoder_for(msgtype: str) -> Decoder | None:
    """The decoder of a message type (ROS 1 or ROS 2 spelling), or None."""
    try:
        return _BY_GIVEN_NAME[msgtype]
    except KeyError:
        pass
    decoder = active_decoders().get(normalize_msgtype(msgtype))
    if len(_BY_GIVEN_NAME) > 1024:
        _BY_GIVEN_NAME.clear()
    _BY_GIVEN_NAME[msgtype] = decoder
    return decoder


def topic_kind(info: TopicInfo) -> tuple[DecodedKind, SensorType | None] | None:
    """How a topic's values are used — (kind, sensor type) — or None when nothing decodes it.

    A ``native`` topic says so itself (its reader sets ``TopicInfo.kind``); a message-typed
    topic's decoder says.
    """
    if info.encoding == "native":
        return None if info.kind is None else (info.kind, info.sensor_type)
    decoder = decoder_for(info.msgtype)
    return None if decoder is None else (decoder.kind, decoder.sensor_type)


def capabilities_of(topics: Iterable[TopicInfo], *, message_typed: bool) -> ReaderCapabilities:
    """What a log with these topics can provide: transforms, objects (usable as ground truth)
    and ego motion, by the kind of each topic (:func:`topic_kind`)."""
    kinds = {found[0] for info in topics if (found := topic_kind(info)) is not None}
    return ReaderCapabilities(
        message_typed=message_typed,
        has_tf=DecodedKind.TRANSFORMS in kinds,
        has_ground_truth=DecodedKind.OBJECTS in kinds,
        has_ego_pose=DecodedKind.VEHICLE_STATE in kinds,
    )


def decode(message: LogMessage, deserialize: Deserialize) -> Decoded:
    """Decode one message; ``native`` messages that already hold a :class:`Decoded` pass through.

    Raises:
        UnsupportedMessageError: no decoder knows the type, or the message cannot be decoded.
    """
    if message.encoding == "native":
        if isinstance(message.payload, Decoded):
            return message.payload
        kind = type(message.payload).__name__
        msg = (
            f"native message on {describe(message)} carries a {kind}, not a Decoded; "
            "native readers must yield redrive.io.ros.decoders.Decoded payloads"
        )
        raise UnsupportedMessageError(msg)
    # decoder_for's cache read here first: one lookup a message, no call.
    decoder: Decoder | None = _BY_GIVEN_NAME.get(message.msgtype, _UNKNOWN)
    if decoder is _UNKNOWN:
        decoder = decoder_for(message.msgtype)
    if decoder is None:
        msg = (
            f"no decoder for {message.msgtype} on {describe(message)}; redrive decodes "
            f"{', '.join(sorted(active_decoders()))} — pass the messages through raw or add a "
            "decoder plugin (entry-point group redrive.decoders, docs/architecture.md)"
        )
        raise UnsupportedMessageError(msg)
    return decoder.decode(message, deserialize)
