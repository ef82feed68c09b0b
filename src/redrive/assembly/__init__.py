"""Frame assembly (layer L4, DESIGN.md's Sensor Dispatcher): from a log's messages to synchronised
:class:`~redrive.types.Frame`\\ s — the sensor map, sensor mounts over a tf buffer, camera
calibrations, and the summary ``redrive info`` prints.

>>> from redrive.io import open_log
>>> from redrive.assembly import FrameAssembler
>>> with open_log("drive.bag") as log:                      # doctest: +SKIP
...     for frame in FrameAssembler(log).frames():
...         ...
"""

from __future__ import annotations

from redrive.assembly.frames import FrameAssembler
from redrive.assembly.sensor_map import SensorMap, infer_sensor_map

__all__ = ["FrameAssembler", "SensorMap", "infer_sensor_map"]
