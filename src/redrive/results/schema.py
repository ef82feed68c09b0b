"""The fixed Arrow schemas of a run's tables (one Parquet part per table per flush).

Every column has a fixed type whatever the data: time is int64 ns, values are float64, names are
strings, so an empty part has the same schema as a full one and parts concatenate.  Columns that
may be missing are nullable and documented as such; see ``docs/results.md``.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import pyarrow as pa

__all__ = [
    "CLOSED_LOOP",
    "COMMANDS",
    "DETECTIONS",
    "EGO",
    "EGO_LOGGED",
    "FRAMES",
    "GROUND_TRUTH",
    "PATHS",
    "RESOURCES",
    "SCHEMAS",
    "SORT_KEYS",
    "STEPS",
    "SUMMARY",
    "TABLES",
    "TRAFFIC_LIGHTS",
]


def _f(name: str, type_: pa.DataType, *, nullable: bool = False) -> pa.Field:
    return pa.field(name, type_, nullable=nullable)


_I64 = pa.int64()
_F64 = pa.float64()
_STR = pa.string()


def _floats(*names: str, nullable: bool = False) -> list[pa.Field]:
    return [_f(n, _F64, nullable=nullable) for n in names]


_BOX = _floats("x", "y", "z", "length", "width", "height", "yaw_rad")
_MOTION = _floats("vx", "vy", "vz", "ax", "ay", "az")
_BBOX = _floats("bbox_x", "bbox_y", "bbox_w", "bbox_h", nullable=True)

#: one row per frame processed; its parts are the commit marker of a flush.
FRAMES = pa.schema(
    [
        _f("frame_index", _I64),
        _f("stamp_ns", _I64),
        _f("wall_ns", _I64),
        _f("late", pa.bool_()),
        _f("n_ground_truth", _I64, nullable=True),
        # inputs with no sample within the tolerance, comma-separated ("" none; null in runs
        # written before the column)
        _f("missing_inputs", _STR, nullable=True),
    ]
)

#: one row per algorithm per frame.
STEPS = pa.schema(
    [
        _f("frame_index", _I64),
        _f("stamp_ns", _I64),
        _f("algorithm", _STR),
        _f("stage", _STR),
        _f("role", _STR),
        _f("status", _STR),
        _f("latency_ns", _I64),
        _f("cpu_ns", _I64),
        _f("n_outputs", _I64),
        _f("error_type", _STR),
        _f("error_message", _STR),
        _f("traceback", _STR),
    ]
)

#: one row per object a perception algorithm returned.
DETECTIONS = pa.schema(
    [
        _f("algorithm", _STR),
        _f("frame_index", _I64),
        _f("stamp_ns", _I64),
        _f("object_id", _I64),
        _f("object_class", _STR),
        _f("confidence", _F64),
        *_BOX,
        *_MOTION,
        *_BBOX,
    ]
)

#: one row per ground-truth object of a frame.
GROUND_TRUTH = pa.schema(
    [
        _f("frame_index", _I64),
        _f("stamp_ns", _I64),
        _f("object_id", _I64),
        _f("object_class", _STR),
        *_BOX,
        *_MOTION,
        *_BBOX,
        _f("num_lidar_points", _I64, nullable=True),
        _f("visible", pa.bool_(), nullable=True),
    ]
)

#: one row per frame with an ego state.
EGO = pa.schema(
    [
        _f("frame_index", _I64),
        _f("stamp_ns", _I64),
        _f("frame_id", _STR),
        *_floats("x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az"),
        _f("heading_rad", _F64),
        _f("yaw_rate_rad_s", _F64),
    ]
)

#: one row per frame with a logged ego state besides the driven one (closed loop: the expert
#: route); same columns as ``ego``.  Optional: runs written before it existed have no parts.
EGO_LOGGED = EGO

#: one row per waypoint of a planned path.
PATHS = pa.schema(
    [
        _f("algorithm", _STR),
        _f("frame_index", _I64),
        _f("stamp_ns", _I64),
        _f("frame_id", _STR),
        _f("waypoint", _I64),
        *_floats("x", "y", "z", "t_s"),
    ]
)

#: one row per control command.
COMMANDS = pa.schema(
    [
        _f("algorithm", _STR),
        _f("frame_index", _I64),
        _f("stamp_ns", _I64),
        *_floats("throttle", "brake", "steering_angle_rad"),
    ]
)

#: one row per resource sample of a process.
RESOURCES = pa.schema(
    [
        _f("t_ns", _I64),
        _f("label", _STR),
        _f("pid", _I64),
        _f("cpu_percent", _F64),
        _f("rss_bytes", _I64),
    ]
)

#: closed loop: one row per frame, what moved the ego after it (``ClosedLoopRecord``).
CLOSED_LOOP = pa.schema(
    [
        _f("frame_index", _I64),
        _f("stamp_ns", _I64),
        _f("source", _STR),
        _f("algorithm", _STR),
        _f("reason", _STR),
        *_floats("throttle", "brake", "steering_angle_rad", "deviation_m", "deviation_yaw_rad"),
        # null: no logged ego to compare with (and runs written before the column existed)
        _f("deviated", pa.bool_(), nullable=True),
    ]
)

#: one row per traffic light per frame with light states (``Frame.traffic``): ``light_id`` is
#: ``TrafficLight.id`` (the road map's ``MapTrafficLight.light_id``), ``state`` the
#: ``LightState`` value (``red``, ``yellow``, ``green``, ``unknown``).  Optional: runs of logs
#: without lights (and runs written before it existed) have no parts.
TRAFFIC_LIGHTS = pa.schema(
    [
        _f("frame_index", _I64),
        _f("stamp_ns", _I64),
        _f("light_id", _STR),
        _f("state", _STR),
    ]
)

#: the per-algorithm summary of :meth:`redrive.results.Run.summary` (not stored; computed).
SUMMARY = pa.schema(
    [
        _f("algorithm", _STR),
        _f("stage", _STR),
        _f("role", _STR),
        _f("frames", _I64),
        _f("ok", _I64),
        _f("error", _I64),
        _f("timeout", _I64),
        _f("skipped", _I64),
        _f("outputs", _I64),
        *_floats(
            "latency_mean_ms",
            "latency_p50_ms",
            "latency_p95_ms",
            "latency_max_ms",
            "cpu_mean_ms",
            nullable=True,
        ),
    ]
)

#: table name → schema, in the order tables are written (``frames`` last: it commits a flush).
SCHEMAS: Mapping[str, pa.Schema] = MappingProxyType(
    {
        "steps": STEPS,
        "detections": DETECTIONS,
        "ground_truth": GROUND_TRUTH,
        "ego": EGO,
        "ego_logged": EGO_LOGGED,
        "paths": PATHS,
        "commands": COMMANDS,
        "closed_loop": CLOSED_LOOP,
        "traffic_lights": TRAFFIC_LIGHTS,
        "resources": RESOURCES,
        "frames": FRAMES,
    }
)

#: the table names, ``frames`` first (the order of documentation and exports).
TABLES: tuple[str, ...] = ("frames", *(name for name in SCHEMAS if name != "frames"))

#: the columns :meth:`redrive.results.Run.table` sorts by (a stable sort: rows of equal keys,
#: such as the objects of one frame or the waypoints of one path, keep their written order).
SORT_KEYS: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {
        name: ("t_ns",)
        if name == "resources"
        else (("frame_index", "algorithm") if "algorithm" in schema.names else ("frame_index",))
        for name, schema in SCHEMAS.items()
    }
)
