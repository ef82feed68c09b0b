"""A run's stored results → per-frame shapes and transforms (what the scene export draws);
:func:`record_scene` draws the same from one frame the engine just finished (a live run).

Topics (each a :class:`~redrive.interop.shapes.ShapeSet` per frame, stamped with the frame):

================================  =========================================================
``/redrive/ground_truth``         ground-truth boxes (``base_link``), class colours, labels
                                  ``class #id``, velocity arrows
``/redrive/detections/ALG``       every perception algorithm's boxes (``base_link``): labels
                                  ``#id class 0.93`` (a tracker's ids are its track ids),
                                  velocity arrows and a ``v m/s`` label when it moves
``/redrive/paths/ALG``            every planning algorithm's path as a line (its frame)
``/redrive/ego``                  the ego box (the run's driven ego, in its ``map``/``odom``)
``/redrive/ego_logged``           closed loop: the logged ego (the ghost), translucent
``/redrive/bookmarks``            the stored evaluation's bookmarks as labels over the ego,
                                  ``metric/algorithm: detail`` (none before ``redrive
                                  evaluate``)
``/redrive/traffic_lights``       runs whose map has lights: each light at its map position,
                                  coloured by the state the frame records (grey when the log
                                  has no states), with its stop line (:mod:`.light_shapes`)
``/redrive/map``                  runs with a road map: lanes, boundaries, crosswalks, areas,
                                  stop lines, once at the first frame (:mod:`.map_shapes`)
================================  =========================================================

The transforms per frame: the log's static transforms (sensors on ``base_link``) plus the ego's
``frame_id → base_link`` from the run's ``ego`` table, so every box's frame is reachable from
``map``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from redrive.errors import ConfigError
from redrive.geometry.se3 import quaternion_from_yaw
from redrive.interop.light_shapes import LIGHTS_TOPIC, light_shapes
from redrive.interop.map_shapes import MAP_TOPIC, map_shapes
from redrive.interop.shapes import (
    BoxShape,
    Color,
    LabelShape,
    LineShape,
    ShapeSet,
    class_color,
)
from redrive.results import Run
from redrive.results.evaluation import read_evaluation, stored_metric_names
from redrive.results.records import FrameRecord
from redrive.sim.ego import EgoGeometry
from redrive.types import (
    DetectedObject,
    LightState,
    ObjectColumns,
    PlannedPath,
    RoadMap,
    Transform,
    VehicleState,
)

__all__ = [
    "BODY_FRAME",
    "FrameScene",
    "live_topics",
    "log_object_shapes",
    "record_scene",
    "run_scenes",
    "scene_topics",
]

#: the vehicle frame boxes of detections and ground truth are stored in.
BODY_FRAME = "base_link"
_GT_TOPIC = "/redrive/ground_truth"
_EGO_TOPIC = "/redrive/ego"
_GHOST_TOPIC = "/redrive/ego_logged"
_BOOKMARK_TOPIC = "/redrive/bookmarks"
_EGO_COLOR = (0.10, 0.85, 0.30, 0.8)
_GHOST_COLOR = (0.85, 0.85, 0.85, 0.3)
_PATH_COLORS = ((0.2, 1.0, 0.4, 1.0), (1.0, 0.9, 0.2, 1.0), (0.4, 0.9, 1.0, 1.0))
_BOOKMARK_COLOR = (1.0, 0.3, 0.3, 1.0)


@dataclass(frozen=True, slots=True, kw_only=True)
class FrameScene:
    """What the export writes at one frame: its shapes by topic and its transforms."""

    frame_index: int
    stamp_ns: int
    shapes: Mapping[str, ShapeSet] = field(default_factory=dict)
    transforms: tuple[Transform, ...] = ()


def _algorithms(run: Run, role: str) -> list[str]:
    return [a.name for a in run.manifest.algorithms if a.role.value == role]


def scene_topics(run: Run) -> tuple[str, ...]:
    """The SceneUpdate topics :func:`run_scenes` fills for ``run`` (each once, sorted)."""
    topics = {_GT_TOPIC, _EGO_TOPIC, _BOOKMARK_TOPIC}
    topics |= {f"/redrive/detections/{a}" for a in _algorithms(run, "perception")}
    topics |= {f"/redrive/paths/{a}" for a in _algorithms(run, "planning")}
    if "ego_logged" in run.tables():
        topics.add(_GHOST_TOPIC)
    road_map = _road_map(run)
    if road_map is not None:
        topics.add(MAP_TOPIC)
        if road_map.traffic_lights:
            topics.add(LIGHTS_TOPIC)
    return tuple(sorted(topics))


def _road_map(run: Run) -> RoadMap | None:
    """The run's road map, None when it has none."""
    try:
        return run.road_map()
    except ConfigError:
        return None  # a damaged map: the scene goes without it


