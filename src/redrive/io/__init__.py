"""Log I/O (layer L3), by format: ``mcap/`` (files, split sets, the writer), ``rosbag1/``,
``rosbag2/``, ``datasets/`` (KITTI, nuScenes, mmdetection3d infos) and ``ros/`` (type store,
encoding, decoders to the data model); here what they share: the reader interface, the registry
that decides what a log is, damage reports, what a log holds beside its messages
(:mod:`redrive.io.content`), ``convert`` and ``repair``.  Frames are assembled above, in
:mod:`redrive.assembly`.

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
