"""ObjectColumns: DetectedObject.many's objects keep their columns, filled lazily, and behave as
the objects DetectedObject(...) gives to every consumer."""

from __future__ import annotations

import copy
import dataclasses
import pickle

import numpy as np
import pytest

from redrive.types import DetectedObject, ObjectClass, ObjectColumns
from tests._objects import plain

CLASSES = [ObjectClass.VEHICLE, ObjectClass.PEDESTRIAN, ObjectClass.BICYCLE, ObjectClass.TRUCK]


def batch(n: int = 4, seed: int = 1) -> list[DetectedObject]:
    rng = np.random.default_rng(seed)
    return DetectedObject.many(
        object_class=CLASSES[:n],
        center_m=rng.normal(size=(n, 3)),
        size_m=rng.uniform(0.5, 4.0, (n, 3)),
        yaw_rad=rng.uniform(-3, 3, n),
        object_id=list(range(7, 7 + n)),
        confidence=rng.uniform(0, 1, n),
        velocity_mps=rng.normal(size=(n, 3)),
        acceleration_mps2=rng.normal(size=(n, 3)),
        orientation_rad=rng.normal(size=(n, 3)),
        num_lidar_points=[3, None, 0, 9][:n],
        visible=[True, None, False, True][:n],
    )


def assert_columns_equal(a: ObjectColumns, b: ObjectColumns) -> None:
    for f in dataclasses.fields(ObjectColumns):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype, f.name
            assert not x.flags.writeable, f.name
            assert x.tobytes() == y.tobytes(), f.name
        else:
            assert x == y, f.name


def test_many_shares_its_columns_without_building_the_objects() -> None:
    objects = batch()
    columns = ObjectColumns.shared_by(objects)
    assert columns is not None
    assert len(columns) == 4
    assert ObjectColumns.shared_by(tuple(objects)) is columns  # as a Frame or stage holds them
    assert columns.object_id.tolist() == [7, 8, 9, 10]
    assert columns.num_lidar_points.tolist() == [3, -1, 0, 9]
    # nothing was filled: the slots are still unset
    with pytest.raises(AttributeError):
        DetectedObject.__dict__["box"].__get__(objects[0])
    # a field read fills the object from its row; the columns stay shared
    assert objects[1].box.center.tolist() == columns.center_m[1].tolist()
    assert type(objects[1]) is DetectedObject
    assert ObjectColumns.shared_by(objects) is columns
    # gathered from constructor-made objects: the same columns
    assert_columns_equal(ObjectColumns.from_objects([plain(o) for o in objects]), columns)
    assert ObjectColumns.shared_by([plain(o) for o in objects]) is None


def test_subsets_reorderings_and_mutated_lists_give_the_right_rows() -> None:
    objects = batch()
    columns = ObjectColumns.shared_by(objects)
    assert columns is not None
    for picked in ([2, 0], [3, 2, 1, 0], [1], [1, 1, 3]):
        sub = ObjectColumns.shared_by([objects[i] for i in picked])
        assert sub is not None
        assert sub.object_id.tolist() == [columns.object_id[i] for i in picked]
        assert sub.center_m.tolist() == columns.center_m[picked].tolist()
        assert not sub.center_m.flags.writeable
        assert_columns_equal(sub, ObjectColumns.from_objects([plain(objects[i]) for i in picked]))
    mutated = list(objects)
    mutated[0] = objects[3]
    assert ObjectColumns.shared_by(mutated).object_id.tolist() == [10, 8, 9, 10]  # type: ignore[union-attr]
    mutated.append(plain(objects[0]))  # not a row of the batch: no shared columns
    assert ObjectColumns.shared_by(mutated) is None
    assert ObjectColumns.shared_by(objects + batch(2, seed=5)) is None  # two batches
    assert ObjectColumns.shared_by([]) is not None
    assert len(ObjectColumns.from_objects([])) == 0
    # dataclasses.replace gives an ordinary object, not a row
    changed = dataclasses.replace(objects[2], object_id=99)
    assert changed.object_id == 99
    assert ObjectColumns.shared_by([changed]) is None


