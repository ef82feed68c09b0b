"""Collisions while a closed loop runs: which objects the driven ego's footprint touches.

The geometry is that of the collision metrics (``redrive.evaluation.closedloop``, nuPlan's
``in_collision``): the ego footprint is the rectangle ``length_m × width_m`` whose centre lies
``length/2 − rear_overhang`` ahead of the rear axle, each object its box's footprint, and touching
counts as a collision (the separating axis test of
:func:`redrive.evaluation._kinematics.rectangles_overlap`).  A frame's ground truth is in the
driven ego's ``base_link``, so the ego rectangle is fixed there.

What a run does on a collision is ``on_collision`` (:data:`ON_COLLISION`): ``continue`` (the
default, as nuPlan: the simulation goes on, the metrics count the collisions) or ``stop`` (the
run ends after the first frame with one, the reason in the run summary).
"""

from __future__ import annotations

from dataclasses import dataclass

from redrive.closedloop._contact_kernels import touching
from redrive.errors import ConfigError
from redrive.sim.ego import EgoGeometry
from redrive.types import Frame, ObjectColumns

__all__ = ["ON_COLLISION", "Contact", "check_on_collision", "contacts"]

#: what a closed loop does when the ego collides (``--on-collision``); the first is the default.
ON_COLLISION = ("continue", "stop")


def check_on_collision(value: str) -> None:
    """Raises ConfigError for a value not in :data:`ON_COLLISION`."""
    if value not in ON_COLLISION:
        msg = f"--on-collision must be one of {', '.join(ON_COLLISION)}, got {value!r}"
        raise ConfigError(msg)


@dataclass(frozen=True, slots=True, kw_only=True)
class Contact:
    """One object the ego's footprint touches in a frame: its id and class (value)."""

    object_id: int
    object_class: str


def contacts(frame: Frame, geometry: EgoGeometry) -> tuple[Contact, ...]:
    """The ground-truth objects of ``frame`` (base_link of the driven ego) that the ego footprint
    of ``geometry`` touches, by object id; () without ground truth."""
    objects = frame.ground_truth
    if not objects:
        return ()
    # the objects' columns (shared with the simulator's DetectedObject.many: no object is
    # filled field by field), the same values as the objects' boxes; the pre-filter and the
    # separating axis test in one compiled call (._contact_kernels.touching)
    columns = ObjectColumns.from_objects(objects)
    rows = touching(
        columns.center_m,
        columns.size_m,
        columns.yaw_rad,
        geometry.center_offset_m,
        geometry.length_m,
        geometry.width_m,
    ).tolist()
    if not rows:
        return ()
    ids = columns.object_id.tolist()
    found = [Contact(object_id=ids[m], object_class=columns.object_class[m].value) for m in rows]
    return tuple(sorted(found, key=lambda c: c.object_id))
