"""``redrive live`` end to end: real rospy publishers and ``rosbag play`` → scrapers → shared
memory → frames → the reference detector, and the recording checked against what was sent."""

from __future__ import annotations

import hashlib
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from redrive.io import open_log
from redrive.results import open_run
from redrive.transport import stale_segments
from tests.live.conftest import RosCore, ros1_missing

pytestmark = pytest.mark.skipif(ros1_missing() is not None, reason=str(ros1_missing()))

KITTI_BAG = "rosbag1_recorded_here/kitti_3frames_rosbag_record_lz4.bag"
KITTI_TOPICS = ["/kitti/velo/pointcloud", "/kitti/camera_color_left/image_raw"]

# A rospy publisher at sensor rates: a 20k-point cloud at 10 Hz, a 640x480 rgb8 image at 10 Hz and
# an IMU at 100 Hz, for 3 s once subscribed; prints the sha256 of every payload it sent.
PUBLISHER = r"""
import hashlib, io, sys, time
import numpy as np
import rospy
from sensor_msgs.msg import Image, Imu, PointCloud2, PointField

rospy.init_node("sensor_rig", anonymous=True)
pubs = {
    "/rig/points": rospy.Publisher("/rig/points", PointCloud2, queue_size=100),
    "/rig/image": rospy.Publisher("/rig/image", Image, queue_size=100),
    "/rig/imu": rospy.Publisher("/rig/imu", Imu, queue_size=1000),
}
print("READY", flush=True)
deadline = time.time() + 40  # start once redrive's scrapers are subscribed to every topic
while any(p.get_num_connections() == 0 for p in pubs.values()) and time.time() < deadline:
    time.sleep(0.05)
time.sleep(0.5)
rng = np.random.default_rng(0)
n = 20000
fields = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1)
          for i, c in enumerate("xyz")] + [PointField(name="intensity", offset=12,
          datatype=PointField.FLOAT32, count=1)]
def sent(topic, msg):
    # rospy fills in header.seq while publishing: the check is on the payload (and the stamp)
    body = msg.data if hasattr(msg, "data") else repr(msg.linear_acceleration.z).encode()
    stamp = msg.header.stamp.to_nsec()
    print(topic, hashlib.sha256(bytes(body)).hexdigest() + f"/{stamp}", flush=True)
    pubs[topic].publish(msg)
start = time.time()
tick = 0
while time.time() - start < 3.0 and not rospy.is_shutdown():
    now = rospy.Time.now()
    imu = Imu(); imu.header.stamp = now; imu.header.frame_id = "imu"
    imu.linear_acceleration.z = 9.81 + 0.01 * tick
    sent("/rig/imu", imu)
    if tick % 10 == 0:
        cars = [np.c_[rng.uniform(8 + 6 * k, 12.5 + 6 * k, 600), rng.uniform(-4 + 3.5 * k,
                 -2.2 + 3.5 * k, 600), rng.uniform(-1.6, -0.2, 600)] for k in range(3)]
        ground = np.c_[rng.uniform(-40, 40, (n - 1800, 2)), rng.normal(-1.7, 0.02, n - 1800)]
        xyz = np.vstack(cars + [ground]).astype(np.float32)
        pts = np.c_[xyz, rng.random(n).astype(np.float32)].astype(np.float32)
        cloud = PointCloud2(height=1, width=n, fields=fields, is_bigendian=False, point_step=16,
                            row_step=16 * n, is_dense=True, data=pts.tobytes())
        cloud.header.stamp = now; cloud.header.frame_id = "velodyne"
        sent("/rig/points", cloud)
        img = Image(height=480, width=640, encoding="rgb8", is_bigendian=0, step=640 * 3,
                    data=rng.integers(0, 256, 640 * 480 * 3, dtype=np.uint8).tobytes())
        img.header.stamp = now; img.header.frame_id = "camera"
        sent("/rig/image", img)
    tick += 1
    time.sleep(max(0.0, start + tick * 0.01 - time.time()))
print("DONE", flush=True)
time.sleep(1.0)
"""


