"""Objects: 3D boxes, detected (or ground-truth) objects, and objects as columns.

:class:`ObjectColumns` is the one columnar objects type: N objects (of one frame, or of many
with :attr:`~ObjectColumns.frame_index`), one read-only array per field, units in the names.
Simulated ground truth, perception, the planner, the results writer and the evaluation all work
on it.

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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from itertools import repeat
from operator import attrgetter
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from redrive.types._arrays import (
    bbox,
    frozen_vector,
    length_msg,
    minus_ones,
    ones,
    zeros,
)
from redrive.types._object_checks import checked_column_values
from redrive.types.enums import ObjectClass

__all__ = ["CLASS_CODES", "Box3D", "DetectedObject", "ObjectColumns"]

#: ObjectClass → small int code (the order of the enum): what :meth:`ObjectColumns.class_code`
#: gives.
CLASS_CODES: Mapping[ObjectClass, int] = MappingProxyType({c: i for i, c in enumerate(ObjectClass)})


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
    def many(cls, **columns: Any) -> list[DetectedObject]:
        """N objects from columns, given as to :meth:`ObjectColumns.of` (``object_class``,
        ``center_m``, ``size_m``, ``yaw_rad``, optional ``object_id``, ``confidence``,
        ``velocity_mps`` …): object i has ``object_class[i]``, ``Box3D(center=center_m[i],
        size=size_m[i], yaw_rad=yaw_rad[i])``, ``velocity_mps[i]`` … (a column left out takes the
        field's default for every object).

        For code that makes many objects per frame (decoders, simulators, perception): the
        columns are checked once, with the checks ``DetectedObject(...)`` and ``Box3D(...)`` make
        (ValueError naming the column and the object's index), and the objects are the ones those
        constructors would give — float64, read-only (3,) row views of one frozen copy of each
        column.  They are built lazily: each holds its row of one :class:`ObjectColumns` and
        fills its fields from it when one is first read (see the module docstring), so
        :meth:`ObjectColumns.shared_by` gives the columns back without a pass over the objects.
        """
        return _checked_columns("DetectedObject.many", **columns).objects()


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class ObjectColumns:
    """N objects as columns, row i is object i (arrays share the first axis, all read-only).

    The one columnar objects type: what :meth:`DetectedObject.many` keeps, a simulator's ground
    truth, the evaluation's boxes.  The frame of the positions is the frame of whatever holds
    the columns (a message's, base_link of a frame, or the map for a simulator's world).
    Made by :meth:`of` (checked, optional columns take their defaults), by
    :meth:`DetectedObject.many` (then :meth:`shared_by` gives it back), by :meth:`from_objects`,
    or directly with every column (checked as ``of`` checks them; the arrays are copied and
    frozen).  Change with :meth:`take` or :func:`dataclasses.replace`.  Equality is identity.

    Attributes:
        object_id: (N,) int64 track / label ids, -1 when none is known.
        object_class: (N,) tuple of :class:`ObjectClass` (:meth:`class_code`: as int codes).
        confidence: (N,) float64 in [0, 1]; 1 for ground truth.
        center_m: (N, 3) float64, metres, the boxes' geometric centres.
        size_m: (N, 3) float64, metres, length (along the heading), width, height; finite, ≥ 0.
        yaw_rad: (N,) float64, the boxes' headings about +z, counter-clockwise from +x; finite.
        velocity_mps: (N, 3) float64, m/s.
        acceleration_mps2: (N, 3) float64, m/s².
        orientation_rad: (N, 3) float64, yaw, pitch, roll.
        bbox_2d_px: (N,) tuple of ``(x, y, w, h)`` image boxes in pixels, or None.
        num_lidar_points: (N,) int64 LiDAR returns on the object (ground truth), -1 when unknown.
        visible: (N,) tuple of bool, or None when unknown (ground truth).
        frame_index: (N,) int64 the frame each row belongs to, when the columns gather the
            objects of several frames (the evaluation's), else -1.
    """

    object_id: npt.NDArray[np.int64]
    object_class: tuple[ObjectClass, ...]
    confidence: npt.NDArray[np.float64]
    center_m: npt.NDArray[np.float64]
    size_m: npt.NDArray[np.float64]
    yaw_rad: npt.NDArray[np.float64]
    velocity_mps: npt.NDArray[np.float64]
    acceleration_mps2: npt.NDArray[np.float64]
    orientation_rad: npt.NDArray[np.float64]
    bbox_2d_px: tuple[tuple[float, float, float, float] | None, ...]
    num_lidar_points: npt.NDArray[np.int64]
    visible: tuple[bool | None, ...]
    frame_index: npt.NDArray[np.int64]

    def __post_init__(self) -> None:
        n = len(self.object_class)
        if len(self.bbox_2d_px) != n:
            raise ValueError(length_msg("bbox_2d_px", len(self.bbox_2d_px), n, "ObjectColumns"))
        checked = _checked_columns(
            "ObjectColumns",
            object_class=self.object_class,
            center_m=self.center_m,
            size_m=self.size_m,
            yaw_rad=self.yaw_rad,
            object_id=self.object_id,
            confidence=self.confidence,
            velocity_mps=self.velocity_mps,
            acceleration_mps2=self.acceleration_mps2,
            orientation_rad=self.orientation_rad,
            num_lidar_points=self.num_lidar_points,
            visible=self.visible,
            frame_index=self.frame_index,
        )
        for name in _COLUMN_NAMES:
            if name != "bbox_2d_px":
                _COLUMN_SETTERS[name](self, getattr(checked, name))
        boxes = tuple(None if b is None else bbox(b, "ObjectColumns") for b in self.bbox_2d_px)
        _COLUMN_SETTERS["bbox_2d_px"](self, boxes)

    @classmethod
    def of(
        cls,
        *,
        object_class: Sequence[ObjectClass],
        center_m: npt.ArrayLike,
        size_m: npt.ArrayLike,
        yaw_rad: npt.ArrayLike,
        object_id: npt.ArrayLike | None = None,
        confidence: npt.ArrayLike | None = None,
        velocity_mps: npt.ArrayLike | None = None,
        acceleration_mps2: npt.ArrayLike | None = None,
        orientation_rad: npt.ArrayLike | None = None,
        num_lidar_points: Sequence[int | None] | npt.NDArray[np.int64] | None = None,
        visible: Sequence[bool | None] | None = None,
        frame_index: npt.ArrayLike | None = None,
    ) -> ObjectColumns:
        """Columns from these values, checked as ``DetectedObject(...)`` checks one object
        (ValueError naming the column and the first bad row), copied and frozen; a column left
        out takes the field's default for every row (``num_lidar_points`` may hold None or -1
        for unknown).  No ``bbox_2d_px``: pass it to the constructor."""
        return _checked_columns(
            "ObjectColumns.of",
            object_class=object_class,
            center_m=center_m,
            size_m=size_m,
            yaw_rad=yaw_rad,
            object_id=object_id,
            confidence=confidence,
            velocity_mps=velocity_mps,
            acceleration_mps2=acceleration_mps2,
            orientation_rad=orientation_rad,
            num_lidar_points=num_lidar_points,
            visible=visible,
            frame_index=frame_index,
        )

    @classmethod
    def trusted(
        cls,
        *,
        object_id: npt.NDArray[np.int64],
        object_class: tuple[ObjectClass, ...],
        center_m: npt.NDArray[np.float64],
        size_m: npt.NDArray[np.float64],
        yaw_rad: npt.NDArray[np.float64],
        velocity_mps: npt.NDArray[np.float64],
        orientation_rad: npt.NDArray[np.float64] | None = None,
        num_lidar_points: npt.NDArray[np.int64] | None = None,
        visible: tuple[bool | None, ...] | None = None,
    ) -> ObjectColumns:
        """Columns of arrays the caller built and vouches for (a simulator's world, or its
        ground truth moved into base_link: int64 and float64 of the shapes above, nothing to
        check), neither checked nor copied, made read-only in place; the other columns (and
        ``orientation_rad``, ``num_lidar_points``, ``visible`` left at None) take their
        defaults."""
        n = len(object_class)
        arrays = [object_id, center_m, size_m, yaw_rad, velocity_mps]
        if orientation_rad is not None:
            arrays.append(orientation_rad)
        if num_lidar_points is not None:
            arrays.append(num_lidar_points)
        for arr in arrays:
            arr.flags.writeable = False
        return _columns_unchecked(
            object_id,
            object_class,
            ones(n),
            center_m,
            size_m,
            yaw_rad,
            velocity_mps,
            zeros(n),
            zeros(n) if orientation_rad is None else orientation_rad,
            (None,) * n,
            minus_ones(n) if num_lidar_points is None else num_lidar_points,
            (None,) * n if visible is None else visible,
            minus_ones(n),
        )

    def with_trusted(self, **arrays: npt.NDArray[Any]) -> ObjectColumns:
        """These columns with some of the array columns replaced (by name) by arrays the
        caller made and vouches for — of the replaced column's dtype and shape, finite where
        the checks ask it (a rigid motion of these columns' poses) — neither checked nor copied,
        made read-only in place: :func:`dataclasses.replace` without the second check.

        Raises:
            ValueError: a name that is no array column of the columns.
        """
        values = [getattr(self, name) for name in _COLUMN_NAMES]
        for name, arr in arrays.items():
            at = _ARRAY_COLUMN_AT.get(name)
            if at is None:
                msg = f"ObjectColumns.with_trusted: {name!r} is not an array column"
                raise ValueError(msg)
            arr.flags.writeable = False
            values[at] = arr
        return _columns_unchecked(*values)

    def __len__(self) -> int:
        return len(self.object_class)

    def class_code(self) -> npt.NDArray[np.int64]:
        """(N,) int64 :data:`CLASS_CODES` of the rows' classes."""
        return np.array([CLASS_CODES[c] for c in self.object_class], dtype=np.int64)

    @property
    def distance_xy_m(self) -> npt.NDArray[np.float64]:
        """(N,) distance of each centre from the frame's origin in the x-y plane, metres (in
        base_link: nuScenes' ``ego_dist``)."""
        return np.asarray(np.hypot(self.center_m[:, 0], self.center_m[:, 1]), dtype=np.float64)

    def objects(self) -> list[DetectedObject]:
        """The N objects (each filled from its row when a field is first read)."""
        n = len(self.object_class)
        objects: list[DetectedObject] = list(map(object.__new__, repeat(DetectedObject, n)))
        any(map(_SET_COLUMNS, objects, repeat(self, n)))
        any(map(_SET_ROW, objects, range(n)))
        return objects

    def take(
        self, rows: Sequence[int] | npt.NDArray[np.intp | np.int64 | np.bool_]
    ) -> ObjectColumns:
        """The columns of these rows, in this order (an index sequence or a boolean mask)."""
        index = np.asarray(rows)
        index = (
            np.flatnonzero(index) if index.dtype == np.bool_ else index.astype(np.intp).reshape(-1)
        )
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
        when they are all its rows in order), else None.  Reads no field of the objects.  The
        answers for the last two tuples asked about are kept (a frame's objects are asked about
        by several readers: the perception, the planner, the collision check, the results)."""
        recent = _RECENT_SHARED[0]
        for seen, columns in recent:
            if seen is objects:
                return columns
        columns = _shared_by(objects)
        if type(objects) is tuple:  # (immutable: the same tuple, the same rows)
            _RECENT_SHARED[0] = ((objects, columns), recent[0])
        return columns

    @staticmethod
    def from_objects(
        objects: Sequence[DetectedObject], *, frame_index: npt.ArrayLike | None = None
    ) -> ObjectColumns:
        """The columns of ``objects``: :meth:`shared_by`'s when it has them, else gathered from
        the objects' fields (the same values); with ``frame_index`` (N,) that column set."""
        columns = ObjectColumns.shared_by(objects)
        if columns is None:
            columns = _gathered(objects)
        if frame_index is None:
            return columns
        frames = np.array(frame_index, dtype=np.int64).reshape(len(columns))
        frames.flags.writeable = False
        values = [
            frames if name == "frame_index" else getattr(columns, name) for name in _COLUMN_NAMES
        ]
        return _columns_unchecked(*values)


def _shared_by(objects: Sequence[DetectedObject]) -> ObjectColumns | None:
    """:meth:`ObjectColumns.shared_by`, asked."""
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
    if n == len(first.object_class) and rows == list(range(n)):
        return first
    return first.take(rows)


def _gathered(objects: Sequence[DetectedObject]) -> ObjectColumns:
    """The columns of ``objects`` read from their fields."""
    n = len(objects)
    boxes = [o.box for o in objects]

    def rows3(values: list[Any]) -> npt.NDArray[np.float64]:
        arr = np.array(values, dtype=np.float64).reshape(n, 3)
        arr.flags.writeable = False
        return arr

    def rows1(values: list[Any], dtype: type[Any] = np.float64) -> npt.NDArray[Any]:
        arr = np.array(values, dtype=dtype).reshape(n)
        arr.flags.writeable = False
        return arr

    return _columns_unchecked(
        rows1([o.object_id for o in objects], np.int64),
        tuple(o.object_class for o in objects),
        rows1([o.confidence for o in objects]),
        rows3([b.center for b in boxes]),
        rows3([b.size for b in boxes]),
        rows1([b.yaw_rad for b in boxes]),
        rows3([o.velocity for o in objects]),
        rows3([o.acceleration for o in objects]),
        rows3([o.orientation for o in objects]),
        tuple(o.bbox_2d for o in objects),
        rows1([-1 if p is None else p for p in (o.num_lidar_points for o in objects)], np.int64),
        tuple(o.visible for o in objects),
        minus_ones(n),
    )


def _checked_columns(where: str, **columns: Any) -> ObjectColumns:
    """The columns checked as ``DetectedObject(...)`` checks one object (ValueError naming
    ``where``, the column and the first bad row), copied and frozen."""
    return _columns_unchecked(*checked_column_values(where, **columns))


def _columns_unchecked(*values: Any) -> ObjectColumns:
    """An :class:`ObjectColumns` of these columns (in field order) as they are."""
    columns: ObjectColumns = object.__new__(ObjectColumns)
    for setter, value in zip(_COLUMN_SETTER_LIST, values, strict=True):
        setter(columns, value)
    return columns


def _fill(obj: Any, columns: ObjectColumns, row: int) -> None:
    """Set every field of ``obj`` from row ``row`` of ``columns`` (what many's objects hold)."""
    box = object.__new__(Box3D)
    _SET_BOX_CENTER(box, columns.center_m[row])
    _SET_BOX_SIZE(box, columns.size_m[row])
    _SET_BOX_YAW(box, float(columns.yaw_rad[row]))
    points = int(columns.num_lidar_points[row])
    set_ = _OBJECT_SETTERS
    set_["object_id"](obj, int(columns.object_id[row]))
    set_["object_class"](obj, columns.object_class[row])
    set_["confidence"](obj, float(columns.confidence[row]))
    set_["box"](obj, box)
    set_["velocity"](obj, columns.velocity_mps[row])
    set_["acceleration"](obj, columns.acceleration_mps2[row])
    set_["orientation"](obj, columns.orientation_rad[row])
    set_["bbox_2d"](obj, columns.bbox_2d_px[row])
    set_["num_lidar_points"](obj, None if points < 0 else points)
    set_["visible"](obj, columns.visible[row])


# The slots' own setters: what ``object.__setattr__`` ends in, without its lookup.
_SET_BOX_CENTER = Box3D.__dict__["center"].__set__
_SET_BOX_SIZE = Box3D.__dict__["size"].__set__
_SET_BOX_YAW = Box3D.__dict__["yaw_rad"].__set__
_OBJECT_SETTERS = {
    name: DetectedObject.__dict__[name].__set__
    for name in DetectedObject.__dataclass_fields__  # object_id … visible, in order
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
#: the array columns' positions in field order (ObjectColumns.with_trusted)
_ARRAY_COLUMN_AT = {
    name: k
    for k, name in enumerate(_COLUMN_NAMES)
    if name not in ("object_class", "bbox_2d_px", "visible")
}
#: ObjectColumns.shared_by's last two (objects, answer): the newest first
_RECENT_SHARED: list[tuple[tuple[Any, ObjectColumns | None], ...]] = [((None, None), (None, None))]


_EMPTY = _columns_unchecked(
    minus_ones(0), (), ones(0), zeros(0), zeros(0), ones(0)[:0], zeros(0), zeros(0), zeros(0), (),
    minus_ones(0), (), minus_ones(0),
)  # fmt: skip
