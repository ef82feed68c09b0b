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
        object_ids=(1, -1, 3, 4, 5),
        object_classes=(ObjectClass.VEHICLE,) * 3 + (ObjectClass.PEDESTRIAN,) * 2,
        confidences=rng.uniform(0, 1, n),
        centers=rng.normal(size=(n, 3)) * 1e3,
        sizes=rng.uniform(0, 5, (n, 3)),
        yaws_rad=rng.uniform(-3, 3, n),
        velocities=rng.normal(size=(n, 3)),
        accelerations=rng.normal(size=(n, 3)),
        orientations=rng.normal(size=(n, 3)),
        bbox_2d=(None, (1.0, 2.0, 30.0, 40.0), None, None, (0.5, 0.5, 1.0, 1.0)),
        num_lidar_points=(None, 0, 12, None, 3),
        visible=(True, False, None, None, True),
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
