"""The decoder registry: msgtype → decoder, plus the per-topic :class:`MessageDecoder` helper."""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from types import MappingProxyType

from redrive.errors import PluginError, UnsupportedMessageError
from redrive.io.base import LogMessage
from redrive.io.decoders._common import describe
from redrive.io.decoders.base import Decoded, Decoder, Deserialize
from redrive.io.decoders.camera_info import CameraInfoDecoder
from redrive.io.decoders.image import CompressedImageDecoder, ImageDecoder
from redrive.io.decoders.motion import OdometryDecoder, PoseDecoder, TwistDecoder
from redrive.io.decoders.objects import (
    Detection3DArrayDecoder,
    GroundTruthObjectArrayDecoder,
    MarkerArrayDecoder,
    ObjectArrayDecoder,
)
from redrive.io.decoders.pointcloud2 import PointCloud2Decoder
from redrive.io.decoders.sensors import ImuDecoder, LaserScanDecoder, NavSatFixDecoder
from redrive.io.decoders.tf import TFMessageDecoder

__all__ = [
    "DEFAULT_DECODERS",
    "MessageDecoder",
    "build_registry",
    "decode",
    "decoder_for",
    "normalize_msgtype",
]

logger = logging.getLogger(__name__)


def normalize_msgtype(msgtype: str) -> str:
    """``pkg/msg/Type`` for ROS 2 names and ROS 1 names alike (``sensor_msgs/PointCloud2``)."""
    parts = msgtype.strip().strip("/").split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return "/".join(parts)


def build_registry(decoders: Iterable[Decoder]) -> Mapping[str, Decoder]:
    """A read-only msgtype → decoder mapping.

    Raises:
        PluginError: two decoders claim the same message type.
    """
    out: dict[str, Decoder] = {}
    for decoder in decoders:
        for raw_name in decoder.msgtypes:
            msgtype = normalize_msgtype(raw_name)
            if msgtype in out:
                msg = (
                    f"decoders {out[msgtype].name!r} and {decoder.name!r} both claim {msgtype}; "
                    "give each message type one decoder"
                )
                raise PluginError(msg)
            out[msgtype] = decoder
    return MappingProxyType(out)


#: The decoders redrive ships, by ROS 2 style message type.
DEFAULT_DECODERS: Mapping[str, Decoder] = build_registry(
    [
        PointCloud2Decoder(),
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
    ]
)


def decoder_for(msgtype: str, registry: Mapping[str, Decoder] = DEFAULT_DECODERS) -> Decoder | None:
    """The decoder of a message type (ROS 1 or ROS 2 spelling), or None."""
    return registry.get(normalize_msgtype(msgtype))


def decode(
    message: LogMessage,
    deserialize: Deserialize,
    *,
    registry: Mapping[str, Decoder] = DEFAULT_DECODERS,
) -> Decoded:
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
            "native readers must yield redrive.io.decoders.Decoded payloads"
        )
        raise UnsupportedMessageError(msg)
    decoder = decoder_for(message.msgtype, registry)
    if decoder is None:
        msg = (
            f"no decoder for {message.msgtype} on {describe(message)}; redrive decodes "
            f"{', '.join(sorted(registry))} — pass the messages through raw or add a decoder"
        )
        raise UnsupportedMessageError(msg)
    return decoder.decode(message, deserialize)


class MessageDecoder:
    """Decodes a stream of messages with one ``deserialize``, never raising for a bad topic.

    The decoder is looked up once per topic.  A topic without a decoder logs one warning and its
    messages come back as None (raw pass-through); a message that fails to decode logs a warning
    the first time on its topic (DEBUG afterwards), is counted in :attr:`failures` and gives None —
    unless ``strict`` is set, then the :class:`UnsupportedMessageError` propagates.
    """

    def __init__(
        self,
        deserialize: Deserialize,
        *,
        registry: Mapping[str, Decoder] = DEFAULT_DECODERS,
        strict: bool = False,
    ) -> None:
        self._deserialize = deserialize
        self._registry = registry
        self._strict = strict
        self._by_topic: dict[tuple[str, str], Decoder | None] = {}
        #: topic → number of messages that failed to decode.
        self.failures: dict[str, int] = {}

    def decoder_for_topic(self, topic: str, msgtype: str) -> Decoder | None:
        """The (cached) decoder of a topic; warns once when there is none."""
        key = (topic, msgtype)
        try:
            return self._by_topic[key]
        except KeyError:
            pass
        decoder = decoder_for(msgtype, self._registry)
        if decoder is None:
            logger.warning(
                "no decoder for %s on topic %r: its messages pass through undecoded",
                msgtype,
                topic,
            )
        self._by_topic[key] = decoder
        return decoder

    def decode(self, message: LogMessage) -> Decoded | None:
        """The decoded message, or None when its topic has no decoder or it does not decode."""
        if message.encoding == "native" and isinstance(message.payload, Decoded):
            return message.payload
        decoder = self.decoder_for_topic(message.topic, message.msgtype)
        if decoder is None:
            return None
        try:
            return decoder.decode(message, self._deserialize)
        except UnsupportedMessageError as err:
            if self._strict:
                raise
            count = self.failures.get(message.topic, 0)
            self.failures[message.topic] = count + 1
            level = logging.WARNING if count == 0 else logging.DEBUG
            logger.log(level, "skipping an undecodable message: %s", err)
            return None

    __call__ = decode


#: Alias: the helper that decodes messages topic by topic.
TopicDecoder = MessageDecoder
