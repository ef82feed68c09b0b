"""Log I/O (layer L2): readers for ROS 1 bags, ROS 2 bags, MCAP, KITTI and nuScenes; decoders to the data
model; the Sensor Dispatcher that assembles frames; the MCAP writer.

>>> from redrive.io import open_log
>>> with open_log("drive.bag") as log:                      # doctest: +SKIP
...     for message in log.messages(topics=["/velodyne_points"]):
...         ...
"""

from __future__ import annotations

from redrive.io.base import Encoding, LogMessage, LogReader, ReaderCapabilities, TopicInfo
from redrive.io.readers import detect_format, open_log, reader_formats

__all__ = [
    "Encoding",
    "LogMessage",
    "LogReader",
    "ReaderCapabilities",
    "TopicInfo",
    "detect_format",
    "open_log",
    "reader_formats",
]
