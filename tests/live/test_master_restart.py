"""A scraper keeps its stream when the ROS master restarts, and subscribes again with the new one."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import pytest

from redrive.live.session import LiveSession
from redrive.testing.ros1 import master_answers
from redrive.transport import Policy, Reader
from tests.live.conftest import ROSMASTER, _stop_group, ros1_missing, start_master

pytestmark = pytest.mark.skipif(ros1_missing() is not None, reason=str(ros1_missing()))

IMU_PUBLISHER = r"""
import rospy
from sensor_msgs.msg import Imu
rospy.init_node("imu_rig", anonymous=True)
pub = rospy.Publisher("/rs/imu", Imu, queue_size=10)
print("READY", flush=True)
rate = rospy.Rate(50)
while not rospy.is_shutdown():
    msg = Imu(); msg.header.stamp = rospy.Time.now(); pub.publish(msg); rate.sleep()
"""


def _messages_within(reader: Reader, seconds: float) -> int:
    deadline, got = time.monotonic() + seconds, 0
    while time.monotonic() < deadline and got < 5:
        got += reader.read(timeout_s=0.2) is not None
    return got


def _drain(reader: Reader) -> None:
    """Read what the stream still holds from before (the publisher ran on after the fifth
    message was read), until it has been quiet for half a second."""
    while reader.read(timeout_s=0.5) is not None:
        pass


def test_scraper_subscribes_again_after_a_master_restart(tmp_path: Path) -> None:
    core, master = start_master(tmp_path / "ros")
    session = None
    try:
        with core.python_process(IMU_PUBLISHER):
            session = LiveSession.ros1(["/rs/imu"], master_uri=core.uri)
            reader = Reader(session.specs[0].stream, policy=Policy.KEEP_LATEST)
            assert _messages_within(reader, 10.0) == 5
        _stop_group(master, wait_s=10)
        _drain(reader)
        assert _messages_within(reader, 1.0) == 0  # publisher and master gone
        master = subprocess.Popen(
            [str(ROSMASTER), "--core", "-p", str(core.port)],
            env=core.env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        deadline = time.monotonic() + 20
        while not master_answers(core.port) and time.monotonic() < deadline:
            time.sleep(0.05)
        with core.python_process(IMU_PUBLISHER):  # registers with the new master
            assert _messages_within(reader, 15.0) == 5
            assert session.alive()
        reader.close()
    finally:
        if session is not None:
            session.close()
        _stop_group(master, wait_s=10)
