"""Object lists → ``tuple[DetectedObject, ...]`` (kind OBJECTS).

* ``visualization_msgs/msg/MarkerArray``: CUBE markers being added; every other marker type and
  DELETE / DELETEALL actions are ignored.  ``id`` → object_id, ``ns`` text → class.
* ``vision_msgs/msg/Detection3DArray``: ROS 2 vision_msgs 4.x (``results[].hypothesis.class_id``
  / ``score``, ``id`` string) and the ROS 1 noetic layout (``results[].id`` / ``score``,
  optional ``tracking_id``).  The best-scoring hypothesis gives class and confidence; class names
  map by :func:`object_class_from_text`, numeric class ids are UNKNOWN.
* ``derived_object_msgs/msg/ObjectArray`` (CARLA ROS bridge ground truth): classification
  constants → class; SolidPrimitive BOX dimensions x, y, z = length, width, height.

Object ids that are not integers (vision_msgs 4.x ``id`` strings) become a stable CRC-32 of the
text, so the same string always gives the same id; an empty id is -1.
"""

from __future__ import annotations

import functools
import math
import re
import zlib
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from redrive.errors import UnsupportedMessageError
from redrive.geometry.quaternion import euler_from_quaternion
from redrive.io.base import LogMessage
from redrive.io.ros.decoders._common import header_stamp_ns, quat, unsupported, vec3
from redrive.io.ros.decoders._gt_bytes import GroundTruthBytes, read_ground_truth
from redrive.io.ros.decoders.base import Decoded, DecodedKind, Deserialize
from redrive.types import Box3D, DetectedObject, ObjectClass, SensorType

__all__ = [
    "DERIVED_OBJECT_CLASSES",
    "Detection3DArrayDecoder",
    "GroundTruthObjectArrayDecoder",
    "MarkerArrayDecoder",
    "ObjectArrayDecoder",
    "object_class_from_text",
    "object_id_from_text",
]

# Most specific first: "vehicle.truck" is a truck, "vehicle.bicycle" a bicycle.
_CLASS_WORDS: tuple[tuple[ObjectClass, frozenset[str]], ...] = (
    (ObjectClass.MOTORCYCLE, frozenset({"motorcycle", "motorbike", "motorcyclist", "moped"})),
    (ObjectClass.BICYCLE, frozenset({"bicycle", "bike", "cyclist", "bicyclist"})),
    (ObjectClass.TRUCK, frozenset({"truck", "bus", "buses", "trailer", "lorry"})),
    (
        ObjectClass.PEDESTRIAN,
        frozenset({"pedestrian", "person", "people", "walker", "human", "ped", "child", "adult"}),
    ),
    (
        ObjectClass.STATIC,
        frozenset({"barrier", "cone", "trafficcone", "sign", "pole", "static", "bollard"}),
    ),
    (ObjectClass.VEHICLE, frozenset({"car", "vehicle", "van", "suv", "sedan", "automobile"})),
    (ObjectClass.OTHER, frozenset({"misc", "other", "animal", "tram"})),
)


@functools.lru_cache(maxsize=1024)
def object_class_from_text(text: str) -> ObjectClass:
    """An ObjectClass from a class name (``Car``, ``pedestrian``, ``vehicle.truck``, a marker ns).

    Numbers, empty and unrecognised text give UNKNOWN.  Remembered per text: a log repeats a
    handful of class names in every message.
    """
    words = {w for w in re.split(r"[^a-z0-9]+", text.lower()) if w}
    words |= {w[:-1] for w in words if len(w) > 3 and w.endswith("s")}
    for cls, vocabulary in _CLASS_WORDS:
        if words & vocabulary:
            return cls
    return ObjectClass.UNKNOWN


def object_id_from_text(text: str) -> int:
    """An int object id from an id string: the integer it spells, else a stable CRC-32; -1 if empty."""
    text = text.strip()
    if not text:
        return -1
    try:
        return int(text)
    except ValueError:
        return zlib.crc32(text.encode("utf-8")) & 0x7FFFFFFF


def _box(message: LogMessage, center: Any, orientation: Any, size: tuple[float, ...]) -> Any:
    return _box_of(message, vec3(center), quat(orientation), size)


