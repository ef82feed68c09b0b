"""``nuscenes_detection``: the nuScenes detection benchmark's definition on a run.

Definition: nuScenes devkit ``python-sdk/nuscenes/eval/detection`` (see :mod:`.nuscenes_core`
for the ported functions and the details that decide numbers).  What differs, and why:

* **Classes**: ObjectClass → nuScenes name by ``class_map`` (default vehicle→car, truck,
  pedestrian, bicycle, motorcycle; unknown/static/other are not evaluated).  By default
  (``class_mean = "present"``) the means (mAP, mATE …) run over the classes that have ground truth
  or predictions in the run — the devkit's class list is fixed at ten, and a class with neither
  scores AP 0 there (on a cars-only set with perfect detections: mAP 1.0 here, 0.1 in the
  devkit).  ``class_mean = "devkit"`` averages as the devkit does (and adds ``mAAE`` and the
  official ``NDS``).  A class with predictions only gets AP 0 and TP errors 1, as in the devkit.
* **No attributes** in redrive's data model, so no ``attr_err`` (mAAE): the value
  ``NDS_no_AAE`` = ``(5·mAP + Σ max(0, 1 − mTPE)) / 9`` over mATE, mASE, mAOE, mAVE.  It is **not**
  the official NDS (``/10`` with ``1 − mAAE``); the devkit run on attribute-less ground truth
  would give mAAE = 1, i.e. NDS = (9·NDS_no_AAE) / 10.
* **Filtering** as ``filter_eval_boxes`` where the data allows: class range on the BEV distance
  from the base_link origin (``ego_dist``), ground truth with ``num_lidar_points == 0`` dropped
  (unknown counts kept); no bike-rack filter (no bike racks in the data).
* **Frames**: every frame with ground truth; a frame where the detector's step failed counts as
  one without detections (``frames_without_output`` says how many).  Detections of frames without
  ground truth are not scored.
* Velocities are compared in base_link of the frame (nuScenes: global frame), xy only.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from redrive.evaluation.base import Bookmark, EvalData, Metric, MetricResult
from redrive.evaluation.detection.arrays import objects_to_arrays
from redrive.evaluation.detection.classes import NUSCENES_CLASS_RANGE_M, NUSCENES_CLASSES
from redrive.evaluation.detection.nuscenes_core import evaluate_nuscenes
from redrive.types import Role

__all__ = ["NuScenesDetection"]


class NuScenesDetection(Metric):
    """nuScenes detection: mAP over classes and centre-distance thresholds, TP errors, per
    distance band, per-frame TP/FP/missed, missed-object bookmarks.

    Parameters (``defaults``):
        class_map: ObjectClass value → nuScenes class.
        class_range_m: nuScenes class → evaluation range, metres (devkit cvpr_2019 config).
        dist_ths_m: [0.5, 1, 2, 4] BEV centre-distance thresholds, metres.
        dist_th_tp_m: 2.0, threshold of TP errors, recall, per-frame counts and bookmarks.
        min_recall, min_precision: 0.1, 0.1.
        mean_ap_weight: 5.
        distance_bands_m: [[0, 20], [20, 40], [40, None]] ego-distance bands [lo, hi), metres.
        bookmark_range_m: 20, ground truth nearer than this (BEV) and not matched at
            ``dist_th_tp_m`` is bookmarked ``missed_object`` (severity 1/range).
        class_mean: ``present`` (default: the means over the classes the run has) or
            ``devkit`` (over the devkit's ten classes, absent ones scoring AP 0 and TP errors 1,
            plus ``mAAE`` = 1 and the official ``NDS``; ``redrive evaluate --devkit-compat``).

    Values: ``mAP`` (headline), ``NDS_no_AAE``, ``mATE`` ``mASE`` ``mAOE`` ``mAVE``,
    ``AP/<class>/<th>``, ``AP/<class>``, ``ATE/<class>`` ``ASE/…`` ``AOE/…`` ``AVE/…``,
    ``recall/<class>/2.0``, ``AP/band_0_20/<th>`` …, ``mAP/band_0_20`` …, ``gt_objects``,
    ``detections``, ``frames``, ``frames_without_output``.  Curves ``PR/<class>/<th>`` (recall,
    precision on 101 points).  Per frame (at 2 m): ``tp``, ``fp``, ``missed``, ``gt``.
    """

    name = "nuscenes_detection"
    pooling = "concatenate"
    version = "1"
    role = Role.PERCEPTION
    needs = frozenset({"detections", "ground_truth"})
    unit = ""
    higher_is_better = True
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {
            "class_map": dict(NUSCENES_CLASSES),
            "class_range_m": dict(NUSCENES_CLASS_RANGE_M),
            "dist_ths_m": [0.5, 1.0, 2.0, 4.0],
            "dist_th_tp_m": 2.0,
            "min_recall": 0.1,
            "min_precision": 0.1,
            "mean_ap_weight": 5.0,
            "distance_bands_m": [[0.0, 20.0], [20.0, 40.0], [40.0, None]],
            "bookmark_range_m": 20.0,
            "class_mean": "present",
        }
    )

    def evaluate(self, data: EvalData) -> MetricResult:
        p = self.params
        gt_by_frame = data.ground_truth()
        det_by_frame = data.detections()
        frames = np.array(sorted(gt_by_frame), dtype=np.int64)
        gt = objects_to_arrays(gt_by_frame, frames.tolist())
        pred = objects_to_arrays(det_by_frame, frames.tolist())
        ev = evaluate_nuscenes(
            gt,
            pred,
            class_map=p["class_map"],
            class_range_m=p["class_range_m"],
            dist_ths_m=[float(t) for t in p["dist_ths_m"]],
            dist_th_tp_m=float(p["dist_th_tp_m"]),
            min_recall=float(p["min_recall"]),
            min_precision=float(p["min_precision"]),
            mean_ap_weight=float(p["mean_ap_weight"]),
            distance_bands_m=[
                (float(lo), None if hi is None else float(hi)) for lo, hi in p["distance_bands_m"]
            ],
            class_mean=str(p["class_mean"]),
        )
        values = dict(ev.values)
        values["frames"] = float(frames.size)
        values["frames_without_output"] = float(np.sum(~np.isin(frames, list(det_by_frame))))
        units = dict(ev.units)
        units["frames"] = units["frames_without_output"] = "frames"
        slot = np.searchsorted(frames, ev.gt.frame_index)
        pslot = np.searchsorted(frames, ev.pred.frame_index)
        n_f = frames.size
        gt_n = np.bincount(slot, minlength=n_f).astype(np.float64)
        hit = np.bincount(slot[ev.gt_matched], minlength=n_f).astype(np.float64)
        tp = np.bincount(pslot[ev.pred_tp], minlength=n_f).astype(np.float64)
        fp = np.bincount(pslot[~ev.pred_tp], minlength=n_f).astype(np.float64)
        per_frame = {
            "tp": (frames, tp),
            "fp": (frames, fp),
            "missed": (frames, gt_n - hit),
            "gt": (frames, gt_n),
        }
        rng_m = ev.gt.distance_xy_m
        missed = np.flatnonzero(~ev.gt_matched & (rng_m < float(p["bookmark_range_m"])))
        marks = [
            Bookmark(
                frame_index=int(ev.gt.frame_index[i]),
                kind="missed_object",
                detail=(
                    f"{ev.class_names[int(ev.gt_label[i])]} at {rng_m[i]:.1f} m not detected "
                    f"(within {float(p['dist_th_tp_m']):g} m)"
                ),
                severity=1.0 / max(float(rng_m[i]), 0.1),
            )
            for i in missed
        ]
        return MetricResult(
            values=values,
            units=units,
            higher_is_better=nuscenes_directions(values),
            per_frame=per_frame,
            curves=ev.curves,
            bookmarks=marks,
        )


#: the nuScenes true-positive errors (``mATE`` … and per class ``ATE/car`` …): lower is better.
_TP_ERRORS = frozenset({"ATE", "ASE", "AOE", "AVE", "AAE"})
#: counts of what the data held: no direction.
_COUNTS = frozenset({"gt_objects", "detections", "frames"})


def nuscenes_directions(values: Mapping[str, float]) -> dict[str, bool | None]:
    """Per value: the TP errors and ``frames_without_output`` are lower-is-better, the counts
    of the data have none; the rest (AP, recall, NDS) take the metric's higher-is-better."""
    out: dict[str, bool | None] = {}
    for key in values:
        head = key.split("/", 1)[0]
        if (
            head in _TP_ERRORS
            or head.removeprefix("m") in _TP_ERRORS
            or key == "frames_without_output"
        ):
            out[key] = False
        elif key in _COUNTS:
            out[key] = None
    return out
