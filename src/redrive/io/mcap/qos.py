"""The QoS a recording says its ROS 2 publishers offered (MCAP channel metadata
``offered_qos_profiles``, as rosbag2 writes it), so ``ros2 bag play`` republishes each topic
with the right durability.

* ``/tf_static`` (any topic ending in ``tf_static``): reliable, **transient local** — played
  back latched, as ``static_transform_publisher`` offers it: a node that starts late still gets
  the sensor mounts.
* every other topic: reliable, volatile — a reliable publisher matches both reliable and
  best-effort subscribers (sensor drivers' ``SensorDataQoS``), a best-effort one only the latter.

The text is rosbag2's YAML of one ``rclcpp::QoS`` per publisher (ROS 2 Humble and later:
history 3 = unknown, depth 0, reliability 1 = reliable, durability 1 = transient local / 2 =
volatile, infinite deadline and lifespan, liveliness 1 = automatic).
"""

from __future__ import annotations

__all__ = ["LATCHED_QOS", "VOLATILE_QOS", "is_latched", "offered_qos_profiles"]

_PROFILE = """- history: 3
  depth: 0
  reliability: 1
  durability: {durability}
  deadline:
    sec: 2147483647
    nsec: 4294967295
  lifespan:
    sec: 2147483647
    nsec: 4294967295
  liveliness: 1
  liveliness_lease_duration:
    sec: 2147483647
    nsec: 4294967295
  avoid_ros_namespace_conventions: false
"""

#: reliable, transient local (latched): ``/tf_static``.
LATCHED_QOS = _PROFILE.format(durability=1)
#: reliable, volatile: every other topic.
VOLATILE_QOS = _PROFILE.format(durability=2)


def is_latched(topic: str) -> bool:
    """Whether ``topic`` is played back latched (transient local): ``/tf_static`` and
    namespaced ``…/tf_static``."""
    return topic.rstrip("/").endswith("tf_static")


def offered_qos_profiles(topic: str) -> str:
    """The ``offered_qos_profiles`` metadata of a ROS 2 channel on ``topic``."""
    return LATCHED_QOS if is_latched(topic) else VOLATILE_QOS
