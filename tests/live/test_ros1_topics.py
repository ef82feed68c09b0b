"""ROS 1 topic discovery against a real master and a real rospy publisher (/usr/bin/python3)."""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Iterator
from xmlrpc.server import SimpleXMLRPCServer

import pytest

from redrive.cli.main import main
from redrive.errors import ConfigError, TransportError
from redrive.io.ros.decoders import DecodedKind
from redrive.live import TopicInfo, list_topics, master_alive
from redrive.live.ros1 import DEFAULT_MASTER_URI, default_master_uri
from redrive.types import SensorType
from tests.live.conftest import RosCore

#: A rospy node publishing a lidar cloud, a camera image, an IMU and a string at 20 Hz under the
#: namespace argv[1], and subscribing to ``NS/any`` with AnyMsg (a topic of no known type).
PUBLISHER = """
import sys
import numpy as np
import rospy
from sensor_msgs.msg import Image, Imu, PointCloud2, PointField
from std_msgs.msg import String

ns = sys.argv[1]
rospy.init_node("fake_sensors")
cloud_pub = rospy.Publisher(ns + "/velodyne_points", PointCloud2, queue_size=1)
image_pub = rospy.Publisher(ns + "/camera/image_raw", Image, queue_size=1)
imu_pub = rospy.Publisher(ns + "/imu/data", Imu, queue_size=1)
text_pub = rospy.Publisher(ns + "/chatter", String, queue_size=1)
rospy.Subscriber(ns + "/any", rospy.AnyMsg, lambda msg: None)

points = np.random.default_rng(0).normal(size=(1000, 4)).astype(np.float32)
cloud = PointCloud2(
    height=1, width=len(points), is_bigendian=False, point_step=16, row_step=16 * len(points),
    is_dense=True, data=points.tobytes(),
    fields=[PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
            for i, n in enumerate(("x", "y", "z", "intensity"))],
)
cloud.header.frame_id = "velodyne"
image = Image(height=4, width=6, encoding="rgb8", step=18, data=bytes(range(72)))
image.header.frame_id = "camera"
imu = Imu()
imu.header.frame_id = "imu"
imu.orientation.w = 1.0
imu.linear_acceleration.z = 9.81
print("READY", flush=True)
rate = rospy.Rate(20)
try:
    while not rospy.is_shutdown():
        now = rospy.Time.now()
        for msg, pub in ((cloud, cloud_pub), (image, image_pub), (imu, imu_pub)):
            msg.header.stamp = now
            pub.publish(msg)
        text_pub.publish(String(data="hello"))
        rate.sleep()
except rospy.ROSInterruptException:
    pass
"""

NS = "/redrive_test"
EXPECTED = {
    f"{NS}/velodyne_points": ("sensor_msgs/PointCloud2", "pointcloud2", SensorType.LIDAR),
    f"{NS}/camera/image_raw": ("sensor_msgs/Image", "image", SensorType.CAMERA),
    f"{NS}/imu/data": ("sensor_msgs/Imu", "imu", SensorType.IMU),
    f"{NS}/chatter": ("std_msgs/String", None, None),
}


def _wait_for_topics(uri: str, names: set[str], *, timeout_s: float = 10.0) -> list[TopicInfo]:
    """list_topics once every name in ``names`` has a publisher (registration is asynchronous)."""
    deadline = time.monotonic() + timeout_s
    while True:
        topics = list_topics(uri)
        published = {t.name for t in topics if t.publishers}
        if names <= published or time.monotonic() > deadline:
            return topics
        time.sleep(0.05)


@pytest.fixture(scope="module")
def publisher(roscore: RosCore) -> Iterator[RosCore]:
    """The master with :data:`PUBLISHER` running on it and its topics registered."""
    with roscore.python_process(PUBLISHER, NS):
        _wait_for_topics(roscore.uri, set(EXPECTED))
        yield roscore


def test_list_topics_sees_the_rospy_publisher(publisher: RosCore) -> None:
    topics = {t.name: t for t in list_topics(publisher.uri)}
    for name, (msg_type, decoder, sensor_type) in EXPECTED.items():
        topic = topics[name]
        assert topic.msg_type == msg_type
        assert topic.decoder == decoder
        assert topic.decodable is (decoder is not None)
        assert topic.sensor_type is sensor_type
        assert len(topic.publishers) == 1
        assert topic.publishers[0].startswith("/fake_sensors")
    assert topics[f"{NS}/velodyne_points"].kind is DecodedKind.SENSOR
    assert topics[f"{NS}/chatter"].kind is None
    anything = topics[f"{NS}/any"]  # only an AnyMsg subscriber: the master knows no type
    assert anything.msg_type == "*"
    assert anything.publishers == ()
    assert anything.subscribers == topics[f"{NS}/chatter"].publishers
    assert not anything.decodable
    assert list(topics) == sorted(topics)