def _box_of(
    message: LogMessage,
    center: tuple[float, float, float],
    q: tuple[float, float, float, float],
    size: tuple[float, ...],
) -> Any:
    if q == (0.0, 0.0, 0.0, 0.0):
        q = (0.0, 0.0, 0.0, 1.0)
    try:
        roll_rad, pitch_rad, yaw_rad = euler_from_quaternion(q)
        box = Box3D(center=np.array(center), size=np.abs(np.array(size)), yaw_rad=yaw_rad)
    except ValueError as err:
        raise unsupported(message, f"object box is invalid: {err}", "check the publisher") from err
    return box, np.array([yaw_rad, pitch_rad, roll_rad])


class MarkerArrayDecoder:
    """``visualization_msgs/msg/MarkerArray`` CUBE markers → DetectedObjects (class from ``ns``)."""

    name = "marker_array"
    msgtypes: tuple[str, ...] = ("visualization_msgs/msg/MarkerArray",)
    kind = DecodedKind.OBJECTS
    sensor_type: SensorType | None = None

    _CUBE = 1
    _ADD = 0

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        out: list[DetectedObject] = []
        for marker in msg.markers:
            if int(marker.type) != self._CUBE or int(marker.action) != self._ADD:
                continue
            size = vec3(marker.scale)
            box, orientation = _box(message, marker.pose.position, marker.pose.orientation, size)
            out.append(
                DetectedObject(
                    object_id=int(marker.id),
                    object_class=object_class_from_text(str(marker.ns)),
                    box=box,
                    orientation=orientation,
                )
            )
        first = msg.markers[0] if msg.markers else None
        stamp_ns = header_stamp_ns(first.header, message) if first else message.log_time_ns
        frame_id = str(first.header.frame_id) if first else ""
        return Decoded(stamp_ns=stamp_ns, frame_id=frame_id, value=tuple(out))


def _confidence(score: float) -> float:
    return min(1.0, max(0.0, score)) if math.isfinite(score) else 0.0


class Detection3DArrayDecoder:
    """``vision_msgs/msg/Detection3DArray`` (4.x and noetic layouts) → DetectedObjects."""

    name = "detection3d_array"
    msgtypes: tuple[str, ...] = ("vision_msgs/msg/Detection3DArray",)
    kind = DecodedKind.OBJECTS
    sensor_type: SensorType | None = None

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        out = [_from_detection(message, det) for det in msg.detections]
        return Decoded(
            stamp_ns=header_stamp_ns(msg.header, message),
            frame_id=str(msg.header.frame_id),
            value=tuple(out),
        )


def _from_detection(message: LogMessage, det: Any, **extra: Any) -> DetectedObject:
    """One vision_msgs Detection3D (4.x or noetic layout) as a DetectedObject."""
    results = []
    for result in det.results:
        hyp = getattr(result, "hypothesis", None)
        class_id, score = (
            (hyp.class_id, hyp.score) if hyp is not None else (result.id, result.score)
        )
        results.append((str(class_id), float(score)))
    bbox = det.bbox
    center = getattr(bbox, "center", None) or bbox.origin
    raw_id = getattr(det, "id", None)
    if raw_id is None:
        raw_id = getattr(det, "tracking_id", "")
    return _detected(
        message,
        results=results,
        position=vec3(center.position),
        orientation=quat(center.orientation),
        size=vec3(bbox.size),
        raw_id=str(raw_id),
        **extra,
    )


def _detected(
    message: LogMessage,
    *,
    results: Iterable[tuple[str, float]],
    position: tuple[float, float, float],
    orientation: tuple[float, float, float, float],
    size: tuple[float, float, float],
    raw_id: str,
    **extra: Any,
) -> DetectedObject:
    """A DetectedObject from a detection's values: the best-scoring hypothesis (the first of
    equals) gives class and confidence."""
    best_class, best_score = "", None
    for class_id, score in results:
        if best_score is None or score > best_score:
            best_class, best_score = class_id, score
    box, euler = _box_of(message, position, orientation, size)
    return DetectedObject(
        object_id=object_id_from_text(raw_id),
        object_class=object_class_from_text(best_class),
        confidence=1.0 if best_score is None else _confidence(best_score),
        box=box,
        orientation=euler,
        **extra,
    )


