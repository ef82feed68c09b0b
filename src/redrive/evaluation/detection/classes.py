"""Which redrive classes each benchmark evaluates, and under which name.

redrive's :class:`~redrive.types.ObjectClass` is coarser than nuScenes' ten detection classes and
KITTI's labels.  The defaults map the classes that have a counterpart; ``UNKNOWN``, ``STATIC`` and
``OTHER`` are not evaluated (dropped from ground truth and detections alike) unless a user maps
them (e.g. ``{"static": "barrier"}``; the nuScenes special cases of ``barrier`` and
``traffic_cone`` then apply by name).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

__all__ = [
    "KITTI_CLASSES",
    "KITTI_MIN_OVERLAP",
    "NUSCENES_CLASSES",
    "NUSCENES_CLASS_RANGE_M",
]

#: ObjectClass value → nuScenes detection name.
NUSCENES_CLASSES: Mapping[str, str] = MappingProxyType(
    {
        "vehicle": "car",
        "truck": "truck",
        "pedestrian": "pedestrian",
        "bicycle": "bicycle",
        "motorcycle": "motorcycle",
    }
)

#: nuScenes evaluation range per class, metres (``configs/detection_cvpr_2019.json``,
#: ``class_range``); boxes at ``ego_dist >= range`` are dropped (``filter_eval_boxes``).
NUSCENES_CLASS_RANGE_M: Mapping[str, float] = MappingProxyType(
    {
        "car": 50.0,
        "truck": 50.0,
        "bus": 50.0,
        "trailer": 50.0,
        "construction_vehicle": 50.0,
        "pedestrian": 40.0,
        "motorcycle": 40.0,
        "bicycle": 40.0,
        "traffic_cone": 30.0,
        "barrier": 30.0,
    }
)

#: KITTI class → the ObjectClass values that count as it.  (redrive's KITTI reader maps Car and
#: Van to ``vehicle``, Pedestrian and Person_sitting to ``pedestrian``, Cyclist to ``bicycle``.)
KITTI_CLASSES: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {"car": ("vehicle",), "pedestrian": ("pedestrian",), "cyclist": ("bicycle",)}
)

#: KITTI's minimum overlap for a match, BEV and 3D alike (``kitti_eval``: ``overlap_0_7``).
KITTI_MIN_OVERLAP: Mapping[str, float] = MappingProxyType(
    {"car": 0.7, "pedestrian": 0.5, "cyclist": 0.5}
)
