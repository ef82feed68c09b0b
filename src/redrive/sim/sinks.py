"""Where rendered sensor data goes, and what it is rendered from: the :class:`MessageSink`
protocol (a log writer, or an in-memory :class:`SampleSink`) and the :class:`SensorWorld`
protocol (a world, or a closed loop's view of two)."""

from __future__ import annotations

from typing import Protocol

import numpy as np
import numpy.typing as npt
from rosbags.typesys.store import Typestore

from redrive.io.base import LogMessage
from redrive.io.ros.decoders import decode
from redrive.io.ros.typestore import typestore_for
from redrive.sim.scene import Scene
from redrive.types import VehicleState

__all__ = ["MessageSink", "SampleSink", "SensorWorld"]


class MessageSink(Protocol):
    """Where a :class:`SensorSimulation` sends its messages: a
    :class:`~redrive.io.mcap.writer.McapWriter` (:func:`synthesize`), or a live source's buffer."""

    @property
    def typestore(self) -> Typestore:
        """The ROS 2 typestore messages handed to :meth:`write_raw` are serialised with."""
        ...

    def write(
        self,
        topic: str,
        log_time_ns: int,
        value: object,
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> None:
        """A data-model value, as :meth:`McapWriter.write <redrive.io.mcap.writer.McapWriter.write>`."""
        ...

    def write_raw(
        self, topic: str, msgtype: str, log_time_ns: int, cdr_bytes: bytes | memoryview
    ) -> None:
        """An already-serialised ROS 2 CDR message (the 2D LiDAR's ``LaserScan``)."""
        ...


class SampleSink:
    """Base of the :class:`MessageSink` s that keep rendered samples in memory instead of writing
    a log (a live source's buffer, a closed loop's frame): the typestore the 2D LiDAR's
    ``LaserScan`` is serialised with, and :meth:`write_raw` decoding it back to :meth:`write`, as
    a replay of the log would.  Subclasses say which topics they keep (:meth:`keeps`)."""

    _typestore: Typestore | None = None

    def keeps(self, topic: str) -> bool:
        """Whether samples of ``topic`` are kept (the others are dropped)."""
        raise NotImplementedError

    @property
    def typestore(self) -> Typestore:
        if self._typestore is None:
            self._typestore = typestore_for(2, needed=("sensor_msgs/msg/LaserScan",))[0]
        return self._typestore

    def write(
        self,
        topic: str,
        log_time_ns: int,
        value: object,
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> None:
        raise NotImplementedError

    def write_raw(
        self, topic: str, msgtype: str, log_time_ns: int, cdr_bytes: bytes | memoryview
    ) -> None:
        if not self.keeps(topic):
            return
        message = LogMessage(
            topic=topic, msgtype=msgtype, log_time_ns=log_time_ns, encoding="cdr", raw=cdr_bytes
        )
        ts = self.typestore
        decoded = decode(message, lambda m: ts.deserialize_cdr(bytes(m.raw), m.msgtype))
        self.write(
            topic, log_time_ns, decoded.value, frame_id=decoded.frame_id, stamp_ns=decoded.stamp_ns
        )


class SensorWorld(Protocol):
    """What the sensors are rendered from: a :class:`~redrive.sim.world.World`, or a closed
    loop's view of two worlds (the scene of one, the ego of the other)."""

    @property
    def time_ns(self) -> int:
        """The current time, int ns since the epoch."""
        ...

    def step_to(self, stamp_ns: int) -> None:
        """Advance to ``stamp_ns`` (never backwards)."""
        ...

    def scene(self) -> Scene:
        """What the sensors see at :attr:`time_ns` (the ego's pose included)."""
        ...

    def ego_state(self) -> VehicleState:
        """The ego's true state at :attr:`time_ns` (IMU, GNSS, odometry, the pose topics)."""
        ...

    def map_from_base(self) -> npt.NDArray[np.float64]:
        """The ego pose at :attr:`time_ns`."""
        ...

    def map_from_base_at(self, stamp_ns: int) -> npt.NDArray[np.float64]:
        """The ego pose at a recent time (a LiDAR sweep's ego-motion skew)."""
        ...
