"""Data-model values → standard ROS 2 messages (rosbags message objects of a typestore).

The inverse of :mod:`redrive.io.ros.decoders` for the types the MCAP writer records:

=========================  =================================  ====================================
value                      message                            notes
=========================  =================================  ====================================
PointCloud                 ``sensor_msgs/msg/PointCloud2``    x, y, z FLOAT32 then every channel in
                                                              its dtype, packed, little-endian,
                                                              height 1; int64 channels are stored
                                                              as INT32/UINT32 when they fit
Image                      ``sensor_msgs/msg/Image``          step = width × channels × itemsize
CameraInfo                 ``sensor_msgs/msg/CameraInfo``     binning 0, empty region of interest
Imu                        ``sensor_msgs/msg/Imu``            NaN orientation → covariance[0] = -1
GnssFix                    ``sensor_msgs/msg/NavSatFix``      NaN covariance → type UNKNOWN
VehicleState               ``nav_msgs/msg/Odometry``          twist in the body (``base_link``);
                                                              acceleration is not carried
tuple[Transform, ...]      ``tf2_msgs/msg/TFMessage``         a stamp 0 (static) is written as the
                                                              message stamp
tuple[DetectedObject,...]  ``vision_msgs/msg/Detection3DArray``  class name (``vehicle`` …) in
                                                              ``hypothesis.class_id``, confidence
                                                              as score, ``id = str(object_id)``;
                                                              velocity and bbox_2d are not carried
ground truth (objects with  ``redrive_msgs/msg/                   the same Detection3Ds plus
num_lidar_points or         GroundTruthObjectArray``          velocities, num_lidar_points and
visible set)                                                  visible (shipped .msg, built of
                                                              standard parts)
TrafficData (lights only)  ``redrive_msgs/msg/                   ``ids`` (``TrafficLight.id``) and
                           TrafficLightStateArray``           ``states`` (UNKNOWN 0, RED 1,
                                                              YELLOW 2, GREEN 3; shipped .msg);
                                                              nearby vehicles are objects: a
                                                              TrafficData with any is refused
=========================  =================================  ====================================
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.typesys.store import Typestore

from redrive.errors import UnsupportedMessageError
from redrive.geometry.quaternion import rotation_matrix_from_quaternion
from redrive.geometry.se3 import quaternion_from_euler, quaternion_from_yaw
from redrive.types import (
    CameraInfo,
    DetectedObject,
    GnssFix,
    Image,
    Imu,
    LightState,
    PointCloud,
    TrafficData,
    Transform,
    VehicleState,
)

__all__ = ["BODY_FRAME", "LIGHT_STATE_CODES", "encode_value", "msgtype_of"]

#: child_frame_id of the Odometry messages written for a VehicleState.
BODY_FRAME = "base_link"

# numpy dtype → PointField datatype
_POINTFIELD: dict[np.dtype[Any], int] = {
    np.dtype(np.int8): 1,
    np.dtype(np.uint8): 2,
    np.dtype(np.int16): 3,
    np.dtype(np.uint16): 4,
    np.dtype(np.int32): 5,
    np.dtype(np.uint32): 6,
    np.dtype(np.float32): 7,
    np.dtype(np.float64): 8,
}
_NAVSAT_COVARIANCE_UNKNOWN = 0
_NAVSAT_COVARIANCE_KNOWN = 3
_NAVSAT_SERVICE_GPS = 1
#: a light's state → its code in ``redrive_msgs/msg/TrafficLightStateArray`` (the .msg constants)
LIGHT_STATE_CODES: dict[LightState, int] = {
    LightState.UNKNOWN: 0,
    LightState.RED: 1,
    LightState.YELLOW: 2,
    LightState.GREEN: 3,
}


def is_ground_truth(objects: tuple[DetectedObject, ...]) -> bool:
    """Objects that carry ground-truth facts (LiDAR point counts, visibility)."""
    return any(o.num_lidar_points is not None or o.visible is not None for o in objects)


def msgtype_of(value: object) -> str:
    """The ROS 2 message type :func:`encode_value` writes for ``value``.

    Raises:
        UnsupportedMessageError: the value has no standard message.
    """
    if isinstance(value, PointCloud):
        return "sensor_msgs/msg/PointCloud2"
    if isinstance(value, Image):
        return "sensor_msgs/msg/Image"
    if isinstance(value, CameraInfo):
        return "sensor_msgs/msg/CameraInfo"
    if isinstance(value, Imu):
        return "sensor_msgs/msg/Imu"
    if isinstance(value, GnssFix):
        return "sensor_msgs/msg/NavSatFix"
    if isinstance(value, VehicleState):
        return "nav_msgs/msg/Odometry"
    if isinstance(value, TrafficData):
        if value.nearby_vehicles:
            msg = (
                f"a TrafficData with {len(value.nearby_vehicles)} nearby vehicle(s): its message "
                "carries the lights only; write the vehicles as a tuple[DetectedObject] on an "
                "object topic and the lights as TrafficData(traffic_lights=...)"
            )
            raise UnsupportedMessageError(msg)
        return "redrive_msgs/msg/TrafficLightStateArray"
    if isinstance(value, tuple) and all(isinstance(v, Transform) for v in value):
        return "tf2_msgs/msg/TFMessage"  # an empty tuple is an empty TFMessage
    if isinstance(value, tuple) and all(isinstance(v, DetectedObject) for v in value):
        if is_ground_truth(value):
            return "redrive_msgs/msg/GroundTruthObjectArray"
        return "vision_msgs/msg/Detection3DArray"
    msg = (
        f"a {type(value).__name__} has no standard ROS 2 message; write PointCloud, Image, "
        "CameraInfo, Imu, GnssFix, VehicleState, TrafficData, tuple[Transform] or "
        "tuple[DetectedObject]"
    )
    raise UnsupportedMessageError(msg)


class _Builder:
    """Message constructors of one typestore."""

    def __init__(self, typestore: Typestore) -> None:
        self.ts = typestore

    def new(self, msgtype: str, **fields: Any) -> Any:
        return self.ts.types[msgtype](**fields)

    def header(self, stamp_ns: int, frame_id: str) -> Any:
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        stamp = self.new("builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)
        return self.new("std_msgs/msg/Header", stamp=stamp, frame_id=frame_id)

    def vector3(self, xyz: npt.ArrayLike) -> Any:
        x, y, z = (float(v) for v in np.asarray(xyz, dtype=np.float64))
        return self.new("geometry_msgs/msg/Vector3", x=x, y=y, z=z)

    def point(self, xyz: npt.ArrayLike) -> Any:
        x, y, z = (float(v) for v in np.asarray(xyz, dtype=np.float64))
        return self.new("geometry_msgs/msg/Point", x=x, y=y, z=z)

    def quaternion(self, q_xyzw: npt.ArrayLike) -> Any:
        x, y, z, w = (float(v) for v in np.asarray(q_xyzw, dtype=np.float64))
        return self.new("geometry_msgs/msg/Quaternion", x=x, y=y, z=z, w=w)

    def pose(self, position: npt.ArrayLike, q_xyzw: npt.ArrayLike) -> Any:
        return self.new(
            "geometry_msgs/msg/Pose",
            position=self.point(position),
            orientation=self.quaternion(q_xyzw),
        )


def _cloud_channel(name: str, values: npt.NDArray[Any]) -> npt.NDArray[Any]:
    if not values.dtype.isnative:
        values = values.astype(values.dtype.newbyteorder("="))
    if values.dtype in _POINTFIELD:
        return values
    if values.dtype == np.bool_:
        return values.astype(np.uint8)
    if values.dtype.kind in "iu":
        narrow = np.dtype(np.int32 if values.dtype.kind == "i" else np.uint32)
        info = np.iinfo(narrow)
        if values.size == 0 or (int(values.min()) >= info.min and int(values.max()) <= info.max):
            return values.astype(narrow)
    msg = (
        f"PointCloud channel {name!r} of dtype {values.dtype} has no PointField datatype (and does "
        "not fit INT32/UINT32); convert it to float64 or a 32-bit integer first"
    )
    raise UnsupportedMessageError(msg)


def _point_cloud(b: _Builder, cloud: PointCloud, header: Any) -> Any:
    columns: list[tuple[str, npt.NDArray[Any]]] = [
        ("x", cloud.xyz[:, 0]),
        ("y", cloud.xyz[:, 1]),
        ("z", cloud.xyz[:, 2]),
    ]
    columns += [(name, _cloud_channel(name, values)) for name, values in cloud.channels.items()]
    dtype = np.dtype([(name, values.dtype.newbyteorder("<")) for name, values in columns])
    packed = np.empty(cloud.num_points, dtype=dtype)
    for name, values in columns:
        packed[name] = values
    fields = [
        b.new(
            "sensor_msgs/msg/PointField",
            name=name,
            offset=dtype.fields[name][1] if dtype.fields else 0,
            datatype=_POINTFIELD[values.dtype.newbyteorder("=")],
            count=1,
        )
        for name, values in columns
    ]
    return b.new(
        "sensor_msgs/msg/PointCloud2",
        header=header,
        height=1,
        width=cloud.num_points,
        fields=fields,
        is_bigendian=False,
        point_step=dtype.itemsize,
        row_step=dtype.itemsize * cloud.num_points,
        data=packed.view(np.uint8).reshape(-1),
        is_dense=bool(np.isfinite(cloud.xyz).all()),
    )


def _image(b: _Builder, image: Image, header: Any) -> Any:
    pixels = np.ascontiguousarray(image.pixels)
    little = pixels.astype(pixels.dtype.newbyteorder("<"), copy=False)
    return b.new(
        "sensor_msgs/msg/Image",
        header=header,
        height=image.height,
        width=image.width,
        encoding=image.encoding,
        is_bigendian=0,
        step=int(little.strides[0]),
        data=np.frombuffer(little.tobytes(), dtype=np.uint8),
    )


def _camera_info(b: _Builder, info: CameraInfo, header: Any) -> Any:
    return b.new(
        "sensor_msgs/msg/CameraInfo",
        header=header,
        height=info.height,
        width=info.width,
        distortion_model=info.distortion_model,
        d=info.d.copy(),
        k=info.k.reshape(9).copy(),
        r=info.r.reshape(9).copy(),
        p=info.p.reshape(12).copy(),
        binning_x=0,
        binning_y=0,
        roi=b.new(
            "sensor_msgs/msg/RegionOfInterest",
            x_offset=0,
            y_offset=0,
            height=0,
            width=0,
            do_rectify=False,
        ),
    )


def _imu(b: _Builder, imu: Imu, header: Any) -> Any:
    no_orientation = bool(np.isnan(imu.orientation).any())
    orientation_cov = np.zeros(9)
    if no_orientation:
        orientation_cov[0] = -1.0
    return b.new(
        "sensor_msgs/msg/Imu",
        header=header,
        orientation=b.quaternion([0.0, 0.0, 0.0, 1.0] if no_orientation else imu.orientation),
        orientation_covariance=orientation_cov,
        angular_velocity=b.vector3(imu.angular_velocity),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=b.vector3(imu.linear_acceleration),
        linear_acceleration_covariance=np.zeros(9),
    )


def _navsat(b: _Builder, fix: GnssFix, header: Any) -> Any:
    cov = fix.position_covariance_m2
    known = bool(np.isfinite(cov).all())
    return b.new(
        "sensor_msgs/msg/NavSatFix",
        header=header,
        status=b.new(
            "sensor_msgs/msg/NavSatStatus", status=int(fix.status), service=_NAVSAT_SERVICE_GPS
        ),
        latitude=float(fix.latitude_deg),
        longitude=float(fix.longitude_deg),
        altitude=float(fix.altitude_m),
        position_covariance=cov.reshape(9).copy() if known else np.zeros(9),
        position_covariance_type=_NAVSAT_COVARIANCE_KNOWN if known else _NAVSAT_COVARIANCE_UNKNOWN,
    )


def _odometry(b: _Builder, state: VehicleState, header: Any) -> Any:
    q = quaternion_from_yaw(state.heading_rad)
    body_from_frame = rotation_matrix_from_quaternion(q).T
    twist = b.new(
        "geometry_msgs/msg/Twist",
        linear=b.vector3(body_from_frame @ state.velocity),
        angular=b.vector3([0.0, 0.0, state.yaw_rate_rad_s]),
    )
    return b.new(
        "nav_msgs/msg/Odometry",
        header=header,
        child_frame_id=BODY_FRAME,
        pose=b.new(
            "geometry_msgs/msg/PoseWithCovariance",
            pose=b.pose(state.position, q),
            covariance=np.zeros(36),
        ),
        twist=b.new("geometry_msgs/msg/TwistWithCovariance", twist=twist, covariance=np.zeros(36)),
    )


def _tf(b: _Builder, transforms: tuple[Transform, ...], stamp_ns: int) -> Any:
    items = [
        b.new(
            "geometry_msgs/msg/TransformStamped",
            header=b.header(t.stamp_ns or stamp_ns, t.parent_frame),
            child_frame_id=t.child_frame,
            transform=b.new(
                "geometry_msgs/msg/Transform",
                translation=b.vector3(t.translation),
                rotation=b.quaternion(t.rotation),
            ),
        )
        for t in transforms
    ]
    return b.new("tf2_msgs/msg/TFMessage", transforms=items)


def _detection(b: _Builder, obj: DetectedObject, header: Any) -> Any:
    q = quaternion_from_euler(float(obj.orientation[2]), float(obj.orientation[1]), obj.box.yaw_rad)
    pose = b.pose(obj.box.center, q)
    hypothesis = b.new(
        "vision_msgs/msg/ObjectHypothesisWithPose",
        hypothesis=b.new(
            "vision_msgs/msg/ObjectHypothesis",
            class_id=obj.object_class.value,
            score=float(obj.confidence),
        ),
        pose=b.new("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=np.zeros(36)),
    )
    return b.new(
        "vision_msgs/msg/Detection3D",
        header=header,
        results=[hypothesis],
        bbox=b.new("vision_msgs/msg/BoundingBox3D", center=pose, size=b.vector3(obj.box.size)),
        id=str(obj.object_id),
    )


def _detections(b: _Builder, objects: tuple[DetectedObject, ...], header: Any) -> Any:
    detections = [_detection(b, obj, header) for obj in objects]
    return b.new("vision_msgs/msg/Detection3DArray", header=header, detections=detections)


def _ground_truth(b: _Builder, objects: tuple[DetectedObject, ...], header: Any) -> Any:
    return b.new(
        "redrive_msgs/msg/GroundTruthObjectArray",
        header=header,
        detections=[_detection(b, obj, header) for obj in objects],
        velocities=[b.vector3(obj.velocity) for obj in objects],
        num_lidar_points=np.array(
            [-1 if o.num_lidar_points is None else o.num_lidar_points for o in objects],
            dtype=np.int32,
        ),
        visible=np.array([-1 if o.visible is None else int(o.visible) for o in objects], np.int8),
    )


def _traffic_lights(b: _Builder, traffic: TrafficData, header: Any) -> Any:
    ids = [light.id for light in traffic.traffic_lights]
    if len(set(ids)) != len(ids):
        twice = sorted({i for i in ids if ids.count(i) > 1})
        msg = f"TrafficData: light id(s) {', '.join(map(repr, twice))} appear twice; ids are unique"
        raise UnsupportedMessageError(msg)
    return b.new(
        "redrive_msgs/msg/TrafficLightStateArray",
        header=header,
        ids=ids,
        states=np.array(
            [LIGHT_STATE_CODES[light.state] for light in traffic.traffic_lights], dtype=np.uint8
        ),
    )


def encode_value(
    value: object,
    typestore: Typestore,
    *,
    frame_id: str,
    stamp_ns: int,
    empty_objects_as: str | None = None,
) -> tuple[str, Any]:
    """``(msgtype, message)``: ``value`` as a standard ROS 2 message of ``typestore``.

    Args:
        value: a data-model value (see the module table).
        typestore: a ROS 2 store that knows the types (``typestore_for(2)``).
        frame_id: the header frame (for tf, each transform's parent frame is used instead).
        stamp_ns: the header stamp, int ns.
        empty_objects_as: the object message type (``vision_msgs/msg/Detection3DArray`` or
            ``redrive_msgs/msg/GroundTruthObjectArray``) of an empty tuple from an objects
            topic; without it an empty tuple is an empty TFMessage.

    Raises:
        UnsupportedMessageError: the value has no standard message, or cannot be represented.
    """
    msgtype = msgtype_of(value)
    if value == () and empty_objects_as is not None:
        msgtype = empty_objects_as
    b = _Builder(typestore)
    if isinstance(value, tuple) and msgtype == "tf2_msgs/msg/TFMessage":
        return msgtype, _tf(b, value, stamp_ns)
    header = b.header(stamp_ns, frame_id)
    if isinstance(value, PointCloud):
        return msgtype, _point_cloud(b, value, header)
    if isinstance(value, Image):
        return msgtype, _image(b, value, header)
    if isinstance(value, CameraInfo):
        return msgtype, _camera_info(b, value, header)
    if isinstance(value, Imu):
        return msgtype, _imu(b, value, header)
    if isinstance(value, GnssFix):
        return msgtype, _navsat(b, value, header)
    if isinstance(value, VehicleState):
        return msgtype, _odometry(b, value, header)
    if isinstance(value, TrafficData):
        return msgtype, _traffic_lights(b, value, header)
    assert isinstance(value, tuple)
    if msgtype == "redrive_msgs/msg/GroundTruthObjectArray":
        return msgtype, _ground_truth(b, value, header)
    return msgtype, _detections(b, value, header)
