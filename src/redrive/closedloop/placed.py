"""Reactive agents in a frame's ground truth: the rows of the objects whose agent left its log
take the agent's pose, seen from the driven ego — in the columns, so the frame's objects stay
rows of one batch (``ObjectColumns.shared_by`` gives them to the planner, the collision check
and the results writer without building an object field by field)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from redrive.geometry import invert
from redrive.sim.ego import pose_matrix
from redrive.types import ObjectColumns, VehicleState

__all__ = ["at_poses"]


def at_poses(
    columns: ObjectColumns,
    poses: Mapping[int, tuple[float, float, float, float]],
    *,
    driven: VehicleState,
) -> ObjectColumns:
    """``columns`` (the driven ego's base frame) with each row whose object id has a pose in
    ``poses`` — x, y, yaw, speed in the map frame (along its lane line, or its logged path) — at
    that pose: centre (its height kept), heading (the orientation's yaw with it) and velocity
    along the heading.  The same columns when no row has one."""
    if not poses:
        return columns
    rows = [i for i, oid in enumerate(columns.object_id.tolist()) if oid in poses]
    if not rows:
        return columns
    ids = columns.object_id
    map_from_base = pose_matrix(
        float(driven.position[0]), float(driven.position[1]), driven.heading_rad
    )
    base_from_map = invert(map_from_base)
    center = columns.center_m.copy()
    yaws = columns.yaw_rad.copy()
    velocity = columns.velocity_mps.copy()
    orientation = columns.orientation_rad.copy()
    for i in rows:
        x, y, yaw, v = poses[int(ids[i])]
        c = base_from_map @ np.array([x, y, 0.0, 1.0])
        yaw_base = math.remainder(yaw - driven.heading_rad, math.tau)
        center[i, 0], center[i, 1] = c[0], c[1]
        yaws[i] = yaw_base
        velocity[i] = base_from_map[:3, :3] @ np.array([v * math.cos(yaw), v * math.sin(yaw), 0.0])
        orientation[i, 0] = yaw_base
    # copies of the columns' own arrays with some rows set to finite values: nothing for a
    # second check (dataclasses.replace's) to find
    return columns.with_trusted(
        center_m=center, yaw_rad=yaws, velocity_mps=velocity, orientation_rad=orientation
    )
