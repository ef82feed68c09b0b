"""Arrow tables of a run → the data model (the read side used by evaluation and the GUI)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from redrive.types import (
    Box3D,
    ControlCommands,
    DetectedObject,
    ObjectClass,
    PlannedPath,
    VehicleState,
)

__all__ = ["commands_by_frame", "ego_by_frame", "objects_by_frame", "paths_by_frame"]


def _columns(table: pa.Table, names: tuple[str, ...]) -> dict[str, list[Any]]:
    return {n: table.column(n).to_pylist() for n in names if n in table.schema.names}


def _groups(frame_index: list[int]) -> list[tuple[int, int, int]]:
    """(frame, start, stop) of runs of equal frame indices (the table is sorted by frame)."""
    out: list[tuple[int, int, int]] = []
    start = 0
    for i in range(1, len(frame_index) + 1):
        if i == len(frame_index) or frame_index[i] != frame_index[start]:
            out.append((frame_index[start], start, i))
            start = i
    return out


_OBJECT_COLUMNS = (
    "frame_index",
    "object_id",
    "object_class",
    "confidence",
    "x",
    "y",
    "z",
    "length",
    "width",
    "height",
    "yaw_rad",
    "vx",
    "vy",
    "vz",
    "ax",
    "ay",
    "az",
    "bbox_x",
    "bbox_y",
    "bbox_w",
    "bbox_h",
    "num_lidar_points",
    "visible",
)


def objects_by_frame(
    table: pa.Table, *, frames: list[int] | None = None
) -> dict[int, tuple[DetectedObject, ...]]:
    """Detections or ground-truth rows (sorted by frame) → frame_index → objects.

    ``frames`` lists frames that must appear even without a row (as an empty tuple).  Boxes,
    velocities and accelerations are in the frame they were written in; ``orientation`` is not
    stored and comes back as zeros.
    """
    c = _columns(table, _OBJECT_COLUMNS)
    n = table.num_rows
    conf = c.get("confidence", [1.0] * n)
    nlp = c.get("num_lidar_points", [None] * n)
    vis = c.get("visible", [None] * n)
    out: dict[int, tuple[DetectedObject, ...]] = dict.fromkeys(frames or (), ())
    for frame, start, stop in _groups(c["frame_index"]):
        objs = []
        for i in range(start, stop):
            bbox = (c["bbox_x"][i], c["bbox_y"][i], c["bbox_w"][i], c["bbox_h"][i])
            objs.append(
                DetectedObject(
                    object_id=c["object_id"][i],
                    object_class=ObjectClass(c["object_class"][i]),
                    confidence=conf[i],
                    box=Box3D(
                        center=np.array([c["x"][i], c["y"][i], c["z"][i]]),
                        size=np.array([c["length"][i], c["width"][i], c["height"][i]]),
                        yaw_rad=c["yaw_rad"][i],
                    ),
                    velocity=np.array([c["vx"][i], c["vy"][i], c["vz"][i]]),
                    acceleration=np.array([c["ax"][i], c["ay"][i], c["az"][i]]),
                    bbox_2d=None if bbox[0] is None else bbox,
                    num_lidar_points=nlp[i],
                    visible=vis[i],
                )
            )
        out[frame] = tuple(objs)
    return out


def paths_by_frame(table: pa.Table) -> dict[int, PlannedPath]:
    """Path rows of one algorithm (sorted by frame, then waypoint) → frame_index → path."""
    fi = table.column("frame_index").to_pylist()
    stamp = table.column("stamp_ns").to_pylist()
    frame_id = table.column("frame_id").to_pylist()
    wp: npt.NDArray[np.float64] = np.column_stack(
        [table.column(n).to_numpy().astype(np.float64) for n in ("x", "y", "z", "t_s")]
    ).reshape(-1, 4)
    out: dict[int, PlannedPath] = {}
    for frame, start, stop in _groups(fi):
        out[frame] = PlannedPath(
            stamp_ns=stamp[start], waypoints=wp[start:stop].copy(), frame_id=frame_id[start]
        )
    return out


def commands_by_frame(table: pa.Table) -> dict[int, ControlCommands]:
    """Command rows of one algorithm → frame_index → commands."""
    c = _columns(table, ("frame_index", "throttle", "brake", "steering_angle_rad"))
    return {
        f: ControlCommands(throttle=t, brake=b, steering_angle_rad=s)
        for f, t, b, s in zip(
            c["frame_index"], c["throttle"], c["brake"], c["steering_angle_rad"], strict=True
        )
    }


def ego_by_frame(table: pa.Table) -> dict[int, VehicleState]:
    """Ego rows → frame_index → vehicle state."""
    names = ("frame_index", "stamp_ns", "frame_id", "x", "y", "z", "vx", "vy", "vz")
    c = _columns(table, (*names, "ax", "ay", "az", "heading_rad", "yaw_rate_rad_s"))
    out: dict[int, VehicleState] = {}
    for i, frame in enumerate(c["frame_index"]):
        out[frame] = VehicleState(
            stamp_ns=c["stamp_ns"][i],
            frame_id=c["frame_id"][i],
            position=np.array([c["x"][i], c["y"][i], c["z"][i]]),
            velocity=np.array([c["vx"][i], c["vy"][i], c["vz"][i]]),
            acceleration=np.array([c["ax"][i], c["ay"][i], c["az"][i]]),
            heading_rad=c["heading_rad"][i],
            yaw_rate_rad_s=c["yaw_rate_rad_s"][i],
        )
    return out
