"""The Waymo Open Motion ``Scenario`` protobuf schema, built from its documented field numbers.

No generated code and no ``protoc``: the messages of ``waymo-research/waymo-open-dataset``'s
``src/waymo_open_dataset/protos/scenario.proto`` and ``map.proto`` (package
``waymo.open_dataset``, proto2) are declared here as descriptors (``descriptor_pb2``) and turned
into message classes by the ``protobuf`` runtime (``message_factory.GetMessageClass``).  Fields
redrive does not read (``compressed_frame_laser_data`` = 12, ``frame_camera_tokens`` = 13 of
``Scenario``) are left out: the runtime skips unknown fields.
"""

from __future__ import annotations

import functools
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

__all__ = ["LANE_STATE_NAMES", "OBJECT_TYPE_NAMES", "scenario_class"]

_PACKAGE = "waymo.open_dataset"
_F = descriptor_pb2.FieldDescriptorProto
_OPT, _REP = _F.LABEL_OPTIONAL, _F.LABEL_REPEATED
_SCALARS = {
    "double": _F.TYPE_DOUBLE,
    "float": _F.TYPE_FLOAT,
    "int32": _F.TYPE_INT32,
    "int64": _F.TYPE_INT64,
    "bool": _F.TYPE_BOOL,
    "string": _F.TYPE_STRING,
}

#: Track.ObjectType values
OBJECT_TYPE_NAMES = ("TYPE_UNSET", "TYPE_VEHICLE", "TYPE_PEDESTRIAN", "TYPE_CYCLIST", "TYPE_OTHER")
#: TrafficSignalLaneState.State values
LANE_STATE_NAMES = (
    "LANE_STATE_UNKNOWN",
    "LANE_STATE_ARROW_STOP",
    "LANE_STATE_ARROW_CAUTION",
    "LANE_STATE_ARROW_GO",
    "LANE_STATE_STOP",
    "LANE_STATE_CAUTION",
    "LANE_STATE_GO",
    "LANE_STATE_FLASHING_STOP",
    "LANE_STATE_FLASHING_CAUTION",
)
_ROAD_LINE_TYPES = (
    "TYPE_UNKNOWN",
    "TYPE_BROKEN_SINGLE_WHITE",
    "TYPE_SOLID_SINGLE_WHITE",
    "TYPE_SOLID_DOUBLE_WHITE",
    "TYPE_BROKEN_SINGLE_YELLOW",
    "TYPE_BROKEN_DOUBLE_YELLOW",
    "TYPE_SOLID_SINGLE_YELLOW",
    "TYPE_SOLID_DOUBLE_YELLOW",
    "TYPE_PASSING_DOUBLE_YELLOW",
)

