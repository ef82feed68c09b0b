"""Objects: 3D boxes and detected (or ground-truth) objects, and objects as columns.

:meth:`DetectedObject.many` builds N objects from columns.  It checks the columns, keeps them
as one read-only :class:`ObjectColumns` and returns N ``DetectedObject`` instances that hold
only their row of it: each one's fields are filled from its row the first time any of them is
read (the object is then the one ``DetectedObject(...)`` would give, and stays so; the fields
never change).  To every consumer the list is a ``list[DetectedObject]`` as before — ``len``,
iteration, indexing, ``==``, ``repr``, pickling, ``dataclasses.replace`` behave the same, the
containers are plain lists and tuples (mutate, slice or concatenate them freely).  Code that wants
the columns (the noisy oracle, the planner, the results writer) asks
:meth:`ObjectColumns.shared_by` — the columns when every object of a sequence is a row of one
``many`` call (any order, any subset), else None — or :meth:`ObjectColumns.from_objects`, which
gathers them from the objects when they are not; neither reads a field of a row object, so
objects that stay columns from the ground truth to the planner are never built one by one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import repeat
from operator import attrgetter
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from redrive.types._arrays import frozen_vector
from redrive.types.enums import ObjectClass

__all__ = ["Box3D", "DetectedObject", "ObjectColumns"]


@dataclass(frozen=True, slots=True, kw_only=True)
class Box3D:
    """An oriented 3D box.

    Attributes:
        center: (3,) float64, metres, the geometric centre of the box in its frame.
        size: (3,) float64, metres, length (along the heading), width, height; all ≥ 0.
        yaw_rad: heading about +z, radians, counter-clockwise from +x.
    """

    center: npt.NDArray[np.float64]
    size: npt.NDArray[np.float64]
    yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", frozen_vector(self.center, name="Box3D.center", size=3))
        size = frozen_vector(self.size, name="Box3D.size", size=3)
        if np.any(size < 0) or not np.all(np.isfinite(size)):
            msg = f"Box3D.size must be finite and non-negative, got {size.tolist()}"
            raise ValueError(msg)
        object.__setattr__(self, "size", size)
        if not math.isfinite(self.yaw_rad):
            msg = f"Box3D.yaw_rad must be finite, got {self.yaw_rad}"
            raise ValueError(msg)
        object.__setattr__(self, "yaw_rad", float(self.yaw_rad))


def _zeros3() -> npt.NDArray[np.float64]:
    return np.zeros(3, dtype=np.float64)


class _ColumnRow:
    """What a :class:`DetectedObject` made by :meth:`DetectedObject.many` holds until a field
    is read: its columns and its row (two slots besides the dataclass fields; unset on objects
    made any other way)."""

    __slots__ = ("_columns", "_row")

    if not TYPE_CHECKING:  # (mypy would type every unknown attribute as this method's result)

        def __getattr__(self, name: str) -> Any:
            # Python calls this only when the normal lookup failed: for a field, that is an
            # unset slot — the first read of a row object's field
            if name in _FIELD_NAMES:
                try:
                    columns, row = _GET_COLUMNS(self), _GET_ROW(self)
                except AttributeError:
                    pass
                else:
                    _fill(self, columns, row)
                    return _FIELD_GETTERS[name](self)
            msg = f"{type(self).__name__!r} object has no attribute {name!r}"
            raise AttributeError(msg, name=name, obj=self)


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectedObject(_ColumnRow):
    """An object found by perception, or given as ground truth.

    Attributes:
        object_id: track / label id; -1 when none is known.
        object_class: what it is.
        confidence: in [0, 1]; 1.0 for ground truth.
        box: the oriented 3D box (frame: the frame of the message or frame it belongs to).
        velocity, acceleration: (3,) m/s and m/s² in the same frame.
        orientation: (3,) yaw, pitch, roll in radians.
        bbox_2d: optional (x, y, w, h) image box in pixels.
        num_lidar_points: ground truth only: LiDAR returns on the object in this frame (nuScenes'
            ``num_lidar_pts``; evaluation drops objects with none); ``None`` when unknown.
        visible: ground truth only: whether any sensor could see the object (not fully occluded
            or out of range); ``None`` when unknown.
    """

    object_id: int = -1
    object_class: ObjectClass = ObjectClass.UNKNOWN
    confidence: float = 1.0
    box: Box3D
    velocity: npt.NDArray[np.float64] = field(default_factory=_zeros3)
    acceleration: npt.NDArray[np.float64] = field(default_factory=_zeros3)
    orientation: npt.NDArray[np.float64] = field(default_factory=_zeros3)
    bbox_2d: tuple[float, float, float, float] | None = None
    num_lidar_points: int | None = None
    visible: bool | None = None

    def __post_init__(self) -> None:
        if self.num_lidar_points is not None and self.num_lidar_points < 0:
            msg = f"DetectedObject.num_lidar_points must be ≥ 0, got {self.num_lidar_points}"
            raise ValueError(msg)
        if not 0.0 <= self.confidence <= 1.0:
            msg = f"DetectedObject.confidence must lie in [0, 1], got {self.confidence}"
            raise ValueError(msg)
        for name in ("velocity", "acceleration", "orientation"):
            vec = frozen_vector(getattr(self, name), name=f"DetectedObject.{name}", size=3)
            object.__setattr__(self, name, vec)
        if self.bbox_2d is not None:
            if len(self.bbox_2d) != 4:
                msg = f"DetectedObject.bbox_2d must be (x, y, w, h), got {self.bbox_2d!r}"
                raise ValueError(msg)
            object.__setattr__(self, "bbox_2d", tuple(float(v) for v in self.bbox_2d))

    @classmethod
    def many(
        cls,
        *,
        object_classes: Sequence[ObjectClass],
        centers: npt.ArrayLike,
        sizes: npt.ArrayLike,
        yaws_rad: npt.ArrayLike,
        object_ids: Sequence[int] | None = None,
        confidences: npt.ArrayLike | None = None,
        velocities: npt.ArrayLike | None = None,
        accelerations: npt.ArrayLike | None = None,
        orientations: npt.ArrayLike | None = None,
        num_lidar_points: Sequence[int | None] | None = None,
        visible: Sequence[bool | None] | None = None,
    ) -> list[DetectedObject]:
        """N objects from columns: object i has ``object_classes[i]``, ``Box3D(center=centers[i],
        size=sizes[i], yaw_rad=yaws_rad[i])``, ``velocities[i]`` … (a column left out takes the
        field's default for every object).

        For code that makes many objects per frame (decoders, simulators, perception): the
        columns are checked once, with the checks ``DetectedObject(...)`` and ``Box3D(...)`` make
        (ValueError naming the column and the object's index), and the objects are the ones those
        constructors would give — float64, read-only (3,) row views of one frozen copy of each
        column.  They are built lazily: each holds its row of one :class:`ObjectColumns` and
        fills its fields from it when one is first read (see the module docstring), so
        :meth:`ObjectColumns.shared_by` gives the columns back without a pass over the objects.
        """
        return _checked_columns(
            "DetectedObject.many",
            object_classes=object_classes,
            centers=centers,
            sizes=sizes,
            yaws_rad=yaws_rad,
            object_ids=object_ids,
            confidences=confidences,
            velocities=velocities,
            accelerations=accelerations,
            orientations=orientations,
            num_lidar_points=num_lidar_points,
            visible=visible,
        ).objects()


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class ObjectColumns:
    """N objects as columns (row i is object i): what :meth:`DetectedObject.many` keeps.

    Made by :meth:`DetectedObject.many` (then :meth:`shared_by` gives it back), by
    :meth:`from_objects`, or directly with every column (checked as ``many`` checks them; the
    arrays are copied and frozen).  Equality is identity (arrays inside).

    Attributes:
        object_ids: (N,) ints, -1 when none is known.
        object_classes: (N,) :class:`ObjectClass`.
        confidences: (N,) float64 in [0, 1].
        centers: (N, 3) float64, metres, the boxes' centres.
        sizes: (N, 3) float64, metres, length, width, height; finite, ≥ 0.
        yaws_rad: (N,) float64, the boxes' headings, finite.
        velocities, accelerations: (N, 3) float64, m/s and m/s².
        orientations: (N, 3) float64, yaw, pitch, roll in radians.
        bbox_2d: (N,) ``(x, y, w, h)`` pixels or None.
        num_lidar_points: (N,) int ≥ 0 or None.
        visible: (N,) bool or None.
    """

    object_ids: tuple[int, ...]
    object_classes: tuple[ObjectClass, ...]
    confidences: npt.NDArray[np.float64]
    centers: npt.NDArray[np.float64]
    sizes: npt.NDArray[np.float64]
    yaws_rad: npt.NDArray[np.float64]
    velocities: npt.NDArray[np.float64]
    accelerations: npt.NDArray[np.float64]
    orientations: npt.NDArray[np.float64]
    bbox_2d: tuple[tuple[float, float, float, float] | None, ...]
    num_lidar_points: tuple[int | None, ...]
    visible: tuple[bool | None, ...]

    def __post_init__(self) -> None:
        n = len(self.object_classes)
        if len(self.bbox_2d) != n:
            raise ValueError(_length_msg("bbox_2d", len(self.bbox_2d), n, "ObjectColumns"))
        checked = _checked_columns(
            "ObjectColumns",
            object_classes=self.object_classes,
            centers=self.centers,
            sizes=self.sizes,
            yaws_rad=self.yaws_rad,
            object_ids=self.object_ids,
            confidences=self.confidences,
            velocities=self.velocities,
            accelerations=self.accelerations,
            orientations=self.orientations,
            num_lidar_points=self.num_lidar_points,
            visible=self.visible,
        )
        for name in _COLUMN_NAMES:
            if name != "bbox_2d":
                _COLUMN_SETTERS[name](self, getattr(checked, name))
        boxes = tuple(None if b is None else _bbox(b, "ObjectColumns") for b in self.bbox_2d)
        _COLUMN_SETTERS["bbox_2d"](self, boxes)

    def __len__(self) -> int:
        return len(self.object_ids)

    def objects(self) -> list[DetectedObject]:
        """The N objects (each filled from its row when a field is first read)."""
        n = len(self.object_ids)
        objects: list[DetectedObject] = list(map(object.__new__, repeat(DetectedObject, n)))
        any(map(_SET_COLUMNS, objects, repeat(self, n)))
        any(map(_SET_ROW, objects, range(n)))
        return objects

    def take(self, rows: Sequence[int]) -> ObjectColumns:
        """The columns of these rows, in this order."""
        index = np.asarray(rows, dtype=np.intp).reshape(-1)
        picked = index.tolist()
        values: list[Any] = []
        for name in _COLUMN_NAMES:
            column = getattr(self, name)
            if isinstance(column, tuple):
                values.append(tuple([column[i] for i in picked]))
            else:
                taken = column[index]
                taken.flags.writeable = False
                values.append(taken)
        return _columns_unchecked(*values)

    @staticmethod
    def shared_by(objects: Sequence[DetectedObject]) -> ObjectColumns | None:
        """The columns of ``objects`` when every one is a row of the same
        :meth:`DetectedObject.many` call (in any order, any subset; the batch's own columns
        when they are all its rows in order), else None.  Reads no field of the objects."""
        n = len(objects)
        if not n:
            return _EMPTY
        try:
            batches = list(map(_ATTR_COLUMNS, objects))
        except AttributeError:
            return None
        first = batches[0]
        if type(first) is not ObjectColumns or batches.count(first) != n:
            return None
        rows = list(map(_ATTR_ROW, objects))
        if n == len(first.object_ids) and rows == list(range(n)):
            return first
        return first.take(rows)

    @staticmethod
    def from_objects(objects: Sequence[DetectedObject]) -> ObjectColumns:
        """The columns of ``objects``: :meth:`shared_by`'s when it has them, else gathered from
        the objects' fields (the same values)."""
        shared = ObjectColumns.shared_by(objects)
        if shared is not None:
            return shared
        n = len(objects)
        boxes = [o.box for o in objects]

        def rows3(values: list[Any]) -> npt.NDArray[np.float64]:
            arr = np.array(values, dtype=np.float64).reshape(n, 3)
            arr.flags.writeable = False
            return arr

        def rows1(values: list[Any]) -> npt.NDArray[np.float64]:
            arr = np.array(values, dtype=np.float64).reshape(n)
            arr.flags.writeable = False
            return arr

        return _columns_unchecked(
            tuple(o.object_id for o in objects),
            tuple(o.object_class for o in objects),
            rows1([o.confidence for o in objects]),
            rows3([b.center for b in boxes]),
            rows3([b.size for b in boxes]),
            rows1([b.yaw_rad for b in boxes]),
            rows3([o.velocity for o in objects]),
            rows3([o.acceleration for o in objects]),
            rows3([o.orientation for o in objects]),
            tuple(o.bbox_2d for o in objects),
            tuple(o.num_lidar_points for o in objects),
            tuple(o.visible for o in objects),
        )


def _checked_columns(
    where: str,
    *,
    object_classes: Sequence[ObjectClass],
    centers: npt.ArrayLike,
    sizes: npt.ArrayLike,
    yaws_rad: npt.ArrayLike,
    object_ids: Sequence[int] | None,
    confidences: npt.ArrayLike | None,
    velocities: npt.ArrayLike | None,
    accelerations: npt.ArrayLike | None,
    orientations: npt.ArrayLike | None,
    num_lidar_points: Sequence[int | None] | None,
    visible: Sequence[bool | None] | None,
) -> ObjectColumns:
    """The columns checked as ``DetectedObject(...)`` checks one object (ValueError naming
    ``where``, the column and the first bad row), copied and frozen."""
    n = len(object_classes)
    centers_a = _column3(centers, "centers", n, where)
    sizes_a = _column3(sizes, "sizes", n, where)
    # The common case in C-level reductions (no numpy Python wrappers; a few objects' values
    # as Python floats, cheaper than numpy's reductions on tiny arrays); the rows are looked
    # at only when there is a bad value, to name the first.
    if n and not _finite_nonnegative(sizes_a):
        bad = ~np.isfinite(sizes_a).all(axis=1) | (sizes_a < 0).any(axis=1)
        i = int(np.flatnonzero(bad)[0])
        msg = f"{where}: sizes[{i}] must be finite and non-negative, got {sizes_a[i].tolist()}"
        raise ValueError(msg)
    yaws = _column1(yaws_rad, "yaws_rad", n, where)
    if n and not _finite(yaws):
        i = int(np.flatnonzero(~np.isfinite(yaws))[0])
        msg = f"{where}: yaws_rad[{i}] must be finite, got {yaws[i]}"
        raise ValueError(msg)
    ids: tuple[int, ...] = (-1,) * n
    if object_ids is not None:
        if len(object_ids) != n:
            raise ValueError(_length_msg("object_ids", len(object_ids), n, where))
        ids = tuple(map(int, object_ids))
    conf = _ones(n)
    if confidences is not None:
        conf = _column1(confidences, "confidences", n, where)
        if n and not _in_unit(conf):
            bad = ~((conf >= 0.0) & (conf <= 1.0))
            i = int(np.flatnonzero(bad)[0])
            msg = f"{where}: confidences[{i}] must lie in [0, 1], got {conf[i]}"
            raise ValueError(msg)
    points: tuple[int | None, ...] = (None,) * n
    if num_lidar_points is not None:
        if len(num_lidar_points) != n:
            raise ValueError(_length_msg("num_lidar_points", len(num_lidar_points), n, where))
        points = tuple(None if p is None else int(p) for p in num_lidar_points)
        for i, p in enumerate(points):
            if p is not None and p < 0:
                msg = f"{where}: num_lidar_points[{i}] must be ≥ 0, got {p}"
                raise ValueError(msg)
    seen: tuple[bool | None, ...] = (None,) * n
    if visible is not None:
        if len(visible) != n:
            raise ValueError(_length_msg("visible", len(visible), n, where))
        seen = tuple(visible)
    vectors = [
        _zeros(n) if column is None else _column3(column, column_name, n, where)
        for column_name, column in (
            ("velocities", velocities),
            ("accelerations", accelerations),
            ("orientations", orientations),
        )
    ]
    return _columns_unchecked(
        ids,
        tuple(object_classes),
        conf,
        centers_a,
        sizes_a,
        yaws,
        *vectors,
        (None,) * n,
        points,
        seen,
    )


#: up to this many values a check reads them as Python floats; beyond, numpy's reductions
_SMALL = 96


def _finite_nonnegative(values: npt.NDArray[np.float64]) -> bool:
    """Whether every value is finite and ≥ 0 (-0.0 counts)."""
    if values.size <= _SMALL:
        flat = values.ravel().tolist()
        return all(map(math.isfinite, flat)) and min(flat) >= 0.0  # min after: no NaN left
    return bool(_ALL(np.isfinite(values), axis=None) and _MIN(values, axis=None) >= 0.0)


def _finite(values: npt.NDArray[np.float64]) -> bool:
    """Whether every value is finite."""
    if values.size <= _SMALL:
        return all(map(math.isfinite, values.ravel().tolist()))
    return bool(_ALL(np.isfinite(values), axis=None))


def _in_unit(values: npt.NDArray[np.float64]) -> bool:
    """Whether every value lies in [0, 1] (NaN does not)."""
    if values.size <= _SMALL:
        flat = values.tolist()
        return all(0.0 <= v <= 1.0 for v in flat)
    return bool(_MIN(values) >= 0.0 and _MAX(values) <= 1.0)  # NaN fails both


def _columns_unchecked(*values: Any) -> ObjectColumns:
    """An :class:`ObjectColumns` of these columns (in field order) as they are."""
    columns: ObjectColumns = object.__new__(ObjectColumns)
    for setter, value in zip(_COLUMN_SETTER_LIST, values, strict=True):
        setter(columns, value)
    return columns


def _fill(obj: Any, columns: ObjectColumns, row: int) -> None:
    """Set every field of ``obj`` from row ``row`` of ``columns`` (what many's objects hold)."""
    box = object.__new__(Box3D)
    _SET_BOX_CENTER(box, columns.centers[row])
    _SET_BOX_SIZE(box, columns.sizes[row])
    _SET_BOX_YAW(box, float(columns.yaws_rad[row]))
    set_ = _OBJECT_SETTERS
    set_["object_id"](obj, columns.object_ids[row])
    set_["object_class"](obj, columns.object_classes[row])
    set_["confidence"](obj, float(columns.confidences[row]))
    set_["box"](obj, box)
    set_["velocity"](obj, columns.velocities[row])
    set_["acceleration"](obj, columns.accelerations[row])
    set_["orientation"](obj, columns.orientations[row])
    set_["bbox_2d"](obj, columns.bbox_2d[row])
    set_["num_lidar_points"](obj, columns.num_lidar_points[row])
    set_["visible"](obj, columns.visible[row])


def _bbox(value: Any, where: str) -> tuple[float, float, float, float]:
    if len(value) != 4:
        msg = f"{where}: a bbox_2d must be (x, y, w, h), got {value!r}"
        raise ValueError(msg)
    x, y, w, h = (float(v) for v in value)
    return (x, y, w, h)


def _ones(n: int) -> npt.NDArray[np.float64]:
    """A read-only (n,) column of ones (shared: one per n, for the small n)."""
    arr = _ONES.get(n)
    if arr is None:
        arr = np.ones(n, dtype=np.float64)
        arr.flags.writeable = False
        if n <= _SHARED_DEFAULTS_MAX:
            _ONES[n] = arr
    return arr


def _zeros(n: int) -> npt.NDArray[np.float64]:
    """A read-only (n, 3) column of zeros (shared: one per n, for the small n)."""
    arr = _ZEROS.get(n)
    if arr is None:
        arr = np.zeros((n, 3), dtype=np.float64)
        arr.flags.writeable = False
        if n <= _SHARED_DEFAULTS_MAX:
            _ZEROS[n] = arr
    return arr


# the default columns are read-only, so batches of the same size share them
_SHARED_DEFAULTS_MAX = 256
_ONES: dict[int, npt.NDArray[np.float64]] = {}
_ZEROS: dict[int, npt.NDArray[np.float64]] = {}


def _length_msg(name: str, have: int, n: int, where: str) -> str:
    return f"{where}: {name} has {have} values for {n} objects"


def _column3(value: Any, name: str, n: int, where: str) -> npt.NDArray[np.float64]:
    """``value`` as one read-only float64 (n, 3) array (a copy: the caller keeps its own)."""
    arr = np.array(value, dtype=np.float64)
    if arr.shape != (n, 3):
        msg = f"{where}: {name} must have shape ({n}, 3), got {arr.shape}"
        raise ValueError(msg)
    arr.flags.writeable = False
    return arr


def _column1(value: Any, name: str, n: int, where: str) -> npt.NDArray[np.float64]:
    """``value`` as one read-only float64 (n,) array (a copy)."""
    arr = np.array(value, dtype=np.float64)
    if arr.shape != (n,):
        msg = f"{where}: {name} must have shape ({n},), got {arr.shape}"
        raise ValueError(msg)
    arr.flags.writeable = False
    return arr


# The slots' own setters: what ``object.__setattr__`` ends in, without its lookup.
_SET_BOX_CENTER = Box3D.__dict__["center"].__set__
_SET_BOX_SIZE = Box3D.__dict__["size"].__set__
_SET_BOX_YAW = Box3D.__dict__["yaw_rad"].__set__
_OBJECT_SETTERS = {
    name: DetectedObject.__dict__[name].__set__
    for name in (
        "object_id",
        "object_class",
        "confidence",
        "box",
        "velocity",
        "acceleration",
        "orientation",
        "bbox_2d",
        "num_lidar_points",
        "visible",
    )
}
_FIELD_NAMES = frozenset(_OBJECT_SETTERS)
_FIELD_GETTERS = {name: DetectedObject.__dict__[name].__get__ for name in _OBJECT_SETTERS}
_SET_COLUMNS = _ColumnRow.__dict__["_columns"].__set__
_SET_ROW = _ColumnRow.__dict__["_row"].__set__
_GET_COLUMNS = _ColumnRow.__dict__["_columns"].__get__
_GET_ROW = _ColumnRow.__dict__["_row"].__get__
_ATTR_COLUMNS, _ATTR_ROW = attrgetter("_columns"), attrgetter("_row")
_COLUMN_NAMES = tuple(ObjectColumns.__dataclass_fields__)
_COLUMN_SETTERS = {name: ObjectColumns.__dict__[name].__set__ for name in _COLUMN_NAMES}
_COLUMN_SETTER_LIST = tuple(_COLUMN_SETTERS.values())


_ALL, _MIN, _MAX = np.logical_and.reduce, np.minimum.reduce, np.maximum.reduce
_EMPTY = _columns_unchecked(
    (), (), _ones(0), _zeros(0), _zeros(0), np.zeros(0), _zeros(0), _zeros(0), _zeros(0), (), (), ()
)
_EMPTY.yaws_rad.flags.writeable = False
