"""``redrive live --foxglove``: a WebSocket client watches a ROS 1 recording session fed by a
rospy publisher (a frame's results reaching a client: tests/interop/test_live_view.py).

The client speaks the Foxglove WebSocket protocol as foxglove-sdk 0.30 serves it (subprotocol
``foxglove.sdk.v1``, as in tests/interop/test_serve.py): it subscribes to every channel the
server advertises, and the publisher starts once the sensor channels are subscribed.  The view
reads the streams keep-latest, so the test checks that what arrives is what was published (not
that everything arrives); the recording made alongside must hold every message.
"""

from __future__ import annotations

import asyncio
import base64
import hashlib
import json
import os
import signal
import struct
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.io import open_log
from redrive.io.ros.typestore import typestore_for
from tests.live.conftest import RosCore, ros1_missing

pytestmark = [
    pytest.mark.skipif(ros1_missing() is not None, reason=str(ros1_missing())),
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
]
websockets = pytest.importorskip("websockets")
pytest.importorskip("foxglove", reason="needs foxglove-sdk (pip install 'redrive[foxglove]')")
message_factory = pytest.importorskip("google.protobuf.message_factory")
from google.protobuf import descriptor_pb2, descriptor_pool  # noqa: E402

_SUBPROTOCOL = "foxglove.sdk.v1"
_POINTS = "/fx/points"

# Publishes, once the file argv[1] exists, a 6000-point cloud (x, y, z, intensity float32) at
# 10 Hz until argv[2] exists; prints the sha256 of each cloud's data.  (One topic: each is a
# scraper process of its own, and starting them is most of this test's time.)
PUBLISHER = r"""
import hashlib, os, sys, time
import numpy as np
import rospy
from sensor_msgs.msg import PointCloud2, PointField

go, stop = sys.argv[1], sys.argv[2]
rospy.init_node("fox_rig", anonymous=True)
points = rospy.Publisher("/fx/points", PointCloud2, queue_size=50)
print("READY", flush=True)
while not os.path.exists(go) and not rospy.is_shutdown():
    time.sleep(0.02)
rng = np.random.default_rng(0)
n = 6000
fields = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1)
          for i, c in enumerate(("x", "y", "z", "intensity"))]
start = time.time()
tick = 0
while not os.path.exists(stop) and time.time() - start < 60 and not rospy.is_shutdown():
    pts = rng.uniform(-40, 40, (n, 4)).astype(np.float32)
    cloud = PointCloud2(height=1, width=n, fields=fields, is_bigendian=False, point_step=16,
                        row_step=16 * n, is_dense=True, data=pts.tobytes())
    cloud.header.stamp = rospy.Time.now(); cloud.header.frame_id = "velodyne"
    print("POINTS", hashlib.sha256(pts.tobytes()).hexdigest(), flush=True)
    points.publish(cloud)
    tick += 1
    time.sleep(max(0.0, start + tick * 0.1 - time.time()))
print("DONE", flush=True)
"""


def _proto_class(channel: dict[str, Any]) -> Any:
    """The protobuf message class of a channel's schema (a FileDescriptorSet, base64)."""
    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