# message → fields (name, number, label, type: a scalar name, "enum:Full.Name" or a message
# name relative to the package), and its nested enums (name → value names in number order)
_MESSAGES: dict[str, tuple[list[tuple[str, int, int, str]], dict[str, tuple[str, ...]]]] = {
    "MapPoint": (
        [("x", 1, _OPT, "double"), ("y", 2, _OPT, "double"), ("z", 3, _OPT, "double")],
        {},
    ),
    "TrafficSignalLaneState": (
        [
            ("lane", 1, _OPT, "int64"),
            ("state", 2, _OPT, "enum:TrafficSignalLaneState.State"),
            ("stop_point", 3, _OPT, "MapPoint"),
        ],
        {"State": LANE_STATE_NAMES},
    ),
    "RoadLine": (
        [("type", 1, _OPT, "enum:RoadLine.RoadLineType"), ("polyline", 2, _REP, "MapPoint")],
        {"RoadLineType": _ROAD_LINE_TYPES},
    ),
    "RoadEdge": (
        [("type", 1, _OPT, "enum:RoadEdge.RoadEdgeType"), ("polyline", 2, _REP, "MapPoint")],
        {"RoadEdgeType": ("TYPE_UNKNOWN", "TYPE_ROAD_EDGE_BOUNDARY", "TYPE_ROAD_EDGE_MEDIAN")},
    ),
    "BoundarySegment": (
        [
            ("lane_start_index", 1, _OPT, "int32"),
            ("lane_end_index", 2, _OPT, "int32"),
            ("boundary_feature_id", 3, _OPT, "int64"),
            ("boundary_type", 4, _OPT, "enum:RoadLine.RoadLineType"),
        ],
        {},
    ),
    "LaneNeighbor": (
        [
            ("feature_id", 1, _OPT, "int64"),
            ("self_start_index", 2, _OPT, "int32"),
            ("self_end_index", 3, _OPT, "int32"),
            ("neighbor_start_index", 4, _OPT, "int32"),
            ("neighbor_end_index", 5, _OPT, "int32"),
            ("boundaries", 6, _REP, "BoundarySegment"),
        ],
        {},
    ),
    "LaneCenter": (
        [
            ("speed_limit_mph", 1, _OPT, "double"),
            ("type", 2, _OPT, "enum:LaneCenter.LaneType"),
            ("interpolating", 3, _OPT, "bool"),
            ("polyline", 8, _REP, "MapPoint"),
            ("entry_lanes", 9, _REP, "int64"),
            ("exit_lanes", 10, _REP, "int64"),
            ("left_neighbors", 11, _REP, "LaneNeighbor"),
            ("right_neighbors", 12, _REP, "LaneNeighbor"),
            ("left_boundaries", 13, _REP, "BoundarySegment"),
            ("right_boundaries", 14, _REP, "BoundarySegment"),
        ],
        {"LaneType": ("TYPE_UNDEFINED", "TYPE_FREEWAY", "TYPE_SURFACE_STREET", "TYPE_BIKE_LANE")},
    ),
    "StopSign": ([("lane", 1, _REP, "int64"), ("position", 2, _OPT, "MapPoint")], {}),
    "Crosswalk": ([("polygon", 1, _REP, "MapPoint")], {}),
    "SpeedBump": ([("polygon", 1, _REP, "MapPoint")], {}),
    "Driveway": ([("polygon", 1, _REP, "MapPoint")], {}),
    "MapFeature": (
        [
            ("id", 1, _OPT, "int64"),
            ("lane", 3, _OPT, "LaneCenter"),
            ("road_line", 4, _OPT, "RoadLine"),
            ("road_edge", 5, _OPT, "RoadEdge"),
            ("stop_sign", 7, _OPT, "StopSign"),
            ("crosswalk", 8, _OPT, "Crosswalk"),
            ("speed_bump", 9, _OPT, "SpeedBump"),
            ("driveway", 10, _OPT, "Driveway"),
        ],
        {},
    ),
    "ObjectState": (
        [
            ("center_x", 2, _OPT, "double"),
            ("center_y", 3, _OPT, "double"),
            ("center_z", 4, _OPT, "double"),
            ("length", 5, _OPT, "float"),
            ("width", 6, _OPT, "float"),
            ("height", 7, _OPT, "float"),
            ("heading", 8, _OPT, "float"),
            ("velocity_x", 9, _OPT, "float"),
            ("velocity_y", 10, _OPT, "float"),
            ("valid", 11, _OPT, "bool"),
        ],
        {},
    ),
    "Track": (
        [
            ("id", 1, _OPT, "int32"),
            ("object_type", 2, _OPT, "enum:Track.ObjectType"),
            ("states", 3, _REP, "ObjectState"),
        ],
        {"ObjectType": OBJECT_TYPE_NAMES},
    ),
    "DynamicMapState": ([("lane_states", 1, _REP, "TrafficSignalLaneState")], {}),
    "RequiredPrediction": (
        [
            ("track_index", 1, _OPT, "int32"),
            ("difficulty", 2, _OPT, "enum:RequiredPrediction.DifficultyLevel"),
        ],
        {"DifficultyLevel": ("NONE", "LEVEL_1", "LEVEL_2")},
    ),
    "Scenario": (
        [
            ("timestamps_seconds", 1, _REP, "double"),
            ("tracks", 2, _REP, "Track"),
            ("objects_of_interest", 4, _REP, "int32"),
            ("scenario_id", 5, _OPT, "string"),
            ("sdc_track_index", 6, _OPT, "int32"),
            ("dynamic_map_states", 7, _REP, "DynamicMapState"),
            ("map_features", 8, _REP, "MapFeature"),
            ("current_time_index", 10, _OPT, "int32"),
            ("tracks_to_predict", 11, _REP, "RequiredPrediction"),
        ],
        {},
    ),
}
_ONEOF = {"MapFeature": ("feature_data", {3, 4, 5, 7, 8, 9, 10})}


def _file_descriptor() -> descriptor_pb2.FileDescriptorProto:
    fdp = descriptor_pb2.FileDescriptorProto(
        name="redrive/womd_scenario.proto", package=_PACKAGE, syntax="proto2"
    )
    for name, (fields, enums) in _MESSAGES.items():
        msg = fdp.message_type.add(name=name)
        for enum_name, values in enums.items():
            enum = msg.enum_type.add(name=enum_name)
            for number, value in enumerate(values):
                enum.value.add(name=value, number=number)
        oneof = _ONEOF.get(name)
        if oneof is not None:
            msg.oneof_decl.add(name=oneof[0])
        for field_name, number, label, kind in fields:
            field = msg.field.add(name=field_name, number=number, label=label)
            if kind in _SCALARS:
                field.type = _SCALARS[kind]
            elif kind.startswith("enum:"):
                field.type = _F.TYPE_ENUM
                field.type_name = f".{_PACKAGE}.{kind[5:]}"
            else:
                field.type = _F.TYPE_MESSAGE
                field.type_name = f".{_PACKAGE}.{kind}"
            if oneof is not None and number in oneof[1]:
                field.oneof_index = 0
    return fdp


@functools.cache
def scenario_class() -> Any:
    """The message class of ``waymo.open_dataset.Scenario`` (built once)."""
    pool = descriptor_pool.DescriptorPool()
    pool.Add(_file_descriptor())
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(f"{_PACKAGE}.Scenario"))
