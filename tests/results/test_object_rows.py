"""The results writer's object rows: from shared columns, the rows object by object gives."""

from __future__ import annotations

import numpy as np

from redrive.results._buffers import _object_rows
from redrive.types import DetectedObject, ObjectClass, ObjectColumns
from tests._objects import plain


def _rows_of_objects(objects: list[DetectedObject], *, ground_truth: bool) -> list[tuple]:  # type: ignore[type-arg]
    """The rows of constructor-made copies (no shared columns: the per-object path)."""
    copies = [plain(o) for o in objects]
    assert ObjectColumns.shared_by(copies) is None
    return _object_rows((3, 42), copies, ground_truth=ground_truth)


def test_rows_from_columns_are_the_rows_object_by_object() -> None:
    rng = np.random.default_rng(0)
    n = 5
    columns = ObjectColumns(
        object_id=np.array([1, -1, 3, 4, 5]),
        object_class=(ObjectClass.VEHICLE,) * 3 + (ObjectClass.PEDESTRIAN,) * 2,
        confidence=rng.uniform(0, 1, n),
        center_m=rng.normal(size=(n, 3)) * 1e3,
        size_m=rng.uniform(0, 5, (n, 3)),
        yaw_rad=rng.uniform(-3, 3, n),
        velocity_mps=rng.normal(size=(n, 3)),
        acceleration_mps2=rng.normal(size=(n, 3)),
        orientation_rad=rng.normal(size=(n, 3)),
        bbox_2d_px=(None, (1.0, 2.0, 30.0, 40.0), None, None, (0.5, 0.5, 1.0, 1.0)),
        num_lidar_points=np.array([-1, 0, 12, -1, 3]),
        visible=(True, False, None, None, True),
        frame_index=np.full(n, -1),
    )
    objects = columns.objects()
    for ground_truth in (True, False):
        shared = _object_rows((3, 42), objects, ground_truth=ground_truth)
        assert shared == _rows_of_objects(objects, ground_truth=ground_truth)
        assert [list(map(type, r)) for r in shared] == [
            list(map(type, r)) for r in _rows_of_objects(objects, ground_truth=ground_truth)
        ]
        # a subset in another order, and none
        part = [objects[4], objects[1]]
        assert _object_rows((3, 42), part, ground_truth=ground_truth) == _rows_of_objects(
            part, ground_truth=ground_truth
        )
        assert _object_rows((3, 42), [], ground_truth=ground_truth) == []
