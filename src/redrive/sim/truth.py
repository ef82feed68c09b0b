"""The ground-truth boxes of a world as columns, for an object-level observation.

:meth:`World.ground_truth_objects <redrive.sim.world.World>` builds validated columns and the
sensors' looks each call; an observation needs only the boxes, and most of them — ids, classes,
sizes, the parked vehicles — do not change from one frame to the next.  :func:`truth_columns`
gives the same rows, in the same order, with the same values, as trusted
:class:`~redrive.types.ObjectColumns`; the constant columns are built once (again when followers
leave or the agents are dropped).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from redrive.sim.agents import ParkedObject
from redrive.types import ObjectColumns

if TYPE_CHECKING:
    from redrive.sim.world import World

__all__ = ["truth_columns", "truth_moving"]


class _Constant:
    """The columns that do not move, and where the moving ones go."""

    def __init__(self, world: World) -> None:
        fleet, static = world._fleet, world._static_truth[0]
        others = world._others()
        nf, n = len(fleet), len(fleet) + len(others)
        self.key = (nf, len(others))
        self.nf = nf
        self.walkers = [
            (k, a) for k, a in enumerate(others, start=nf) if not isinstance(a, ParkedObject)
        ]
        sizes, centers, yaws = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)
        if nf:
            sizes[:nf] = fleet.sizes
            centers[:nf, 2] = fleet.heights / 2
        for k, agent in enumerate(others, start=nf):
            sizes[k] = agent.size_lwh_m
            centers[k, 2] = agent.size_lwh_m[2] / 2
            if isinstance(agent, ParkedObject):
                centers[k, 0], centers[k, 1] = agent.center_xy
                yaws[k] = agent.yaw_rad
        self.n = n
        self.object_ids = np.concatenate(
            [fleet.ids, np.array([a.agent_id for a in others], dtype=np.int64), static.object_id]
        )
        self.classes = (*fleet.classes, *(a.object_class for a in others), *static.object_class)
        self.sizes = np.concatenate([sizes, static.size_m])
        self.centers = np.concatenate([centers, static.center_m])
        self.yaws = np.concatenate([yaws, static.yaw_rad])
        self.velocities = np.concatenate([np.zeros((n, 3)), static.velocity_mps])
        for a in (self.object_ids, self.sizes):
            a.flags.writeable = False


def truth_columns(world: World, cache: _Constant | None) -> tuple[ObjectColumns, _Constant]:
    """``world.ground_truth_objects()``'s rows and values as trusted columns, and the constant
    columns to pass back next time."""
    centers, yaws, vels, cache = truth_moving(world, cache)
    return (
        ObjectColumns.trusted(
            object_id=cache.object_ids,
            object_class=cache.classes,
            center_m=centers,
            size_m=cache.sizes,
            yaw_rad=yaws,
            velocity_mps=vels,
        ),
        cache,
    )


def truth_moving(
    world: World, cache: _Constant | None
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], _Constant]:
    """:func:`truth_columns`' centres (N, 3), yaws (N,) and velocities (N, 3) (new, writable
    arrays), and the constant columns (ids, classes, sizes)."""
    fleet = world._fleet
    nf = len(fleet)
    if cache is None or cache.key != (nf, len(world._walkers) + len(world._parked)):
        cache = _Constant(world)
    centers, yaws, vels = cache.centers.copy(), cache.yaws.copy(), cache.velocities.copy()
    if nf:
        poses = fleet.poses()
        centers[:nf, 0], centers[:nf, 1] = poses[0], poses[1]
        yaws[:nf] = poses[2]
        vels[:nf, 0], vels[:nf, 1] = poses[3], poses[4]
    for k, walker in cache.walkers:
        x, y, yaw = walker.pose()
        vels[k, :2] = walker.velocity()
        centers[k, 0], centers[k, 1] = x, y
        yaws[k] = yaw
    return centers, yaws, vels, cache
