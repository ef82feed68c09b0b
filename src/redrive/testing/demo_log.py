"""Write a small multi-sensor ROS 1 bag (tests use it as a real bag written by rosbags):
``python -m redrive.testing.demo_log OUT``.

The ego drives straight at 5 m/s for 5 s past one parked car.  A 16-beam LiDAR sees the ground and
the car (analytic ray hits, no noise), the IMU and odometry follow the true motion and a GNSS fix
moves with it.  It is a format fixture (a ROS 1 bag with ``velodyne``-style topics), not a
scenario: ``redrive synth`` renders those.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

__all__ = ["write_demo_bag"]

_SPEED_MPS = 5.0
_LIDAR_HEIGHT_M = 1.8
_CAR = (20.0, 4.0, 4.5, 1.8)  # centre x, y, length, width (m); height 1.5 m


def _lidar_points(ego_x_m: float) -> np.ndarray:
    """A VLP-16-like sweep (16 beams, 0.4° azimuth) hitting the ground plane and one box."""
    elev = np.deg2rad(np.arange(-15.0, 0.0, 2.0))  # beams that reach the ground
    azim = np.deg2rad(np.arange(0.0, 360.0, 0.4))
    el, az = np.meshgrid(elev, azim, indexing="ij")
    rng = _LIDAR_HEIGHT_M / np.tan(-el)
    x, y = rng * np.cos(el) * np.cos(az), rng * np.cos(el) * np.sin(az)
    z = np.full_like(x, -_LIDAR_HEIGHT_M)
    cx, cy, length, width = _CAR
    rel_x, rel_y = cx - ego_x_m, cy
    inside = (np.abs(x - rel_x) < length / 2) & (np.abs(y - rel_y) < width / 2)
    z = np.where(inside, -_LIDAR_HEIGHT_M + 1.5, z)  # the car's roof
    intensity = np.where(inside, 80.0, 10.0)
    ring = np.broadcast_to(np.arange(len(elev))[:, None], x.shape)
    out = np.zeros(
        x.size,
        dtype=[
            ("x", "<f4"),
            ("y", "<f4"),
            ("z", "<f4"),
            ("_pad", "<f4"),
            ("intensity", "<f4"),
            ("ring", "<u2"),
            ("_pad2", "<u2"),
        ],
    )
    out["x"], out["y"], out["z"] = x.ravel(), y.ravel(), z.ravel()
    out["intensity"], out["ring"] = intensity.ravel(), ring.ravel()
    return out


def write_demo_bag(path: Path, *, duration_s: float = 5.0) -> Path:
    """Write the demo bag to ``path`` (replacing it) and return the path."""
    ts = get_typestore(Stores.ROS1_NOETIC)
    h = ts.types["std_msgs/msg/Header"]
    t_ = ts.types["builtin_interfaces/msg/Time"]
    pf = ts.types["sensor_msgs/msg/PointField"]
    pc2 = ts.types["sensor_msgs/msg/PointCloud2"]
    imu_t = ts.types["sensor_msgs/msg/Imu"]
    odom_t = ts.types["nav_msgs/msg/Odometry"]
    fix_t = ts.types["sensor_msgs/msg/NavSatFix"]
    st_t = ts.types["sensor_msgs/msg/NavSatStatus"]
    g = ts.types
    path.unlink(missing_ok=True)
    t0_ns = 1_700_000_000_000_000_000
    with Writer(path) as bag:
        c_lidar = bag.add_connection("/velodyne_points", pc2.__msgtype__, typestore=ts)
        c_imu = bag.add_connection("/imu/data", imu_t.__msgtype__, typestore=ts)
        c_odom = bag.add_connection("/odom", odom_t.__msgtype__, typestore=ts)
        c_fix = bag.add_connection("/gnss/fix", fix_t.__msgtype__, typestore=ts)
        fields = [
            pf(name=n, offset=o, datatype=d, count=1)
            for n, o, d in (
                ("x", 0, 7),
                ("y", 4, 7),
                ("z", 8, 7),
                ("intensity", 16, 7),
                ("ring", 20, 4),
            )
        ]
        cov9 = np.zeros(9)
        cov36 = np.zeros(36)
        for step in range(round(duration_s * 100)):  # 100 Hz clock
            t_ns = t0_ns + step * 10_000_000
            x_m = _SPEED_MPS * step * 0.01
            stamp = t_(sec=t_ns // 10**9, nanosec=t_ns % 10**9)
            seq = step
            imu = imu_t(
                header=h(seq=seq, stamp=stamp, frame_id="imu"),
                orientation=g["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=cov9,
                angular_velocity=g["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                angular_velocity_covariance=cov9,
                linear_acceleration=g["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=9.81),
                linear_acceleration_covariance=cov9,
            )
            bag.write(c_imu, t_ns, ts.serialize_ros1(imu, imu_t.__msgtype__))
            if step % 2 == 0:
                pose = g["geometry_msgs/msg/Pose"](
                    position=g["geometry_msgs/msg/Point"](x=x_m, y=0.0, z=0.0),
                    orientation=g["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                )
                twist = g["geometry_msgs/msg/Twist"](
                    linear=g["geometry_msgs/msg/Vector3"](x=_SPEED_MPS, y=0.0, z=0.0),
                    angular=g["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                )
                odom = odom_t(
                    header=h(seq=seq, stamp=stamp, frame_id="odom"),
                    child_frame_id="base_link",
                    pose=g["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov36),
                    twist=g["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov36),
                )
                bag.write(c_odom, t_ns, ts.serialize_ros1(odom, odom_t.__msgtype__))
            if step % 10 == 0:
                pts = _lidar_points(x_m)
                cloud = pc2(
                    header=h(seq=seq, stamp=stamp, frame_id="velodyne"),
                    height=1,
                    width=pts.size,
                    fields=fields,
                    is_bigendian=False,
                    point_step=pts.itemsize,
                    row_step=pts.nbytes,
                    data=pts.view(np.uint8),
                    is_dense=True,
                )
                bag.write(c_lidar, t_ns + 2_000_000, ts.serialize_ros1(cloud, pc2.__msgtype__))
                lat = 48.137 + x_m / 111_320.0
                fix = fix_t(
                    header=h(seq=seq, stamp=stamp, frame_id="gnss"),
                    status=st_t(status=0, service=1),
                    latitude=lat,
                    longitude=11.575,
                    altitude=520.0,
                    position_covariance=cov9,
                    position_covariance_type=0,
                )
                bag.write(c_fix, t_ns, ts.serialize_ros1(fix, fix_t.__msgtype__))
    return path


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m redrive.testing.demo_log OUT.bag", file=sys.stderr)
        return 2
    out = write_demo_bag(Path(args[0]))
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB, {math.floor(5.0)} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