Row = dict[str, Any]


def _rows_by_frame(table: pa.Table | None, algorithm: str | None = None) -> dict[int, list[Row]]:
    """frame index → the rows of ``table`` (of ``algorithm`` only when given), in order."""
    if table is None:
        return {}
    if algorithm is not None:
        if "algorithm" not in table.column_names:
            return {}
        # the algorithm's rows only, in their order: the others are not turned into dicts
        table = table.filter(pc.equal(table.column("algorithm"), algorithm))
    out: dict[int, list[Row]] = {}
    for row in table.to_pylist():
        out.setdefault(int(row["frame_index"]), []).append(row)
    return out


def _object_shapes(
    rows: Sequence[Row], *, prefix: str, detections: bool
) -> tuple[tuple[BoxShape, ...], tuple[LabelShape, ...]]:
    boxes: list[BoxShape] = []
    labels: list[LabelShape] = []
    for r in rows:
        oid = int(r["object_id"])
        cls = str(r["object_class"])
        center = (float(r["x"]), float(r["y"]), float(r["z"]))
        size = (float(r["length"]), float(r["width"]), float(r["height"]))
        velocity = (float(r["vx"]), float(r["vy"]), float(r["vz"]))
        if not all(math.isfinite(v) for v in velocity):
            velocity = (0.0, 0.0, 0.0)
        boxes.append(
            BoxShape(
                id=f"{prefix}/{oid}",
                center=center,
                size=size,
                yaw_rad=float(r["yaw_rad"]),
                color=class_color(cls),
                velocity=velocity,
            )
        )
        speed = math.hypot(velocity[0], velocity[1])
        text = f"#{oid} {cls} {float(r['confidence']):.2f}" if detections else f"{cls} #{oid}"
        if speed > 0.1:
            text += f"\n{speed:.1f} m/s"
        labels.append(
            LabelShape(
                id=f"{prefix}/{oid}/label",
                position=(center[0], center[1], center[2] + size[2] / 2.0 + 0.6),
                text=text,
                size_m=0.6,
            )
        )
    return tuple(boxes), tuple(labels)


def _object_rows(objects: Sequence[DetectedObject]) -> list[Row]:
    columns = ObjectColumns.from_objects(objects)
    return [
        {
            "object_id": i,
            "object_class": c.value,
            "confidence": q,
            "x": x,
            "y": y,
            "z": z,
            "length": length,
            "width": width,
            "height": height,
            "yaw_rad": yaw,
            "vx": vx,
            "vy": vy,
            "vz": vz,
        }
        for i, c, q, (x, y, z), (length, width, height), yaw, (vx, vy, vz) in zip(
            columns.object_id.tolist(),
            columns.object_class,
            columns.confidence.tolist(),
            columns.center_m.tolist(),
            columns.size_m.tolist(),
            columns.yaw_rad.tolist(),
            columns.velocity_mps.tolist(),
            strict=True,
        )
    ]


def log_object_shapes(
    objects: Sequence[DetectedObject], *, frame_id: str, stamp_ns: int
) -> ShapeSet:
    """A log's objects (ground truth or detections of its own) as boxes with labels."""
    rows = _object_rows(objects)
    boxes, labels = _object_shapes(rows, prefix="object", detections=False)
    return ShapeSet(stamp_ns=stamp_ns, frame_id=frame_id, boxes=boxes, labels=labels)


def _ego_box(row: Row, *, geometry: EgoGeometry, ident: str, color: Color) -> BoxShape:
    yaw = float(row["heading_rad"])
    offset = geometry.center_offset_m
    x = float(row["x"]) + offset * math.cos(yaw)
    y = float(row["y"]) + offset * math.sin(yaw)
    z = float(row["z"]) + geometry.height_m / 2.0
    return BoxShape(
        id=ident,
        center=(x, y, z),
        size=(geometry.length_m, geometry.width_m, geometry.height_m),
        yaw_rad=yaw,
        color=color,
    )


def _ego_transform(row: Row, stamp_ns: int) -> Transform:
    return Transform(
        parent_frame=str(row["frame_id"]) or "map",
        child_frame=BODY_FRAME,
        translation=np.array([row["x"], row["y"], row["z"]], dtype=np.float64),
        rotation=quaternion_from_yaw(float(row["heading_rad"])),
        stamp_ns=stamp_ns,
    )


