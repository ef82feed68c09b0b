"""Detection metrics: the nuScenes (centre distance) and KITTI (oriented IoU, R40) definitions.

>>> from redrive.evaluation.detection import NuScenesDetection, KittiDetection
"""

from __future__ import annotations

from redrive.evaluation.detection.arrays import boxes_by_frame, objects_to_arrays
from redrive.evaluation.detection.kitti import KittiDetection
from redrive.evaluation.detection.nuscenes import NuScenesDetection
from redrive.evaluation.detection.nuscenes_core import evaluate_nuscenes

__all__ = [
    "KittiDetection",
    "NuScenesDetection",
    "boxes_by_frame",
    "evaluate_nuscenes",
    "objects_to_arrays",
]
