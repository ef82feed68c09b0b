"""DetectedObject.many: the objects DetectedObject(...) would make, from columns checked once."""

from __future__ import annotations

import numpy as np
import pytest

from redrive.types import Box3D, DetectedObject, ObjectClass


def _fields_equal(a: DetectedObject, b: DetectedObject) -> None:
    assert type(a) is type(b) is DetectedObject
    for name in (
        "object_id",
        "object_class",
        "confidence",
        "bbox_2d",
        "num_lidar_points",
        "visible",
    ):
        assert getattr(a, name) == getattr(b, name), name
        assert type(getattr(a, name)) is type(getattr(b, name)), name
    for name in ("velocity", "acceleration", "orientation"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype == np.float64
        assert x.shape == y.shape == (3,)
        assert not x.flags.writeable
        assert not y.flags.writeable
        assert np.array_equal(x, y), name
    assert type(a.box.yaw_rad) is type(b.box.yaw_rad) is float
    assert a.box.yaw_rad == b.box.yaw_rad
    for name in ("center", "size"):
        x, y = getattr(a.box, name), getattr(b.box, name)
        assert x.dtype == y.dtype == np.float64
        assert not x.flags.writeable
        assert np.array_equal(x, y), name


def test_many_gives_the_objects_the_constructor_gives() -> None:
    rng = np.random.default_rng(3)
    n = 7
    classes = [ObjectClass.VEHICLE, ObjectClass.PEDESTRIAN, ObjectClass.BICYCLE] * 3
    columns = {
        "center_m": rng.normal(size=(n, 3)),
        "size_m": rng.uniform(0.5, 4.0, size=(n, 3)),
        "yaws": rng.uniform(-3, 3, size=n),
        "velocity_mps": rng.normal(size=(n, 3)),
        "orientation_rad": rng.normal(size=(n, 3)),
        "confidence": rng.uniform(0, 1, size=n),
    }
    ids = list(range(10, 10 + n))
    points = [3, None, 0, 12, None, 1, 5]
    visible = [True, None, False, True, None, True, True]
    many = DetectedObject.many(
        object_class=classes[:n],
        center_m=columns["center_m"],
        size_m=columns["size_m"],
        yaw_rad=columns["yaws"],
        object_id=ids,
        confidence=columns["confidence"],
        velocity_mps=columns["velocity_mps"],
        orientation_rad=columns["orientation_rad"],
        num_lidar_points=points,
        visible=visible,
    )
    one_by_one = [
        DetectedObject(
            object_id=ids[i],
            object_class=classes[i],
            confidence=float(columns["confidence"][i]),
            box=Box3D(
                center=columns["center_m"][i],
                size=columns["size_m"][i],
                yaw_rad=float(columns["yaws"][i]),
            ),
            velocity=columns["velocity_mps"][i],
            orientation=columns["orientation_rad"][i],
            num_lidar_points=points[i],
            visible=visible[i],
        )
        for i in range(n)
    ]
    assert len(many) == n
    for a, b in zip(many, one_by_one, strict=True):
        _fields_equal(a, b)
    # the caller's arrays are copied, not frozen or kept
    columns["center_m"][0, 0] = 99.0
    assert many[0].box.center[0] != 99.0
    assert columns["center_m"].flags.writeable


def test_many_defaults_and_empty() -> None:
    (obj,) = DetectedObject.many(
        object_class=[ObjectClass.VEHICLE], center_m=[[1, 2, 3]], size_m=[[4, 2, 1.5]], yaw_rad=[0]
    )
    _fields_equal(
        obj,
        DetectedObject(
            object_class=ObjectClass.VEHICLE,
            box=Box3D(center=np.array([1.0, 2, 3]), size=np.array([4.0, 2, 1.5])),
        ),
    )
    assert (
        DetectedObject.many(
            object_class=[], center_m=np.zeros((0, 3)), size_m=np.zeros((0, 3)), yaw_rad=[]
        )
        == []
    )


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"size_m": [[1, 1, 1], [1, -1, 1]]}, "size_m[1] must be finite and non-negative"),
        ({"size_m": [[1, 1, 1], [1, np.nan, 1]]}, "size_m[1] must be finite"),
        ({"yaw_rad": [0.0, np.inf]}, "yaw_rad[1] must be finite"),
        ({"confidence": [0.5, 1.5]}, "confidence[1] must lie in [0, 1]"),
        ({"num_lidar_points": [None, -2]}, "num_lidar_points[1] must be ≥ 0"),
        ({"center_m": [[0, 0, 0]]}, "center_m must have shape (2, 3)"),
        ({"object_id": [1]}, "object_id has 1 values for 2 objects"),
        ({"velocity_mps": np.zeros((2, 2))}, "velocity_mps must have shape (2, 3)"),
    ],
)
def test_many_refuses_what_the_constructor_refuses(change: dict[str, object], words: str) -> None:
    kwargs: dict[str, object] = {
        "object_class": [ObjectClass.VEHICLE, ObjectClass.VEHICLE],
        "center_m": np.zeros((2, 3)),
        "size_m": np.ones((2, 3)),
        "yaw_rad": [0.0, 0.0],
    }
    kwargs.update(change)
    with pytest.raises(ValueError, match=r"DetectedObject\.many") as err:
        DetectedObject.many(**kwargs)  # type: ignore[arg-type]
    assert words in str(err.value)


def test_many_accepts_finite_values_whose_sum_overflows() -> None:
    (obj,) = DetectedObject.many(
        object_class=[ObjectClass.VEHICLE],
        center_m=[[0.0, 0.0, 0.0]],
        size_m=[[1e308, 1e308, 1e308]],
        yaw_rad=[0.0],
    )
    assert obj.box.size.tolist() == [1e308, 1e308, 1e308]