def test_the_publisher_really_publishes(publisher: RosCore) -> None:
    """The fixture's helpers: a rospy subscriber under /usr/bin/python3 gets the cloud."""
    done = publisher.run_python(
        "import sys, rospy\n"
        "from sensor_msgs.msg import PointCloud2\n"
        "rospy.init_node('probe', anonymous=True)\n"
        "msg = rospy.wait_for_message(sys.argv[1], PointCloud2, timeout=10)\n"
        "print(msg.width, msg.header.frame_id, [f.name for f in msg.fields])\n",
        f"{NS}/velodyne_points",
    )
    assert done.stdout.split("\n")[0] == "1000 velodyne ['x', 'y', 'z', 'intensity']"


def test_topics_cli_json(publisher: RosCore, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["topics", "--master", publisher.uri, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["master"] == publisher.uri
    topics = {t["topic"]: t for t in out["topics"]}
    for name, (msg_type, decoder, sensor_type) in EXPECTED.items():
        assert topics[name]["type"] == msg_type
        assert topics[name]["decoder"] == decoder
        assert topics[name]["decodable"] is (decoder is not None)
        assert topics[name]["sensor_type"] == (sensor_type.value if sensor_type else None)
        assert topics[name]["publishers"][0].startswith("/fake_sensors")


def test_topics_cli_table_and_ros_master_uri(
    publisher: RosCore, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ROS_MASTER_URI", publisher.uri)  # the default master
    assert main(["topics"]) == 0
    out = capsys.readouterr().out
    assert publisher.uri in out
    for name, (msg_type, decoder, _sensor) in EXPECTED.items():
        assert name in out
        assert msg_type in out
        assert (decoder or "raw") in out


def test_master_alive(roscore: RosCore, dead_master_uri: str) -> None:
    assert master_alive(roscore.uri)
    assert master_alive(roscore.uri + "/")
    assert not master_alive(dead_master_uri, timeout_s=0.5)


# --- no ROS needed below ---------------------------------------------------------------------


def test_master_down_is_a_clear_error(dead_master_uri: str) -> None:
    with pytest.raises(TransportError) as err:
        list_topics(dead_master_uri)
    text = str(err.value)
    assert dead_master_uri in text
    assert "roscore" in text
    assert "ROS_MASTER_URI" in text


def test_topics_cli_master_down(dead_master_uri: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["topics", "--master", dead_master_uri]) == 1
    err = capsys.readouterr().err
    assert err.startswith("redrive: error: no ROS master at " + dead_master_uri)
    assert "Traceback" not in err


def test_a_master_that_does_not_answer_times_out() -> None:
    with socket.socket() as server:  # listens, never accepts: the connection hangs in the backlog
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        uri = f"http://127.0.0.1:{server.getsockname()[1]}"
        start = time.monotonic()
        with pytest.raises(TransportError, match=r"did not answer getTopicTypes within 0\.3 s"):
            list_topics(uri, timeout_s=0.3)
        assert time.monotonic() - start < 2.0
        assert not master_alive(uri, timeout_s=0.3)


def test_a_server_that_is_not_a_master() -> None:
    server = SimpleXMLRPCServer(("127.0.0.1", 0), logRequests=False)  # no methods: a Fault
    thread = threading.Thread(target=server.serve_forever, args=(0.02,), daemon=True)
    thread.start()
    try:
        uri = f"http://127.0.0.1:{server.server_address[1]}"
        with pytest.raises(TransportError, match="not as a ROS master"):
            list_topics(uri)
    finally:
        server.shutdown()
        server.server_close()
        thread.join()


@pytest.mark.parametrize(
    "uri", ["127.0.0.1:11311", "https://127.0.0.1:11311", "http://127.0.0.1", "http://:11311"]
)
def test_a_malformed_uri_is_a_config_error(uri: str) -> None:
    with pytest.raises(ConfigError, match="http://HOST:PORT"):
        list_topics(uri)
    with pytest.raises(ConfigError):
        master_alive(uri)


def test_default_master_uri() -> None:
    assert default_master_uri({}) == DEFAULT_MASTER_URI == "http://127.0.0.1:11311"
    assert default_master_uri({"ROS_MASTER_URI": " "}) == DEFAULT_MASTER_URI
    assert default_master_uri({"ROS_MASTER_URI": "http://robot:11311"}) == "http://robot:11311"
