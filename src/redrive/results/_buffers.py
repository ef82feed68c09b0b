"""Records → row buffers → Arrow tables (the write side of the store).

Each table buffers one tuple per row, in its schema's column order, and is turned into columns
only when a flush takes it (``zip(*rows)``, in C): per frame that is one tuple and one append per
row instead of one append per column through a dict of lists.  A planned path is kept as its
waypoint array (and one tuple for the columns its rows share) until the flush, which
concatenates the arrays: no Python row per waypoint.  Likewise a frame's objects (ground truth,
a perception's detections) are kept as their shared columns (:meth:`ObjectColumns.shared_by`),
its ego states and closed-loop record as they are, until the flush builds their columns: per
frame one append each, no Python float per value (the arrays and records are immutable).
"""

from __future__ import annotations

import gc
from collections.abc import Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from redrive.results.records import FrameRecord, ResourceSample
from redrive.results.schema import SCHEMAS
from redrive.types import ControlCommands, DetectedObject, ObjectColumns, PlannedPath, VehicleState

__all__ = ["TableBuffers"]

#: the column order the rows below are built in; checked against the schemas on import
_ORDER: dict[str, tuple[str, ...]] = {
    "steps": (
        "frame_index", "stamp_ns", "algorithm", "stage", "role", "status", "latency_ns",
        "cpu_ns", "n_outputs", "error_type", "error_message", "traceback",
    ),
    "detections": (
        "algorithm", "frame_index", "stamp_ns", "object_id", "object_class", "confidence",
        "x", "y", "z", "length", "width", "height", "yaw_rad", "vx", "vy", "vz", "ax", "ay",
        "az", "bbox_x", "bbox_y", "bbox_w", "bbox_h",
    ),
    "ground_truth": (
        "frame_index", "stamp_ns", "object_id", "object_class", "x", "y", "z", "length",
        "width", "height", "yaw_rad", "vx", "vy", "vz", "ax", "ay", "az", "bbox_x", "bbox_y",
        "bbox_w", "bbox_h", "num_lidar_points", "visible",
    ),
    "ego": (
        "frame_index", "stamp_ns", "frame_id", "x", "y", "z", "vx", "vy", "vz", "ax", "ay",
        "az", "heading_rad", "yaw_rate_rad_s",
    ),
    "paths": (
        "algorithm", "frame_index", "stamp_ns", "frame_id", "waypoint", "x", "y", "z", "t_s",
    ),
    "commands": (
        "algorithm", "frame_index", "stamp_ns", "throttle", "brake", "steering_angle_rad",
    ),
    "closed_loop": (
        "frame_index", "stamp_ns", "source", "algorithm", "reason", "throttle", "brake",
        "steering_angle_rad", "deviation_m", "deviation_yaw_rad", "deviated", "collisions",
        "collision_object_id", "collision_object_class",
    ),
    "traffic_lights": ("frame_index", "stamp_ns", "light_id", "state"),
    "resources": ("t_ns", "label", "pid", "cpu_percent", "rss_bytes"),
    "frames": (
        "frame_index", "stamp_ns", "wall_ns", "late", "n_ground_truth", "missing_inputs",
    ),
}  # fmt: skip
_ORDER["ego_logged"] = _ORDER["ego"]
if {k: tuple(v) for k, v in _ORDER.items()} != {k: tuple(s.names) for k, s in SCHEMAS.items()}:
    msg = "redrive.results._buffers builds rows in an order the table schemas no longer have"
    raise RuntimeError(msg)

_NO_BBOX = (None, None, None, None)
#: the fields of a buffered ``steps`` row: frame_index and stamp_ns are taken from its frame's
_STEP_FIELDS = tuple(SCHEMAS["steps"])[2:]
assert _ORDER["steps"][:2] == _ORDER["frames"][:2] == ("frame_index", "stamp_ns")