class GroundTruthObjectArrayDecoder:
    """``redrive_msgs/msg/GroundTruthObjectArray`` → DetectedObjects with velocity, LiDAR point
    counts and visibility (what ``redrive synth`` writes as ground truth)."""

    name = "ground_truth_array"
    msgtypes: tuple[str, ...] = ("redrive_msgs/msg/GroundTruthObjectArray",)
    kind = DecodedKind.OBJECTS
    sensor_type: SensorType | None = None

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        read = read_ground_truth(message)
        if read is not None:
            return self._from_bytes(message, read)
        msg: Any = deserialize(message)
        n = len(msg.detections)
        if not len(msg.velocities) == len(msg.num_lidar_points) == len(msg.visible) == n:
            raise _not_parallel(
                message, n, len(msg.velocities), len(msg.num_lidar_points), len(msg.visible)
            )
        out = []
        for det, vel, points, visible in zip(
            msg.detections, msg.velocities, msg.num_lidar_points, msg.visible, strict=True
        ):
            out.append(
                _from_detection(
                    message,
                    det,
                    velocity=np.array(vec3(vel)),
                    num_lidar_points=None if points < 0 else int(points),
                    visible=None if visible < 0 else bool(visible),
                )
            )
        return Decoded(
            stamp_ns=header_stamp_ns(msg.header, message),
            frame_id=str(msg.header.frame_id),
            value=tuple(out),
        )

    @staticmethod
    def _from_bytes(message: LogMessage, read: GroundTruthBytes) -> Decoded:
        n = len(read.objects)
        if not len(read.velocities) == len(read.num_lidar_points) == len(read.visible) == n:
            raise _not_parallel(
                message, n, len(read.velocities), len(read.num_lidar_points), len(read.visible)
            )
        out = _ground_truth_objects(read) if n else []
        if out is None:  # a box _detected refuses: its error, for the first such object
            out = [
                _detected(
                    message,
                    results=obj.results,
                    position=obj.position,
                    orientation=obj.orientation,
                    size=obj.size,
                    raw_id=obj.raw_id,
                    velocity=np.array(vel),
                    num_lidar_points=None if points < 0 else int(points),
                    visible=None if visible < 0 else bool(visible),
                )
                for obj, vel, points, visible in zip(
                    read.objects, read.velocities, read.num_lidar_points, read.visible, strict=True
                )
            ]
        stamp_ns = read.stamp_sec * 1_000_000_000 + read.stamp_nanosec
        return Decoded(
            stamp_ns=stamp_ns if stamp_ns != 0 else message.log_time_ns,
            frame_id=read.frame_id,
            value=tuple(out),
        )


def _ground_truth_objects(read: GroundTruthBytes) -> list[DetectedObject] | None:
    """The objects ``_detected`` makes of ``read``'s detections, the same values, built as
    columns by :meth:`DetectedObject.many`; None when a box is not usable (a quaternion without
    a finite non-zero norm, a size that is not finite), for ``_detected`` to refuse as before."""
    objects = read.objects
    quats = np.array([obj.orientation for obj in objects], dtype=np.float64)
    quats[~quats.any(axis=1)] = (0.0, 0.0, 0.0, 1.0)
    # ``quaternion_normalized``'s norm, row by row: ``np.linalg.norm`` of a vector is
    # sqrt(q.dot(q)), and a vectorised sum of squares could round differently.
    norms = np.sqrt([q.dot(q) for q in quats])
    sizes = np.abs(np.array([obj.size for obj in objects], dtype=np.float64))
    if not (np.isfinite(norms).all() and (norms >= _QUAT_EPS).all() and np.isfinite(sizes).all()):
        return None
    eulers = [_euler(*q) for q in (quats / norms[:, None]).tolist()]
    classes = []
    confidences = []
    for obj in objects:
        best_class, best_score = "", None
        for class_id, score in obj.results:
            if best_score is None or score > best_score:
                best_class, best_score = class_id, score
        classes.append(object_class_from_text(best_class))
        confidences.append(1.0 if best_score is None else _confidence(best_score))
    return DetectedObject.many(
        object_id=[object_id_from_text(obj.raw_id) for obj in objects],
        object_class=classes,
        confidence=confidences,
        center_m=[obj.position for obj in objects],
        size_m=sizes,
        yaw_rad=[e[0] for e in eulers],
        velocity_mps=read.velocities,
        orientation_rad=eulers,
        num_lidar_points=[None if p < 0 else p for p in read.num_lidar_points],
        visible=[None if v < 0 else bool(v) for v in read.visible],
    )


