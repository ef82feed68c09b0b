"""The LiDAR points of a few frames of a run's log, in base_link, for the report's bird's-eye views.

The run stores no sensor data, so the points are read again from the log the run replayed
(``manifest.log.path``): one LiDAR's clouds only, through the same frame assembly as the run, up
to the last frame wanted.  A frame counts only when its stamp equals the one the run stored for
its index (a moved or rewritten log, another sensor map: its points are left out, never drawn
at the wrong frame).  Closed-loop runs get none: the log's clouds were taken from the logged ego,
not the driven one.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

import numpy as np
import numpy.typing as npt

from redrive.assembly.frames import FrameAssembler
from redrive.errors import RedriveError
from redrive.io import open_log
from redrive.results import Run
from redrive.types import PointCloud, SensorType

__all__ = ["MAX_POINTS", "lidar_points_of_frames"]

logger = logging.getLogger(__name__)

#: points drawn at most per frame (an even subsample of the sweep)
MAX_POINTS = 30_000


def lidar_points_of_frames(
    run: Run, frames: Iterable[int], *, max_points: int = MAX_POINTS
) -> dict[int, npt.NDArray[np.float64]]:
    """Frame index → (N, 2) x, y in base_link (metres) of the first LiDAR of the run's log, for
    those of ``frames`` the log still gives; {} when there is no log, no LiDAR or a closed loop."""
    wanted = set(frames)
    path = run.manifest.log.path
    if not wanted or not path or run.manifest.pipeline.mode_manager == "closed_loop":
        return {}
    stamps = dict(
        zip(
            run.table("frames").column("frame_index").to_pylist(),
            run.table("frames").column("stamp_ns").to_pylist(),
            strict=True,
        )
    )
    out: dict[int, npt.NDArray[np.float64]] = {}
    try:
        with open_log(Path(path), strict=False) as log:
            smap = FrameAssembler(log).sensor_map
            lidar = next((s for s in smap.sensors if s.sensor_type is SensorType.LIDAR), None)
            if lidar is None:
                return {}
            kept = tuple(s for s in smap.sensors if s.sensor_id in (lidar.sensor_id, smap.driver))
            only = replace(smap, sensors=kept, vehicle_state_topic=None, ground_truth_topic=None)
            last = max(wanted)
            for frame in FrameAssembler(log, sensor_map=only).frames():
                if frame.index > last:
                    break
                sample = frame.sensors.get(lidar.sensor_id)
                if frame.index not in wanted or sample is None:
                    continue
                if stamps.get(frame.index) != frame.stamp_ns or not isinstance(
                    sample.data, PointCloud
                ):
                    continue
                xyz = sample.data.xyz
                step = max(1, len(xyz) // max_points)
                xy = xyz[::step, :2].astype(np.float64) + np.asarray(sample.sensor_location[:2])
                out[frame.index] = xy[np.all(np.isfinite(xy), axis=1)]
    except (RedriveError, OSError) as err:
        logger.info("report: no LiDAR points for the bird's-eye views (%s: %s)", path, err)
        return out
    return out