class TableBuffers:
    """Row lists per table, filled record by record and emptied by :meth:`take`."""

    def __init__(self) -> None:
        self._rows: dict[str, list[tuple[Any, ...]]] = {}
        self.n_frames = 0
        self.clear()

    def clear(self) -> None:
        self._rows = {name: [] for name in SCHEMAS}
        rows = self._rows
        self._frames = rows["frames"].append
        self._steps = rows["steps"].append  # rows of _STEP_FIELDS: the frame's columns apart
        self._steps_per_frame: list[int] = []
        self._commands = rows["commands"].append
        #: a planned path: (algorithm, frame_index, stamp_ns, frame_id) and its (K, 4) waypoints
        self._path_heads: list[tuple[Any, ...]] = []
        self._path_points: list[np.ndarray] = []
        #: a frame's objects: (head, their shared columns or None, the objects), head the
        #: columns their rows share — (algorithm, frame_index, stamp_ns) of a detection,
        #: (frame_index, stamp_ns) of the ground truth
        self._objects: dict[str, list[tuple[Any, ...]]] = {"detections": [], "ground_truth": []}
        self._detections = self._objects["detections"].append
        self._ground_truth = self._objects["ground_truth"].append
        #: (frame_index, VehicleState) of the ego and ego_logged tables
        self._states: dict[str, list[tuple[int, VehicleState]]] = {"ego": [], "ego_logged": []}
        #: (frame_index, stamp_ns, ClosedLoopRecord) of the closed_loop table
        self._closed_loop: list[tuple[Any, ...]] = []
        self.n_frames = 0

    # -- filling -----------------------------------------------------------------------------

    def add_frame(self, rec: FrameRecord) -> None:
        fi, stamp = rec.frame_index, rec.stamp_ns
        gt = rec.ground_truth
        missing = rec.missing
        self._frames(
            (
                fi,
                stamp,
                rec.wall_ns,
                rec.late,
                None if gt is None else len(gt),
                ",".join(missing) if missing else "",
            )
        )
        steps = rec.steps
        self._steps_per_frame.append(len(steps))
        add_step = self._steps
        for step in steps:
            # the outputs the engine makes, told apart by their type (one test each, no call);
            # anything else (a subclass) by the isinstance tests of _add_output
            out = step.output
            name = step.algorithm
            kind = type(out)
            if kind is tuple:
                n_outputs = len(out)  # type: ignore[arg-type]
                if n_outputs:  # no rows for no objects (and no column building to find that out)
                    self._detections(((name, fi, stamp), ObjectColumns.shared_by(out), out))  # type: ignore[arg-type]
            elif kind is PlannedPath:
                n_outputs = 1
                self._add_path(name, fi, out)  # type: ignore[arg-type]
            elif kind is ControlCommands:
                n_outputs = 1
                self._commands((name, fi, stamp, out.throttle, out.brake, out.steering_angle_rad))  # type: ignore[union-attr]
            else:
                n_outputs = self._add_output(name, fi, stamp, out)
            add_step(
                (
                    name,
                    step.stage,
                    step.role,
                    step.status,
                    step.latency_ns,
                    step.cpu_ns,
                    n_outputs,
                    step.error_type,
                    step.error_message,
                    step.traceback,
                )
            )
        if gt:
            self._ground_truth(((fi, stamp), ObjectColumns.shared_by(gt), gt))
        if rec.traffic_lights:
            self._rows["traffic_lights"].extend(
                [(fi, stamp, light.id, light.state.value) for light in rec.traffic_lights]
            )
        if rec.vehicle_state is not None:
            self._states["ego"].append((fi, rec.vehicle_state))
        if rec.logged_vehicle_state is not None:
            self._states["ego_logged"].append((fi, rec.logged_vehicle_state))
        if rec.closed_loop is not None:
            self._closed_loop.append((fi, stamp, rec.closed_loop))
        self.n_frames += 1

    def _add_path(self, name: str, fi: int, out: PlannedPath) -> None:
        # the waypoints are read-only (PlannedPath's frozen array): kept as they are
        self._path_heads.append((name, fi, out.stamp_ns, out.frame_id))
        self._path_points.append(out.waypoints)

    def _add_output(self, name: str, fi: int, stamp: int, out: object) -> int:
        """The rows of an output that is not exactly a tuple, PlannedPath or ControlCommands
        (a subclass, or None); its ``n_outputs``."""
        if isinstance(out, ControlCommands):
            self._commands((name, fi, stamp, out.throttle, out.brake, out.steering_angle_rad))
            return 1
        if isinstance(out, PlannedPath):
            self._add_path(name, fi, out)
            return 1
        if isinstance(out, tuple):
            if out:
                self._detections(((name, fi, stamp), ObjectColumns.shared_by(out), out))
            return len(out)
        return 0

    def add_resources(self, samples: Sequence[ResourceSample]) -> None:
        add = self._rows["resources"].append
        for s in samples:
            add((int(s.t_ns), s.label, int(s.pid), float(s.cpu_percent), int(s.rss_bytes)))

    # -- emptying ----------------------------------------------------------------------------

    def take(self) -> dict[str, pa.Table]:
        """The buffered rows as one Arrow table per table name that has rows, and ``frames``
        always (empty when no frame is buffered), in :data:`SCHEMAS` order; clears."""
        # the collector paused meanwhile: the rows' transposition allocates an iterator per row
        # and a tuple per column, all alive until the tables are built, so the collections
        # they would set off (walking every buffered row) could free nothing
        paused = gc.isenabled()
        if paused:
            gc.disable()
        try:
            out = self._tables()
        finally:
            if paused:
                gc.enable()
        self.clear()
        return out

    def _deferred_rows(self) -> None:
        """The rows of what :meth:`add_frame` kept as it was: the states' and closed-loop
        records' rows, and the objects' of a table with objects that share no columns (the
        others are built column by column, :func:`_object_arrays`)."""
        for name, states in self._states.items():
            self._rows[name] = [_state_row(fi, vs) for fi, vs in states]
        self._rows["closed_loop"] = [
            (
                fi,
                stamp,
                cl.source,
                cl.algorithm,
                cl.reason,
                cl.throttle,
                cl.brake,
                cl.steering_angle_rad,
                cl.deviation_m,
                cl.deviation_yaw_rad,
                cl.deviated,
                cl.collisions,
                cl.collision_object_id,
                cl.collision_object_class,
            )
            for fi, stamp, cl in self._closed_loop
        ]
        for name, blocks in self._objects.items():
            if any(columns is None for _, columns, _ in blocks):
                gt = name == "ground_truth"
                rows = self._rows[name]
                for head, _, objects in blocks:
                    rows.extend(_object_rows(head, objects, ground_truth=gt))

    def _tables(self) -> dict[str, pa.Table]:
        self._deferred_rows()
        # the frames' columns first: the steps' frame_index and stamp_ns are their frame's,
        # taken from them (a step row does not carry them: one Python int conversion a frame,
        # not one a step)
        frames = self._rows["frames"]
        schema = SCHEMAS["frames"]
        columns = list(zip(*frames, strict=True)) if frames else [() for _ in schema.names]
        frame_arrays = [_array(c, f.type) for c, f in zip(columns, schema, strict=True)]
        out = {}
        for name, schema in SCHEMAS.items():
            rows = self._rows[name]
            if name == "frames":
                arrays = frame_arrays
            elif name == "paths":
                arrays = self._path_arrays()
                if not arrays:
                    continue
            elif name in self._objects and self._objects[name] and not rows:
                arrays = _object_arrays(
                    self._objects[name], schema, ground_truth=name == "ground_truth"
                )
            elif not rows:
                continue
            elif name == "steps":
                of_frame = np.repeat(np.arange(len(frames)), self._steps_per_frame)
                arrays = [
                    frame_arrays[0].take(of_frame),  # frame_index
                    frame_arrays[1].take(of_frame),  # stamp_ns
                    *(
                        _array(c, f.type)
                        for c, f in zip(zip(*rows, strict=True), _STEP_FIELDS, strict=True)
                    ),
                ]
            else:
                # one pa.array per column at its field's type: the same table as
                # Table.from_pydict(..., schema=schema), ≈ 30 % less CPU (no per-column
                # dict and schema matching)
                arrays = [
                    _array(c, f.type) for c, f in zip(zip(*rows, strict=True), schema, strict=True)
                ]
            out[name] = pa.Table.from_arrays(arrays, schema=schema)
        return out

    def _path_arrays(self) -> list[pa.Array]:
        """The ``paths`` columns of the buffered paths (a row per waypoint, path by path);
        none when no path has a waypoint."""
        counts = np.array([len(p) for p in self._path_points], dtype=np.int64)
        total = int(counts.sum())
        if total == 0:  # (also: no path)
            return []
        schema = SCHEMAS["paths"]
        heads = [
            _array(c, f.type)
            for c, f in zip(zip(*self._path_heads, strict=True), list(schema)[:4], strict=True)
        ]  # algorithm, frame_index, stamp_ns, frame_id: one value a path
        of_path = np.repeat(np.arange(len(counts)), counts)
        starts = np.cumsum(counts) - counts
        waypoint = np.arange(total, dtype=np.int64) - np.repeat(starts, counts)
        points = np.concatenate(self._path_points)
        return [
            *(h.take(of_path) for h in heads),
            pa.array(waypoint, type=schema.field("waypoint").type),
            *(
                pa.array(np.ascontiguousarray(points[:, k]), type=f.type)
                for k, f in enumerate(list(schema)[5:])  # x, y, z, t_s
            ),
        ]