def _euler(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """(yaw, pitch, roll) of a unit quaternion, the arithmetic of ``euler_from_quaternion``."""
    sin_pitch = max(-1.0, min(1.0, 2 * (w * y - z * x)))
    pitch_rad = math.asin(sin_pitch)
    if abs(sin_pitch) > 1.0 - 1e-10:
        return math.atan2(2 * (w * z - x * y), 1 - 2 * (x * x + z * z)), pitch_rad, 0.0
    roll_rad = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    yaw_rad = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return yaw_rad, pitch_rad, roll_rad


_QUAT_EPS = 1e-12  # quaternion_normalized's smallest norm


def _not_parallel(
    message: LogMessage, n: int, velocities: int, points: int, visible: int
) -> UnsupportedMessageError:
    return unsupported(
        message,
        f"GroundTruthObjectArray has {n} detections but {velocities} velocities, "
        f"{points} point counts and {visible} visible flags",
        "the arrays must be parallel; the writer of this log is broken",
    )


#: derived_object_msgs/Object classification constant → ObjectClass.
DERIVED_OBJECT_CLASSES: Mapping[int, ObjectClass] = MappingProxyType(
    {
        0: ObjectClass.UNKNOWN,  # CLASSIFICATION_UNKNOWN
        1: ObjectClass.UNKNOWN,  # CLASSIFICATION_UNKNOWN_SMALL
        2: ObjectClass.UNKNOWN,  # CLASSIFICATION_UNKNOWN_MEDIUM
        3: ObjectClass.UNKNOWN,  # CLASSIFICATION_UNKNOWN_BIG
        4: ObjectClass.PEDESTRIAN,  # CLASSIFICATION_PEDESTRIAN
        5: ObjectClass.BICYCLE,  # CLASSIFICATION_BIKE
        6: ObjectClass.VEHICLE,  # CLASSIFICATION_CAR
        7: ObjectClass.TRUCK,  # CLASSIFICATION_TRUCK
        8: ObjectClass.MOTORCYCLE,  # CLASSIFICATION_MOTORCYCLE
        9: ObjectClass.VEHICLE,  # CLASSIFICATION_OTHER_VEHICLE
        10: ObjectClass.STATIC,  # CLASSIFICATION_BARRIER
        11: ObjectClass.STATIC,  # CLASSIFICATION_SIGN
    }
)

_BOX, _SPHERE, _CYLINDER, _CONE = 1, 2, 3, 4


def _shape_size(shape: Any) -> tuple[float, float, float]:
    """(length, width, height) of a shape_msgs/SolidPrimitive; zeros when it has no size."""
    dims = [float(v) for v in shape.dimensions]
    kind = int(shape.type)
    if kind == _BOX and len(dims) >= 3:
        return dims[0], dims[1], dims[2]
    if kind == _SPHERE and dims:
        return 2 * dims[0], 2 * dims[0], 2 * dims[0]
    if kind in (_CYLINDER, _CONE) and len(dims) >= 2:
        return 2 * dims[1], 2 * dims[1], dims[0]
    return 0.0, 0.0, 0.0


class ObjectArrayDecoder:
    """``derived_object_msgs/msg/ObjectArray`` (CARLA ground truth) → DetectedObjects.

    Confidence is ``classification_certainty / 255`` for classified objects, else 1.0.
    """

    name = "derived_object_array"
    msgtypes: tuple[str, ...] = ("derived_object_msgs/msg/ObjectArray",)
    kind = DecodedKind.OBJECTS
    sensor_type: SensorType | None = None

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        out: list[DetectedObject] = []
        for obj in msg.objects:
            box, orientation = _box(
                message, obj.pose.position, obj.pose.orientation, _shape_size(obj.shape)
            )
            classified = bool(obj.object_classified)
            out.append(
                DetectedObject(
                    object_id=int(obj.id),
                    object_class=DERIVED_OBJECT_CLASSES.get(
                        int(obj.classification), ObjectClass.UNKNOWN
                    ),
                    confidence=int(obj.classification_certainty) / 255.0 if classified else 1.0,
                    box=box,
                    velocity=np.array(vec3(obj.twist.linear)),
                    acceleration=np.array(vec3(obj.accel.linear)),
                    orientation=orientation,
                )
            )
        return Decoded(
            stamp_ns=header_stamp_ns(msg.header, message),
            frame_id=str(msg.header.frame_id),
            value=tuple(out),
        )
