"""Decoders: serialised ROS messages → redrive data-model values.

``decode(message, reader.deserialize)`` decodes one :class:`~redrive.io.base.LogMessage` with the
decoder of its type: one that redrive ships (:data:`DEFAULT_DECODERS`) or an installed plugin of
the ``redrive.decoders`` entry-point group (:func:`active_decoders`).  Nothing registers itself on
import; two decoders of one type are refused.
"""

from __future__ import annotations

from redrive.io.base import normalize_msgtype
from redrive.io.ros.decoders.base import Decoded, DecodedKind, DecodedValue, Decoder, Deserialize
from redrive.io.ros.decoders.camera_info import CameraInfoDecoder
from redrive.io.ros.decoders.image import CompressedImageDecoder, ImageDecoder
from redrive.io.ros.decoders.lights import TrafficLightStateArrayDecoder
from redrive.io.ros.decoders.motion import OdometryDecoder, PoseDecoder, TwistDecoder
from redrive.io.ros.decoders.objects import (
    Detection3DArrayDecoder,
    GroundTruthObjectArrayDecoder,
    MarkerArrayDecoder,
    ObjectArrayDecoder,
    object_class_from_text,
)
from redrive.io.ros.decoders.pointcloud2 import PointCloud2Decoder, read_cloud_layout
from redrive.io.ros.decoders.registry import (
    DEFAULT_DECODERS,
    active_decoders,
    build_registry,
    capabilities_of,
    decode,
    decoder_for,
    reload_decoders,
    topic_kind,
)
from redrive.io.ros.decoders.sensors import ImuDecoder, LaserScanDecoder, NavSatFixDecoder
from redrive.io.ros.decoders.tf import TFMessageDecoder
from redrive.io.ros.decoders.velodyne import VelodyneScanDecoder

__all__ = [
    "DEFAULT_DECODERS",
    "CameraInfoDecoder",
    "CompressedImageDecoder",
    "Decoded",
    "DecodedKind",
    "DecodedValue",
    "Decoder",
    "Deserialize",
    "Detection3DArrayDecoder",
    "GroundTruthObjectArrayDecoder",
    "ImageDecoder",
    "ImuDecoder",
    "LaserScanDecoder",
    "MarkerArrayDecoder",
    "NavSatFixDecoder",
    "ObjectArrayDecoder",
    "OdometryDecoder",
    "PointCloud2Decoder",
    "PoseDecoder",
    "TFMessageDecoder",
    "TrafficLightStateArrayDecoder",
    "TwistDecoder",
    "VelodyneScanDecoder",
    "active_decoders",
    "build_registry",
    "capabilities_of",
    "decode",
    "decoder_for",
    "normalize_msgtype",
    "object_class_from_text",
    "read_cloud_layout",
    "reload_decoders",
    "topic_kind",
]
