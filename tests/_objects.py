"""Objects made two ways, for tests of code that reads shared columns: the same objects as rows
of one ``DetectedObject.many`` batch, and as constructor-made copies that share nothing."""

from __future__ import annotations

from collections.abc import Sequence

from redrive.types import Box3D, DetectedObject


def plain(obj: DetectedObject) -> DetectedObject:
    """The same object made by the constructor (no shared columns)."""
    return DetectedObject(
        object_id=obj.object_id,
        object_class=obj.object_class,
        confidence=obj.confidence,
        box=Box3D(center=obj.box.center, size=obj.box.size, yaw_rad=obj.box.yaw_rad),
        velocity=obj.velocity,
        acceleration=obj.acceleration,
        orientation=obj.orientation,
        bbox_2d=obj.bbox_2d,
        num_lidar_points=obj.num_lidar_points,
        visible=obj.visible,
    )


def one_batch(objects: Sequence[DetectedObject]) -> list[DetectedObject]:
    """The same objects (``bbox_2d`` aside, which ``many`` does not take) as rows of one
    ``DetectedObject.many`` call."""
    return DetectedObject.many(
        object_id=[o.object_id for o in objects],
        object_class=[o.object_class for o in objects],
        confidence=[o.confidence for o in objects],
        center_m=[o.box.center for o in objects],
        size_m=[o.box.size for o in objects],
        yaw_rad=[o.box.yaw_rad for o in objects],
        velocity_mps=[o.velocity for o in objects],
        acceleration_mps2=[o.acceleration for o in objects],
        orientation_rad=[o.orientation for o in objects],
        num_lidar_points=[o.num_lidar_points for o in objects],
        visible=[o.visible for o in objects],
    )