_STRING = pa.string()


def _array(values: Sequence[Any], kind: pa.DataType) -> pa.Array:
    """``values`` as an Arrow array of type ``kind``: ``pa.array``, except for a string column
    of one value throughout (a step's status, its empty error columns, an algorithm's name in
    its own table): that value repeated, the same array (the same buffers) ≈ 15× faster."""
    if kind == _STRING and values:
        first = values[0]
        if type(first) is str and values.count(first) == len(values):
            return pa.repeat(pa.scalar(first, type=kind), len(values))
    return pa.array(values, type=kind)


def _state_row(fi: int, vs: VehicleState) -> tuple[Any, ...]:
    """One row of the ``ego`` or ``ego_logged`` table."""
    return (
        fi,
        vs.stamp_ns,
        vs.frame_id,
        *vs.position.tolist(),
        *vs.velocity.tolist(),
        *vs.acceleration.tolist(),
        vs.heading_rad,
        vs.yaw_rate_rad_s,
    )


def _object_rows(
    head: tuple[Any, ...], objects: Sequence[DetectedObject], *, ground_truth: bool
) -> list[tuple[Any, ...]]:
    """The ``detections`` rows (``head`` = algorithm, frame index, stamp; then id, class,
    confidence, x … az, bbox_x … bbox_h) or ``ground_truth`` rows (``head`` = frame index,
    stamp; then id, class, x … bbox_h, num_lidar_points, visible) of ``objects``: from their
    columns when they share them (:meth:`ObjectColumns.shared_by`: no object is built), else
    object by object — the same values either way."""
    columns = ObjectColumns.shared_by(objects)
    if columns is None:
        if ground_truth:
            return [
                (*head, *_object_columns(obj), obj.num_lidar_points, obj.visible) for obj in objects
            ]
        rows = []
        for obj in objects:
            cols = _object_columns(obj)
            rows.append((*head, cols[0], cols[1], obj.confidence, *cols[2:]))
        return rows
    # x, y, z, l, w, h, yaw, vx … az of every object in one C pass: the floats tolist gives
    # the objects' arrays, row by row
    numbers = np.concatenate(
        (
            columns.center_m,
            columns.size_m,
            columns.yaw_rad[:, None],
            columns.velocity_mps,
            columns.acceleration_mps2,
        ),
        axis=1,
    ).tolist()
    classes = [c.value for c in columns.object_class]
    boxes = [_NO_BBOX if b is None else b for b in columns.bbox_2d_px]
    if ground_truth:
        return [
            (*head, i, c, *x, *b, p, v)
            for i, c, x, b, p, v in zip(
                columns.object_id.tolist(),
                classes,
                numbers,
                boxes,
                [None if p < 0 else p for p in columns.num_lidar_points.tolist()],
                columns.visible,
                strict=True,
            )
        ]
    return [
        (*head, i, c, q, *x, *b)
        for i, c, q, x, b in zip(
            columns.object_id.tolist(),
            classes,
            columns.confidence.tolist(),
            numbers,
            boxes,
            strict=True,
        )
    ]


