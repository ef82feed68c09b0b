"""A drive through the real Lanelet2 example map (Karlsruhe) as a ROS 1 bag, for the tests of
``--map`` (tests/engine/test_user_map.py) and of the map's drawing (tests/interop)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt

from redrive.types import RoadMap

__all__ = ["DRIVE_LANES", "SPEED_MPS", "drive_poses", "write_drive_bag"]

#: a chain of successors through the map, 45080 (70 m) into 45082 … 45154
DRIVE_LANES = ("45080", "45082", "45086", "45066", "45064", "45062", "45060", "45154")
SPEED_MPS = 8.0


def drive_poses(road: RoadMap, *, seconds: float) -> npt.NDArray[np.float64]:
    """(N, 3) x, y, yaw at 10 Hz along the centrelines of DRIVE_LANES at SPEED_MPS (map frame)."""
    line = np.vstack([road.lane(i).centerline for i in DRIVE_LANES])
    keep = np.concatenate([[True], np.hypot(*np.diff(line, axis=0).T) > 1e-6])
    line = line[keep]
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
    s = 1.0 + np.arange(0.0, seconds, 0.1) * SPEED_MPS  # from 1 m in: not on 45080's start line
    assert s[-1] < arc[-1]
    x, y = np.interp(s, arc, line[:, 0]), np.interp(s, arc, line[:, 1])
    seg = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(line) - 2)
    d = line[seg + 1] - line[seg]
    return np.column_stack([x, y, np.arctan2(d[:, 1], d[:, 0])])


def write_drive_bag(
    path: Path,
    poses: npt.NDArray[np.float64],
    *,
    frame: str,
    map_to_frame: tuple[float, float, float] | None = None,
) -> Path:
    """A ROS 1 bag: Odometry of ``poses`` in ``frame`` and a small cloud per pose (10 Hz);
    ``map_to_frame`` (x, y, yaw): a /tf_static ``map → frame``."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(
        get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
    )
    g = ts.types
    header, stamp_t = g["std_msgs/msg/Header"], g["builtin_interfaces/msg/Time"]
    vec, quat = g["geometry_msgs/msg/Vector3"], g["geometry_msgs/msg/Quaternion"]
    odom_t, pc2, pf = (
        g["nav_msgs/msg/Odometry"],
        g["sensor_msgs/msg/PointCloud2"],
        g["sensor_msgs/msg/PointField"],
    )
    t0 = 1_700_000_000_000_000_000
    fields = [pf(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]
    pts = np.array([[5.0, 0.0, 0.0], [6.0, 1.0, 0.5]], dtype="<f4")
    with Writer(path) as bag:
        c_odom = bag.add_connection("/odom", odom_t.__msgtype__, typestore=ts)
        c_pts = bag.add_connection("/points", pc2.__msgtype__, typestore=ts)
        if map_to_frame is not None:
            tfm, tf_t = g["tf2_msgs/msg/TFMessage"], g["geometry_msgs/msg/TransformStamped"]
            c_tf = bag.add_connection("/tf_static", tfm.__msgtype__, typestore=ts)
            x, y, yaw = map_to_frame
            edge = tf_t(
                header=header(seq=0, stamp=stamp_t(sec=t0 // 10**9, nanosec=0), frame_id="map"),
                child_frame_id=frame,
                transform=g["geometry_msgs/msg/Transform"](
                    translation=vec(x=x, y=y, z=0.0),
                    rotation=quat(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)),
                ),
            )
            bag.write(c_tf, t0, ts.serialize_ros1(tfm(transforms=[edge]), tfm.__msgtype__))
        for k, (x, y, yaw) in enumerate(poses.tolist()):
            t = t0 + k * 100_000_000
            st = stamp_t(sec=t // 10**9, nanosec=t % 10**9)
            pose = g["geometry_msgs/msg/Pose"](
                position=g["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                orientation=quat(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)),
            )
            twist = g["geometry_msgs/msg/Twist"](
                linear=vec(x=SPEED_MPS, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
            )
            odom = odom_t(
                header=header(seq=k, stamp=st, frame_id=frame),
                child_frame_id="base_link",
                pose=g["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                twist=g["geometry_msgs/msg/TwistWithCovariance"](
                    twist=twist, covariance=np.zeros(36)
                ),
            )
            bag.write(c_odom, t, ts.serialize_ros1(odom, odom_t.__msgtype__))
            cloud = pc2(
                header=header(seq=k, stamp=st, frame_id="base_link"),
                height=1,
                width=len(pts),
                fields=fields,
                is_bigendian=False,
                point_step=12,
                row_step=12 * len(pts),
                data=pts.view(np.uint8).ravel(),
                is_dense=True,
            )
            bag.write(c_pts, t, ts.serialize_ros1(cloud, pc2.__msgtype__))  # log time = stamp
    return path