def _bookmarks(run: Run) -> dict[int, list[str]]:
    if not stored_metric_names(run.path):
        return {}
    try:
        evaluation = read_evaluation(run.path)
    except ConfigError:
        return {}
    out: dict[int, list[str]] = {}
    for b in evaluation.bookmarks.to_pylist():
        who = f"{b['metric']}/{b['algorithm']}" if b["algorithm"] else str(b["metric"])
        out.setdefault(int(b["frame_index"]), []).append(f"{who}: {b['detail']}")
    return out


def run_scenes(
    run: Run,
    *,
    static_transforms: Sequence[Transform] = (),
    geometry: EgoGeometry | None = None,
    ego_transform: bool = True,
) -> Iterator[FrameScene]:
    """One :class:`FrameScene` per processed frame of ``run``, in frame order.

    ``static_transforms``: the log's static transforms (sensors on the vehicle), repeated in
    every frame's transforms so a viewer that starts anywhere finds them.  ``geometry``: the ego
    box (default: the synthetic ego's dimensions, rear-axle reference).  ``ego_transform``: give
    the ego's ``frame_id → base_link`` in each frame's transforms (leave it out when the log's
    own ``/tf`` places ``base_link``, as in an open-loop run: a frame has one parent).
    """
    geometry = geometry or EgoGeometry()
    frames = run.table("frames").select(["frame_index", "stamp_ns"]).to_pylist()
    present = set(run.tables())  # each table is read once (its parts are Parquet files)

    def read(name: str) -> pa.Table | None:
        return run.table(name) if name in present else None

    gt = _rows_by_frame(read("ground_truth"))
    ego = {f: rows[0] for f, rows in _rows_by_frame(read("ego")).items()}
    ghost = {f: rows[0] for f, rows in _rows_by_frame(read("ego_logged")).items()}
    has_ghost = "ego_logged" in present
    found = read("detections")
    detections = {a: _rows_by_frame(found, a) for a in _algorithms(run, "perception")}
    found = read("paths")
    paths = {a: _rows_by_frame(found, a) for a in _algorithms(run, "planning")}
    bookmarks = _bookmarks(run)
    road_map = _road_map(run)
    lights_map = road_map if road_map is not None and road_map.traffic_lights else None
    lights = {
        f: {str(r["light_id"]): LightState(r["state"]) for r in rows}
        for f, rows in _rows_by_frame(read("traffic_lights")).items()
    }
    static = tuple(static_transforms)
    for frame in frames:
        index, stamp = int(frame["frame_index"]), int(frame["stamp_ns"])
        shapes: dict[str, ShapeSet] = {}
        boxes, labels = _object_shapes(gt.get(index, ()), prefix="gt", detections=False)
        shapes[_GT_TOPIC] = ShapeSet(
            stamp_ns=stamp, frame_id=BODY_FRAME, boxes=boxes, labels=labels
        )
        for alg, rows in detections.items():
            boxes, labels = _object_shapes(rows.get(index, ()), prefix=alg, detections=True)
            shapes[f"/redrive/detections/{alg}"] = ShapeSet(
                stamp_ns=stamp, frame_id=BODY_FRAME, boxes=boxes, labels=labels
            )
        for k, (alg, rows) in enumerate(paths.items()):
            waypoints = rows.get(index, [])
            frame_id = str(waypoints[0]["frame_id"]) if waypoints else BODY_FRAME
            lines: tuple[LineShape, ...] = ()
            if len(waypoints) >= 2:
                points = tuple((float(w["x"]), float(w["y"]), float(w["z"])) for w in waypoints)
                color = _PATH_COLORS[k % len(_PATH_COLORS)]
                lines = (LineShape(id=f"{alg}/path", points=points, color=color, width_m=0.25),)
            shapes[f"/redrive/paths/{alg}"] = ShapeSet(
                stamp_ns=stamp, frame_id=frame_id, lines=lines
            )
        transforms = static
        own = ego.get(index)
        if own is not None:
            if ego_transform:
                transforms = (*static, _ego_transform(own, stamp))
            shapes[_EGO_TOPIC] = ShapeSet(
                stamp_ns=stamp,
                frame_id=str(own["frame_id"]) or "map",
                boxes=(_ego_box(own, geometry=geometry, ident="ego", color=_EGO_COLOR),),
            )
        else:
            shapes[_EGO_TOPIC] = ShapeSet(stamp_ns=stamp, frame_id=BODY_FRAME)
        if has_ghost:
            logged = ghost.get(index)
            shapes[_GHOST_TOPIC] = (
                ShapeSet(
                    stamp_ns=stamp,
                    frame_id=str(logged["frame_id"]) or "map",
                    boxes=(
                        _ego_box(logged, geometry=geometry, ident="ego_logged", color=_GHOST_COLOR),
                    ),
                )
                if logged is not None
                else ShapeSet(stamp_ns=stamp, frame_id=BODY_FRAME)
            )
        marks = bookmarks.get(index, [])
        shapes[_BOOKMARK_TOPIC] = ShapeSet(
            stamp_ns=stamp,
            frame_id=BODY_FRAME,
            labels=tuple(
                LabelShape(
                    id=f"bookmark/{i}",
                    position=(0.0, 0.0, geometry.height_m + 1.5 + 0.9 * i),
                    text=text,
                    color=_BOOKMARK_COLOR,
                    size_m=0.9,
                )
                for i, text in enumerate(marks)
            ),
        )
        if lights_map is not None:
            shapes[LIGHTS_TOPIC] = light_shapes(lights_map, lights.get(index, {}), stamp_ns=stamp)
        if road_map is not None:  # once: the map does not change over the run
            shapes[MAP_TOPIC] = map_shapes(road_map, stamp_ns=stamp)
            road_map = None
        yield FrameScene(frame_index=index, stamp_ns=stamp, shapes=shapes, transforms=transforms)