def test_row_objects_behave_as_constructed_ones() -> None:
    objects = batch()
    made = [plain(o) for o in batch()]  # another batch, filled by reading it
    assert [repr(o) for o in objects] == [repr(o) for o in made]
    assert list(objects) == objects[:]  # equal element by element (each to itself)
    assert not hasattr(objects[0], "nonexistent")
    with pytest.raises(AttributeError, match="'DetectedObject' object has no attribute 'x'"):
        _ = objects[1].x  # type: ignore[attr-defined]
    for copied in (pickle.loads(pickle.dumps(objects)), copy.deepcopy(objects)):
        assert [type(o) for o in copied] == [DetectedObject] * 4
        assert [repr(o) for o in copied] == [repr(o) for o in made]
        assert ObjectColumns.shared_by(copied) is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        objects[0].object_id = 3  # type: ignore[misc]


def test_constructor_checks_and_freezes_the_columns() -> None:
    n = 2
    good: dict[str, object] = {
        "object_id": (1, 2),
        "object_class": (ObjectClass.VEHICLE, ObjectClass.VEHICLE),
        "confidence": np.ones(n),
        "center_m": np.zeros((n, 3)),
        "size_m": np.ones((n, 3)),
        "yaw_rad": np.zeros(n),
        "velocity_mps": np.zeros((n, 3)),
        "acceleration_mps2": np.zeros((n, 3)),
        "orientation_rad": np.zeros((n, 3)),
        "bbox_2d_px": (None, (1, 2, 3, 4)),
        "num_lidar_points": np.array([-1, 4]),
        "frame_index": np.array([-1, -1]),
        "visible": (None, True),
    }
    columns = ObjectColumns(**good)  # type: ignore[arg-type]
    assert columns.center_m is not good["center_m"]
    assert not columns.center_m.flags.writeable
    assert columns.bbox_2d_px == (None, (1.0, 2.0, 3.0, 4.0))
    objects = columns.objects()
    assert objects[1].bbox_2d == (1.0, 2.0, 3.0, 4.0)
    assert ObjectColumns.shared_by(objects) is columns
    for change, words in (
        ({"size_m": np.array([[1, 1, 1], [1, -1, 1.0]])}, "size_m[1] must be finite"),
        ({"confidence": np.array([0.5, 2.0])}, "confidence[1] must lie in [0, 1]"),
        ({"bbox_2d_px": (None,)}, "bbox_2d_px has 1 values for 2 objects"),
        ({"center_m": np.zeros((3, 3))}, "center_m must have shape (2, 3)"),
    ):
        with pytest.raises(ValueError, match=r"^ObjectColumns: ") as err:
            ObjectColumns(**{**good, **change})  # type: ignore[arg-type]
        assert words in str(err.value)


def test_with_trusted_is_replace_without_the_second_check() -> None:
    """with_trusted gives the columns dataclasses.replace gives (the other columns shared, the
    new arrays read-only, not copied), and refuses a name that is no array column."""
    columns = ObjectColumns.from_objects(batch())
    center = np.asarray(columns.center_m) + 1.0
    yaw = np.asarray(columns.yaw_rad) * 0.5
    got = columns.with_trusted(center_m=center, yaw_rad=yaw)
    assert_columns_equal(got, dataclasses.replace(columns, center_m=center, yaw_rad=yaw))
    assert got.center_m is center
    assert not center.flags.writeable
    assert got.velocity_mps is columns.velocity_mps
    assert got.object_class is columns.object_class
    assert_columns_equal(columns, ObjectColumns.from_objects(batch()))  # the original unchanged
    with pytest.raises(ValueError, match="not an array column"):
        columns.with_trusted(object_class=np.zeros(4))
    with pytest.raises(ValueError, match="not an array column"):
        columns.with_trusted(centre_m=center)