def _live(
    roscore: RosCore, tmp_path: Path, topics: list[str], *extra: str
) -> subprocess.Popen[str]:
    argv = [
        sys.executable, "-m", "redrive", "live", "--master", roscore.uri, "--topics", *topics,
        "--perception", "cluster-detector", "--record", str(tmp_path / "live.mcap"),
        "--out", str(tmp_path / "run"), "--wait", "30", *extra,
    ]  # fmt: skip
    env = dict(os.environ, ROS_MASTER_URI=roscore.uri)
    return subprocess.Popen(
        argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def _payload_digests(path: Path, topics: list[str]) -> dict[str, list[str]]:
    """sha256 of each message's data (accel z for an IMU) and its stamp, as the publisher prints."""
    out: dict[str, list[str]] = {t: [] for t in topics}
    with open_log(path) as log:
        for m in log.messages(topics=topics):
            msg = log.deserialize(m)
            data = getattr(msg, "data", None)
            body = repr(float(msg.linear_acceleration.z)).encode() if data is None else bytes(data)  # type: ignore[attr-defined]
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec  # type: ignore[attr-defined]
            out[m.topic].append(f"{hashlib.sha256(body).hexdigest()}/{stamp}")
    return out


def _digests(path: Path, topics: list[str]) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {t: [] for t in topics}
    with open_log(path) as log:
        for m in log.messages(topics=topics):
            out[m.topic].append(hashlib.sha256(bytes(m.raw)).hexdigest())
    return out


def test_rospy_publisher_at_sensor_rates(roscore: RosCore, tmp_path: Path) -> None:
    topics = ["/rig/points", "/rig/image", "/rig/imu"]
    live = _live(roscore, tmp_path, topics, "--duration", "10")
    try:
        with roscore.python_process(PUBLISHER) as publisher:
            out, err = live.communicate(timeout=90)
            assert live.returncode == 0, err
            assert "DONE" in publisher.output
    finally:
        if live.poll() is None:
            live.kill()
    sent: dict[str, list[str]] = {t: [] for t in topics}
    for line in publisher.output.splitlines():
        parts = line.split()
        if len(parts) == 2 and parts[0] in sent:
            sent[parts[0]].append(parts[1])
    assert len(sent["/rig/imu"]) >= 250
    assert len(sent["/rig/points"]) >= 25
    assert _payload_digests(tmp_path / "live.mcap", topics) == sent  # every message, exactly
    run = open_run(tmp_path / "run")
    frames = run.table("frames").num_rows
    # realtime mode: a sweep that arrives while the detector is busy is skipped (counted), so
    # how many become frames depends on the machine's load; every one is accounted for
    found = re.search(r"frames: (\d+) assembled, (\d+) skipped", out)
    assert found is not None, out
    assert frames == int(found[1]) - int(found[2]) >= 1, out
    detections = run.detections("cluster-detector")
    # three car-sized boxes of points stand on the ground in every sweep
    assert sum(len(v) == 3 for v in detections.values()) >= 0.9 * frames
    assert "realtime" in str(run.manifest.pipeline)
    assert not [p for p in stale_segments() if "live-" in p.name]


@pytest.mark.shared_data
def test_rosbag_play_of_a_real_bag(roscore: RosCore, tmp_path: Path, shared_data: Path) -> None:
    bag = shared_data / KITTI_BAG
    live = _live(roscore, tmp_path, KITTI_TOPICS, "--duration", "14")
    # publishing starts once every played topic has a connected subscriber (redrive's scrapers),
    # not after a fixed delay that a loaded machine may outlast
    play = subprocess.run(
        [
            "rosbag",
            "play",
            "--wait-for-subscribers",
            "-r",
            "0.2",
            str(bag),
            "--topics",
            *KITTI_TOPICS,
        ],
        env=roscore.env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert play.returncode == 0, play.stderr
    out, err = live.communicate(timeout=60)
    assert live.returncode == 0, err
    assert _digests(tmp_path / "live.mcap", KITTI_TOPICS) == _digests(bag, KITTI_TOPICS)
    run = open_run(tmp_path / "run")
    # realtime mode: a frame that arrives while the detector is busy with the one before is
    # skipped (counted), never queued — how many depends on the machine's load, not on redrive
    skipped = int(re.search(r"3 assembled, (\d+) skipped", out)[1])  # type: ignore[index]
    assert run.table("frames").num_rows == 3 - skipped >= 1, out
    found = run.detections("cluster-detector")
    assert all(len(v) > 0 for v in found.values())
    assert "3 to the pipeline" in out


def test_live_replay_source_recorded_exactly(demo_log: Path, tmp_path: Path) -> None:
    """`redrive live --replay`: a log played at its rate as a sensor rig (its own process), frames
    through a detector and a planner, every message recorded (lossless) equal to the log's."""
    import numpy as np

    from redrive.io.ros.decoders import decode

    argv = [
        sys.executable, "-m", "redrive", "live", "--replay", str(demo_log), "--rate", "2",
        "--frames", "20", "--duration", "120", "--record", str(tmp_path / "copy.mcap"),
        "--out", str(tmp_path / "run"),
        "--perception", "cluster-detector", "--planning", "idm-planner",
    ]  # fmt: skip
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    run = open_run(tmp_path / "run")
    frames = run.table("frames").num_rows
    # --frames: a count of assembled frames, not a clock, ends the session; in realtime mode a
    # frame that arrives while the pipeline is busy is skipped (counted), never queued
    found = re.search(r"frames: (\d+) assembled, (\d+) skipped", done.stdout)
    assert found is not None, done.stdout
    assert int(found[1]) == 20, done.stdout
    assert frames == 20 - int(found[2]) >= 1, done.stdout
    steps = run.table("steps").to_pylist()
    planner = {s["frame_index"]: s for s in steps if s["algorithm"] == "idm-planner"}
    # how many frames find an ego state within the tolerance depends on how busy the machine is
    # (a keep-latest stream, a skipped frame); what does not: the planner runs on every frame,
    # succeeds on each that has one, and fails only on those without, which the frames table says
    without_state = {
        f["frame_index"]
        for f in run.table("frames").to_pylist()
        if "vehicle_state" in (f["missing_inputs"] or "")
    }
    assert len(planner) == frames
    for index, step in planner.items():
        assert (step["status"] == "ok") == (index not in without_state), step
    with open_log(demo_log) as original, open_log(tmp_path / "copy.mcap") as copy:
        got = [decode(m, copy.deserialize) for m in copy.messages(topics=["/lidar_top"])]
        assert len(got) >= frames
        want = [
            decode(m, original.deserialize)
            for _, m in zip(range(len(got)), original.messages(topics=["/lidar_top"]), strict=False)
        ]
    for a, b in zip(got, want, strict=True):
        assert a.stamp_ns == b.stamp_ns
        assert np.array_equal(a.value.xyz, b.value.xyz)  # type: ignore[union-attr]
    assert not [p for p in stale_segments() if "live-" in p.name]


def test_a_killed_live_run_leaves_no_source_and_no_segment(demo_log: Path, tmp_path: Path) -> None:
    """SIGKILL of `redrive live`: its source process notices and stops, unlinking its streams."""
    import signal

    argv = [
        sys.executable, "-m", "redrive", "live", "--replay", str(demo_log), "--duration", "60",
        "--out", str(tmp_path / "run"),
    ]  # fmt: skip
    live = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    assert live.stderr is not None
    for line in live.stderr:
        if "receiving" in line:
            break
    session = f"redrive.live-{live.pid}."
    assert [p for p in Path("/dev/shm").iterdir() if p.name.startswith(session)]
    live.send_signal(signal.SIGKILL)
    live.wait(timeout=10)
    live.stderr.close()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        left = [p for p in Path("/dev/shm").iterdir() if p.name.startswith(session)]
        if not left:
            break
        time.sleep(0.1)
    assert not left, left
