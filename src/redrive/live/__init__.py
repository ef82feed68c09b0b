"""Live sources (L5): ROS 1 topics found through the master, scrapers feeding shared memory,
replay and synthetic sources, the live Sensor Dispatcher and the Data Logger (docs/live.md).

Nothing here imports rospy: the core runs under the project's Python, where rospy is not
importable.  The ROS master is reached through its XML-RPC API; processes that need rospy run
under ``/usr/bin/python3`` and hand data over through :mod:`redrive.transport`.

>>> from redrive.live import list_topics
>>> for topic in list_topics("http://127.0.0.1:11311"):      # doctest: +SKIP
...     print(topic.name, topic.msg_type, topic.decoder)
"""

from __future__ import annotations

from redrive.live.ros1 import (
    DEFAULT_MASTER_URI,
    TopicInfo,
    default_master_uri,
    list_topics,
    master_alive,
)

__all__ = [
    "DEFAULT_MASTER_URI",
    "TopicInfo",
    "default_master_uri",
    "list_topics",
    "master_alive",
]