class _Watcher:
    """Subscribes to every advertised channel; keeps each topic's message payloads."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.channels: dict[int, dict[str, Any]] = {}
        self.subscribed: dict[int, int] = {}  # subscription id → channel id
        self.received: dict[str, list[bytes]] = defaultdict(list)
        self.notes: list[dict[str, Any]] = []  # the server's other JSON messages (status …)

    def by_topic(self) -> dict[str, dict[str, Any]]:
        return {c["topic"]: c for c in self.channels.values()}

    async def step(self) -> None:
        try:
            frame = await asyncio.wait_for(self.ws.recv(), 1.0)
        except TimeoutError:
            return
        if isinstance(frame, str):
            msg = json.loads(frame)
            if msg["op"] == "advertise":
                subs = []
                for channel in msg["channels"]:
                    self.channels[channel["id"]] = channel
                    sub = len(self.subscribed)
                    self.subscribed[sub] = channel["id"]
                    subs.append({"id": sub, "channelId": channel["id"]})
                await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
            elif msg["op"] != "serverInfo":
                self.notes.append(msg)
        elif frame[0] == 1:  # message data: subscription id u32, log time u64, payload
            (sub,) = struct.unpack_from("<I", frame, 1)
            topic = self.channels[self.subscribed[sub]]["topic"]
            self.received[topic].append(bytes(frame[13:]))

    async def until(self, done: Any, *, timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not done():
            if time.monotonic() > deadline:
                got = {t: len(v) for t, v in self.received.items()}
                pytest.fail(
                    f"no {what} within {timeout_s} s; channels {list(self.by_topic())}, "
                    f"received {got}; the server said {self.notes}"
                )
            await self.step()


def _url(live: subprocess.Popen[str], timeout_s: float) -> str:
    assert live.stdout is not None
    deadline = time.monotonic() + timeout_s
    seen = []
    while time.monotonic() < deadline:
        line = live.stdout.readline()
        if not line:
            break
        seen.append(line)
        if "ws://" in line:
            return line[line.index("ws://") :].split()[0]
    pytest.fail(f"redrive live printed no ws:// URL:\n{''.join(seen)}")


def test_a_client_sees_a_live_ros1_recording_session(roscore: RosCore, tmp_path: Path) -> None:
    go, stop = tmp_path / "go", tmp_path / "stop"
    argv = [
        sys.executable, "-m", "redrive", "live", "--master", roscore.uri,
        "--topics", _POINTS, "--record", str(tmp_path / "live.mcap"),
        "--wait", "30", "--foxglove", "--foxglove-port", "0", "--duration", "90",
    ]  # fmt: skip
    # started first: it waits for the topics while the publisher starts
    live = subprocess.Popen(
        argv,
        env=dict(os.environ, ROS_MASTER_URI=roscore.uri),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        with roscore.python_process(PUBLISHER, str(go), str(stop)) as publisher:
            try:
                url = _url(live, 60)

                async def watch() -> _Watcher:
                    async with websockets.connect(
                        url, subprotocols=[_SUBPROTOCOL], max_size=None, close_timeout=1
                    ) as ws:
                        client = _Watcher(ws)
                        sensors = {_POINTS, f"/foxglove{_POINTS}"}
                        await client.until(
                            lambda: sensors <= set(client.by_topic()), timeout_s=30, what="channels"
                        )
                        await client.step()  # the subscription is sent with the advertisement
                        go.touch()
                        wanted = {_POINTS: 2, f"/foxglove{_POINTS}": 2}
                        await client.until(
                            lambda: all(len(client.received[t]) >= n for t, n in wanted.items()),
                            timeout_s=60,
                            what="messages on every channel",
                        )
                        return client

                client = asyncio.run(watch())
            finally:
                stop.touch()
                deadline = time.monotonic() + 10  # every cloud sent has reached the recorder
                while "DONE" not in publisher.output and time.monotonic() < deadline:
                    time.sleep(0.05)
                time.sleep(0.5)
                live.send_signal(signal.SIGINT)
                try:
                    out, err = live.communicate(timeout=60)
                except subprocess.TimeoutExpired:
                    live.kill()
                    out, err = live.communicate()
            assert live.returncode == 0, err
    finally:
        if live.poll() is None:  # the publisher did not start
            live.kill()
            live.communicate()

    clouds = [ln.split()[1] for ln in publisher.output.splitlines() if ln.startswith("POINTS ")]
    channels = client.by_topic()
    assert (channels[_POINTS]["schemaName"], channels[_POINTS]["encoding"]) == (
        "sensor_msgs/PointCloud2",
        "ros1",
    )
    assert channels[_POINTS]["schemaEncoding"] == "ros1msg"
    assert channels[f"/foxglove{_POINTS}"]["schemaName"] == "foxglove.PointCloud"

    # the ROS 1 bytes as published; the converted cloud holds the same points
    store = typestore_for(1)[0]
    for raw in client.received[_POINTS]:
        msg = store.deserialize_ros1(raw, "sensor_msgs/msg/PointCloud2")
        assert hashlib.sha256(bytes(msg.data)).hexdigest() in clouds
    point_cloud = _proto_class(channels[f"/foxglove{_POINTS}"])
    for raw in client.received[f"/foxglove{_POINTS}"]:
        cloud = point_cloud.FromString(raw)
        assert [f.name for f in cloud.fields] == ["x", "y", "z", "intensity"]
        assert cloud.frame_id == "velodyne"
        assert hashlib.sha256(cloud.data).hexdigest() in clouds

    # the recording alongside lost nothing
    with open_log(tmp_path / "live.mcap") as log:
        recorded = [log.deserialize(m) for m in log.messages(topics=[_POINTS])]
    digests = [hashlib.sha256(np.asarray(m.data).tobytes()).hexdigest() for m in recorded]  # type: ignore[attr-defined]
    assert digests == clouds
    assert "foxglove:" in out