def _object_arrays(
    blocks: list[tuple[Any, ...]], schema: pa.Schema, *, ground_truth: bool
) -> list[pa.Array]:
    """The ``detections`` or ``ground_truth`` columns (``schema``'s) of ``blocks`` — (head,
    shared columns, objects) each, in order — built column by column: the values
    :func:`_object_rows` gives row by row (a null for a negative point count, for no 2D box)."""
    heads = [head for head, _, _ in blocks]
    parts: list[ObjectColumns] = [columns for _, columns, _ in blocks]
    counts = np.array([len(c) for c in parts], dtype=np.int64)
    of_block = pa.array(np.repeat(np.arange(len(parts)), counts))
    fields = list(schema)
    width = len(heads[0])
    head_arrays = [
        _array(c, f.type).take(of_block)
        for c, f in zip(zip(*heads, strict=True), fields[:width], strict=True)
    ]  # one value a block: algorithm, frame_index, stamp_ns
    numbers = np.concatenate(
        [
            np.concatenate(
                (c.center_m, c.size_m, c.yaw_rad[:, None], c.velocity_mps, c.acceleration_mps2),
                axis=1,
            )
            for c in parts
        ]
    )
    ids = pa.array(np.concatenate([c.object_id for c in parts]), type=pa.int64())
    classes = _array([k.value for c in parts for k in c.object_class], _STRING)
    number_arrays = [
        pa.array(np.ascontiguousarray(numbers[:, k]), type=pa.float64()) for k in range(13)
    ]
    boxes = [_NO_BBOX if b is None else b for c in parts for b in c.bbox_2d_px]
    box_arrays = [pa.array(v, type=pa.float64()) for v in zip(*boxes, strict=True)]
    if not ground_truth:
        confidence = pa.array(np.concatenate([c.confidence for c in parts]), type=pa.float64())
        return [*head_arrays, ids, classes, confidence, *number_arrays, *box_arrays]
    points = np.concatenate([c.num_lidar_points for c in parts])
    visible = [v for c in parts for v in c.visible]
    return [
        *head_arrays,
        ids,
        classes,
        *number_arrays,
        *box_arrays,
        pa.array(points, mask=points < 0, type=pa.int64()),
        pa.array(visible, type=pa.bool_()),
    ]


def _object_columns(obj: DetectedObject) -> tuple[Any, ...]:
    """``object_id, object_class, x … az, bbox_x … bbox_h``: the columns a detection and a
    ground-truth row share, in the ground-truth table's order."""
    box = obj.box
    bbox = obj.bbox_2d
    return (
        obj.object_id,
        obj.object_class.value,
        *box.center.tolist(),
        *box.size.tolist(),
        box.yaw_rad,
        *obj.velocity.tolist(),
        *obj.acceleration.tolist(),
        *(_NO_BBOX if bbox is None else bbox),
    )
