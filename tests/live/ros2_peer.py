"""A ROS 2 node's stand-in for the tests: publishes PointCloud2, Image and Imu samples through
Cyclone DDS with ROS 2's topic and type names, and listens to redrive's results.

The sensor types are written out here as IdlStruct classes, the way ``idlc -l py`` renders ROS 2's
``.idl`` files (``sensor_msgs::msg::dds_::PointCloud2_`` …): they are what rmw_cyclonedds_cpp puts
on the wire, independent of redrive's generated types. Run as its own process::

    python ros2_peer.py --domain 42 --count 25 --rate 10 [--points 2000] [--only TOPIC…]
        [--match TOPIC…] [--exit] [--listen TOPIC TYPE]

It prints ``ADVERTISED`` once its writers exist, publishes ``--count`` samples per topic (0:
until SIGTERM) after every writer (or those of ``--match``) is matched with a reader, ``SENT <n>``
when done (and with ``--exit`` leaves the domain and exits, once its reliable samples are
acknowledged), and for every sample received on ``--listen`` a line ``RESULT <json>``.
"""

import argparse
import json
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np
from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class PointField(IdlStruct, typename="sensor_msgs::msg::dds_::PointField_"):
    name: str
    offset: t.uint32
    datatype: t.uint8
    count: t.uint32


@dataclass
class PointCloud2(IdlStruct, typename="sensor_msgs::msg::dds_::PointCloud2_"):
    header: Header
    height: t.uint32
    width: t.uint32
    fields: t.sequence[PointField]
    is_bigendian: bool
    point_step: t.uint32
    row_step: t.uint32
    data: t.sequence[t.uint8]
    is_dense: bool


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header
    height: t.uint32
    width: t.uint32
    encoding: str
    is_bigendian: t.uint8
    step: t.uint32
    data: t.sequence[t.uint8]


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64
    y: t.float64
    z: t.float64
    w: t.float64


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Imu(IdlStruct, typename="sensor_msgs::msg::dds_::Imu_"):
    header: Header
    orientation: Quaternion
    orientation_covariance: t.array[t.float64, 9]
    angular_velocity: Vector3
    angular_velocity_covariance: t.array[t.float64, 9]
    linear_acceleration: Vector3
    linear_acceleration_covariance: t.array[t.float64, 9]


SENSOR_QOS = Qos(
    Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5)
)
DEFAULT_QOS = Qos(
    Policy.Reliability.Reliable(max_blocking_time=100_000_000),
    Policy.Durability.Volatile,
    Policy.History.KeepLast(10),
)


def cloud(i: int, points: int) -> PointCloud2:
    """A block of points 10 m ahead (one cluster), x, y, z, intensity float32; seeded by i."""
    rng = np.random.default_rng(i)
    xyz = rng.uniform([9.0, -1.0, -0.5], [13.0, 1.0, 1.0], size=(points, 3)).astype(np.float32)
    intensity = np.full((points, 1), float(i), np.float32)
    data = np.hstack([xyz, intensity]).astype("<f4").tobytes()
    fields = [PointField(n, 4 * k, 7, 1) for k, n in enumerate(("x", "y", "z", "intensity"))]
    return PointCloud2(
        stamp(i, "lidar"), 1, points, fields, False, 16, 16 * points, list(data), True
    )


def stamp(i: int, frame: str) -> Header:
    ns = 1_700_000_000_000_000_000 + i * 100_000_000
    return Header(Time(ns // 1_000_000_000, ns % 1_000_000_000), frame)


def image(i: int) -> Image:
    pixels = (np.arange(24 * 32 * 3, dtype=np.uint32) + i).astype(np.uint8)
    return Image(
        stamp(i, "camera"),
        24,
        32,
        "rgb8",
        0,
        96,
        list(pixels.tobytes()),
    )


def imu(i: int) -> Imu:
    cov = [0.0] * 9
    return Imu(
        stamp(i, "imu"),
        Quaternion(0.0, 0.0, 0.0, 1.0),
        cov,
        Vector3(0.01 * i, 0.0, 0.0),
        cov,
        Vector3(0.0, 0.0, 9.81),
        cov,
    )


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--count", type=int, default=25)
    parser.add_argument("--rate", type=float, default=10.0)
    parser.add_argument("--points", type=int, default=2000)
    parser.add_argument("--listen", nargs=2, metavar=("TOPIC", "TYPE"))
    parser.add_argument("--match", nargs="+", help="wait for readers of these topics only")
    parser.add_argument("--exit", action="store_true", help="exit once the samples are sent")
    parser.add_argument(
        "--only", nargs="+", help="publish only these of /points /camera/image_raw /imu"
    )
    args = parser.parse_args()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    dp = DomainParticipant(args.domain)
    kinds = {
        "/points": (PointCloud2, SENSOR_QOS, lambda i: cloud(i, args.points)),
        "/camera/image_raw": (Image, DEFAULT_QOS, image),
        "/imu": (Imu, DEFAULT_QOS, imu),
    }
    published = [name for name in kinds if not args.only or name in args.only]
    writers = [
        (DataWriter(dp, Topic(dp, "rt" + name, cls, qos=qos), qos=qos), make)
        for name, (cls, qos, make) in ((n, kinds[n]) for n in published)
    ]
    matched = [
        writer
        for (writer, _), name in zip(writers, published, strict=True)
        if not args.match or name in args.match
    ]
    if args.listen:
        from redrive.io.ros.typestore import typestore_for
        from redrive.live.ros2_dds import idl_struct

        result_type = idl_struct(typestore_for(2)[0], args.listen[1])
        result_topic = Topic(dp, "rt/" + args.listen[0].lstrip("/"), result_type, qos=DEFAULT_QOS)
        reader = DataReader(dp, result_topic, qos=DEFAULT_QOS)

        def listen() -> None:
            waitset = WaitSet(dp)
            waitset.attach(
                ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any)
            )
            while not stop.is_set():
                waitset.wait(100_000_000)
                for sample in reader.take(N=64):
                    header = sample.header
                    print("RESULT " + json.dumps({
                        "type": result_topic.typename,
                        "frame_id": header.frame_id,
                        "stamp_ns": header.stamp.sec * 1_000_000_000 + header.stamp.nanosec,
                        "n": len(getattr(sample, "detections", getattr(sample, "poses", []))),
                    }), flush=True)  # fmt: skip

        threading.Thread(target=listen, daemon=True).start()
    print("ADVERTISED", flush=True)
    while not stop.is_set() and not all(w.get_matched_subscriptions() for w in matched):
        time.sleep(0.02)
    i = 0
    next_s = time.monotonic()
    while not stop.is_set() and (args.count == 0 or i < args.count):
        for writer, make in writers:
            writer.write(make(i))
        i += 1
        next_s += 1.0 / args.rate
        stop.wait(max(0.0, next_s - time.monotonic()))
    for writer, _ in writers:
        writer.wait_for_acks(2_000_000_000)
    print(f"SENT {i}", flush=True)
    if args.exit:  # leave the domain now (readers see the writers go) rather than at exit
        dp._delete(dp._ref)
        os._exit(0)
    stop.wait()  # stay until told: the readers must not see the writers vanish mid-test
    return 0


if __name__ == "__main__":
    sys.exit(main())