def live_topics(algorithms: Iterable[tuple[str, str]]) -> tuple[str, ...]:
    """The SceneUpdate topics :func:`record_scene` fills for a live run of ``algorithms``
    ((name, role) pairs): ground truth, the ego, each perception algorithm's detections and
    each planner's path (sorted)."""
    topics = {_GT_TOPIC, _EGO_TOPIC}
    for name, role in algorithms:
        if role == "perception":
            topics.add(f"/redrive/detections/{name}")
        elif role == "planning":
            topics.add(f"/redrive/paths/{name}")
    return tuple(sorted(topics))


def _state_row(state: VehicleState) -> Row:
    x, y, z = (float(v) for v in state.position)
    return {"x": x, "y": y, "z": z, "heading_rad": state.heading_rad, "frame_id": state.frame_id}


def _path_line(alg: str, path: PlannedPath, color: Color) -> tuple[LineShape, ...]:
    if len(path.waypoints) < 2:
        return ()
    points = tuple((float(w[0]), float(w[1]), float(w[2])) for w in path.waypoints)
    return (LineShape(id=f"{alg}/path", points=points, color=color, width_m=0.25),)


def record_scene(
    record: FrameRecord,
    *,
    ego_transform: bool = True,
    geometry: EgoGeometry | None = None,
) -> FrameScene:
    """What one finished frame of a live run shows — the shapes :func:`run_scenes` draws for a
    stored frame, from the engine's record: ground truth (when the frame has some), each
    perception algorithm's boxes, each planner's path and the ego box, on the same topics.

    ``ego_transform``: give the ego's ``frame_id → base_link`` as the frame's transform (leave it
    out when the source's own ``/tf`` places ``base_link``: a frame has one parent).
    """
    geometry = geometry or EgoGeometry()
    stamp = record.stamp_ns
    shapes: dict[str, ShapeSet] = {}
    if record.ground_truth is not None:
        boxes, labels = _object_shapes(
            _object_rows(record.ground_truth), prefix="gt", detections=False
        )
        shapes[_GT_TOPIC] = ShapeSet(
            stamp_ns=stamp, frame_id=BODY_FRAME, boxes=boxes, labels=labels
        )
    paths = 0
    for step in record.steps:
        if step.role == "perception":
            objects = step.output if isinstance(step.output, tuple) else ()
            boxes, labels = _object_shapes(
                _object_rows(objects), prefix=step.algorithm, detections=True
            )
            shapes[f"/redrive/detections/{step.algorithm}"] = ShapeSet(
                stamp_ns=stamp, frame_id=BODY_FRAME, boxes=boxes, labels=labels
            )
        elif step.role == "planning":
            color = _PATH_COLORS[paths % len(_PATH_COLORS)]
            paths += 1
            path = step.output if isinstance(step.output, PlannedPath) else None
            shapes[f"/redrive/paths/{step.algorithm}"] = ShapeSet(
                stamp_ns=stamp,
                frame_id=path.frame_id if path is not None else BODY_FRAME,
                lines=() if path is None else _path_line(step.algorithm, path, color),
            )
    transforms: tuple[Transform, ...] = ()
    state = record.vehicle_state
    if state is not None:
        row = _state_row(state)
        if ego_transform:
            transforms = (_ego_transform(row, stamp),)
        shapes[_EGO_TOPIC] = ShapeSet(
            stamp_ns=stamp,
            frame_id=state.frame_id or "map",
            boxes=(_ego_box(row, geometry=geometry, ident="ego", color=_EGO_COLOR),),
        )
    return FrameScene(
        frame_index=record.frame_index, stamp_ns=stamp, shapes=shapes, transforms=transforms
    )
