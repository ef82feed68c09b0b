"""Planners for batch tests that take their worker process down (a crash no ``except`` sees)."""

from __future__ import annotations

import dataclasses
import os
import signal
import time
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from redrive.algorithms import Algorithm, Role, StageOutputs
from redrive.types import Box3D, DetectedObject, Frame, ObjectClass, PlannedPath


def _stand_still(stamp_ns: int) -> PlannedPath:
    t = np.arange(0.0, 3.0 + 1e-9, 0.5)
    zeros = np.zeros_like(t)
    return PlannedPath(stamp_ns=stamp_ns, waypoints=np.column_stack([zeros, zeros, zeros, t]))


class KillAtFrame(Algorithm):
    """SIGKILLs its own process at frame ``frame_index``: only logs that long lose their worker."""

    role = Role.PLANNING
    defaults = MappingProxyType({"frame_index": 25})

    def setup(self, config: Mapping[str, Any]) -> None:
        self.frame_index = int(config["frame_index"])

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        if frame.index == self.frame_index:
            os.kill(os.getpid(), signal.SIGKILL)
        return _stand_still(frame.stamp_ns)


class KillOnce(Algorithm):
    """SIGKILLs its process on the first frame of the first run that creates ``marker`` (an
    atomic O_EXCL create: exactly one run dies, whichever gets there first)."""

    role = Role.PLANNING
    defaults = MappingProxyType({"marker": ""})

    def setup(self, config: Mapping[str, Any]) -> None:
        self.marker = str(config["marker"])

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        if frame.index == 0:
            try:
                fd = os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                pass
            else:
                os.close(fd)
                os.kill(os.getpid(), signal.SIGKILL)
        return _stand_still(frame.stamp_ns)


#: how long :class:`InterruptDriver` waits for the driver's SIGINT (it comes within milliseconds)
_ANSWER_WAIT_S = 10.0


class InterruptDriver(Algorithm):
    """Sends SIGINT (Ctrl-C) to process ``driver_pid`` at frame ``frame_index``, once, and waits
    for the driver to interrupt it back: the run that creates ``marker`` does; later runs plan
    on."""

    role = Role.PLANNING
    defaults = MappingProxyType({"driver_pid": 0, "frame_index": 21, "marker": ""})

    def setup(self, config: Mapping[str, Any]) -> None:
        self.driver_pid = int(config["driver_pid"])
        self.frame_index = int(config["frame_index"])
        self.marker = str(config["marker"])

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        if frame.index == self.frame_index:
            try:
                fd = os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                pass
            else:
                os.close(fd)
                os.kill(self.driver_pid, signal.SIGINT)
                # the driver answers with a SIGINT to this cell: wait for it here, so that the
                # run is interrupted on this frame and not (by chance) after its last one
                time.sleep(_ANSWER_WAIT_S)
        return _stand_still(frame.stamp_ns)


class NoisyOracle(Algorithm):
    """A detector and tracker for evaluation tests: the frame's ground truth, shifted by a
    deterministic error that grows with the object, some objects missed, one false positive on
    some frames, confidences that do not sort hits above misses — so that AP is neither 0 nor 1
    and differs from log to log.  ``worse``: it misses more."""

    role = Role.PERCEPTION
    defaults = MappingProxyType({"worse": False})

    def setup(self, config: Mapping[str, Any]) -> None:
        self.worse = bool(config["worse"])

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        out = []
        for obj in frame.ground_truth or ():
            key = (obj.object_id * 7 + frame.index * 3) % 11
            if key == 0 or (self.worse and key % 3 == 0):
                continue  # missed
            shift = 0.15 * key if obj.object_id % 3 else 0.9 * key  # some far off: FPs
            box = Box3D(
                center=np.asarray(obj.box.center) + np.array([shift, 0.0, 0.0]),
                size=np.asarray(obj.box.size),
                yaw_rad=obj.box.yaw_rad,
            )
            conf = 0.3 + 0.06 * ((key * 5 + obj.object_id) % 11)
            out.append(dataclasses.replace(obj, box=box, confidence=conf))
        if frame.index % 4 == 1:
            out.append(
                DetectedObject(
                    object_id=999,
                    object_class=ObjectClass.VEHICLE,
                    confidence=0.5 + 0.04 * (frame.index % 7),
                    box=Box3D(center=np.array([30.0, -5.0, 0.0]), size=np.array([4.0, 1.8, 1.5])),
                )
            )
        return out


class Sleepy(Algorithm):
    """Sleeps a second a frame: a cell that is still running when its driver is killed."""

    role = Role.PLANNING

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        import time

        time.sleep(1.0)
        return _stand_still(frame.stamp_ns)
