"""Multi-object tracking: CLEAR MOT (MOTA, MOTP) and the identity metrics (IDF1, IDP, IDR).

Definitions:

* CLEAR MOT — K. Bernardin, R. Stiefelhagen, "Evaluating Multiple Object Tracking Performance:
  The CLEAR MOT Metrics", EURASIP JIVP 2008: per frame, keep the correspondences of the previous
  frame that are still within the gate, then match the rest by minimum total distance (Hungarian);
  ``MOTA = 1 − (FN + FP + IDSW) / GT``, ``MOTP = Σ d(matched pairs) / #matches``.
* Identity metrics — E. Ristani et al., "Performance Measures and a Data Set for Multi-Target,
  Multi-Camera Tracking", ECCV-W 2016: ``IDF1 = 2 IDTP / (GT + PRED)``, ``IDP = IDTP / PRED``,
  ``IDR = IDTP / GT`` under the best global one-to-one assignment of tracks.

Both are computed by ``motmetrics`` (``motmetrics/mot.py`` ``MOTAccumulator.update`` and
``motmetrics/metrics.py`` ``mota``, ``motp``, ``idf1``, ``num_fragmentations``, …); this module
only feeds it, frame by frame in order, with the object ids of the run and a distance matrix:

* ``similarity="distance"`` (default): the bird's-eye-view centre distance (x, y of
  ``Box3D.center`` in ``base_link`` of the frame), metres; pairs farther than ``max_distance_m``
  (default 2.0 m) cannot match.  ``MOTP`` is then the mean BEV centre distance of the matches, m.
* ``similarity="iou"``: our own *oriented* bird's-eye-view IoU (:func:`bev_iou_matrix`, exact
  polygon intersection through shapely — not motmetrics' axis-aligned ``iou_matrix``), distance
  ``1 − IoU``; pairs with IoU below ``min_iou`` (default 0.5) cannot match.  ``MOTP`` is then the
  mean ``1 − IoU`` of the matches (motmetrics' convention: lower is better).

Which frames count: every frame with ground truth in the run (an empty tuple is "nothing there";
frames whose log carries no ground truth are skipped); a frame where the tracker's step failed
counts as an empty output.  Object ids come from ``DetectedObject.object_id``; a detection with
id −1 means the algorithm produces no track ids, which is an error (score a tracker instead).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import motmetrics as mm
import numpy as np
import numpy.typing as npt
import shapely

from redrive.errors import ConfigError
from redrive.evaluation.base import (
    Bookmark,
    EvalData,
    Metric,
    MetricResult,
    MetricSkipped,
    Series,
)
from redrive.types import DetectedObject, ObjectColumns, Role

__all__ = [
    "ClearMot",
    "TrackFrame",
    "bev_centre_distance_m",
    "bev_iou_matrix",
    "by_class",
    "tracking_frames",
]

logger = logging.getLogger(__name__)

#: motmetrics metric name → our value name, in the order they are reported (headline first).
_MM_VALUES: tuple[tuple[str, str], ...] = (
    ("mota", "MOTA"),
    ("motp", "MOTP"),
    ("idf1", "IDF1"),
    ("idp", "IDP"),
    ("idr", "IDR"),
    ("num_switches", "num_switches"),
    ("num_fragmentations", "num_fragmentations"),
    ("mostly_tracked", "mostly_tracked"),
    ("mostly_lost", "mostly_lost"),
    ("num_false_positives", "num_false_positives"),
    ("num_misses", "num_misses"),
    ("num_objects", "num_objects"),
    ("num_predictions", "num_predictions"),
    ("num_matches", "num_matches"),
)
_COUNT_UNITS = {
    "num_switches": "switches",
    "num_fragmentations": "fragmentations",
    "mostly_tracked": "tracks",
    "mostly_lost": "tracks",
    "num_false_positives": "objects",
    "num_misses": "objects",
    "num_objects": "objects",
    "num_predictions": "objects",
    "num_matches": "objects",
    "num_frames": "frames",
}


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackFrame:
    """One evaluated frame: ground truth and the tracker's output, with their ids.

    Attributes:
        frame_index: ``Frame.index``.
        gt: ground-truth objects (``base_link`` of the frame).
        pred: the tracker's objects (``base_link`` of the frame).
        gt_ids, pred_ids: (G,), (P,) int64 ``object_id`` of each, unique within the frame.
    """

    frame_index: int
    gt: tuple[DetectedObject, ...]
    pred: tuple[DetectedObject, ...]
    gt_ids: npt.NDArray[np.int64]
    pred_ids: npt.NDArray[np.int64]


def _ids(
    objects: Sequence[DetectedObject], *, what: str, frame_index: int
) -> npt.NDArray[np.int64]:
    ids = np.fromiter((o.object_id for o in objects), dtype=np.int64, count=len(objects))
    if np.any(ids < 0):
        if what == "ground truth":
            msg = (
                f"frame {frame_index}: ground-truth objects without ids (object_id −1); "
                "tracking metrics need ground truth with track ids"
            )
        else:
            msg = (
                f"frame {frame_index}: {what} produces no track ids (object_id −1); tracking "
                "metrics score a tracker's output — evaluate a tracking algorithm instead"
            )
        raise MetricSkipped(msg)
    if np.unique(ids).size != ids.size:
        msg = (
            f"frame {frame_index}: {what} has the same object_id twice ({sorted(ids.tolist())}); "
            "track ids must be unique within a frame"
        )
        raise ConfigError(msg)
    return ids


def tracking_frames(data: EvalData) -> list[TrackFrame]:
    """The frames to score, in frame order: every frame with ground truth.

    A frame whose step failed (absent from ``data.detections()``) counts as an empty output;
    detections of frames without ground truth are not scored.

    Raises:
        ConfigError: a detection or ground-truth object has id −1, or an id repeats in a frame.
    """
    gt_all = data.ground_truth()
    pred_all = data.detections()
    who = f"algorithm {data.algorithm!r}" if data.algorithm else "the algorithm"
    failed = [f for f in gt_all if f not in pred_all]
    if failed:
        logger.debug("%s: no output on %d frame(s) with ground truth", who, len(failed))
    frames = []
    for f in sorted(gt_all):
        gt = tuple(gt_all[f])
        pred = tuple(pred_all.get(f, ()))
        frames.append(
            TrackFrame(
                frame_index=int(f),
                gt=gt,
                pred=pred,
                gt_ids=_ids(gt, what="ground truth", frame_index=f),
                pred_ids=_ids(pred, what=who, frame_index=f),
            )
        )
    return frames


def by_class(frames: Sequence[TrackFrame]) -> dict[str, list[TrackFrame]]:
    """Class value (``ObjectClass.value``) → the frames with only that class on both sides."""
    names = sorted(
        {o.object_class.value for fr in frames for o in fr.gt}
        | {o.object_class.value for fr in frames for o in fr.pred}
    )
    out: dict[str, list[TrackFrame]] = {}
    for name in names:
        sub = []
        for fr in frames:
            g = [i for i, o in enumerate(fr.gt) if o.object_class.value == name]
            p = [i for i, o in enumerate(fr.pred) if o.object_class.value == name]
            sub.append(
                TrackFrame(
                    frame_index=fr.frame_index,
                    gt=tuple(fr.gt[i] for i in g),
                    pred=tuple(fr.pred[i] for i in p),
                    gt_ids=fr.gt_ids[g],
                    pred_ids=fr.pred_ids[p],
                )
            )
        out[name] = sub
    return out


def bev_centre_distance_m(
    gt: Sequence[DetectedObject], pred: Sequence[DetectedObject]
) -> npt.NDArray[np.float64]:
    """(G, P) float64 bird's-eye-view distance between box centres (x, y only), metres."""
    a = ObjectColumns.from_objects(gt).center_m[:, :2]
    b = ObjectColumns.from_objects(pred).center_m[:, :2]
    out: npt.NDArray[np.float64] = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return out


def _bev_polygons(objects: Sequence[DetectedObject]) -> npt.NDArray[np.object_]:
    if not objects:
        return np.empty(0, dtype=object)
    columns = ObjectColumns.from_objects(objects)
    centre = columns.center_m[:, :2]
    half = 0.5 * columns.size_m[:, :2]  # (N,2) l/2, w/2
    yaw = columns.yaw_rad
    signs = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])  # counter-clockwise
    local = signs[None, :, :] * half[:, None, :]  # (N,4,2)
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x = local[..., 0] * c - local[..., 1] * s + centre[:, 0:1]
    y = local[..., 0] * s + local[..., 1] * c + centre[:, 1:2]
    polys: npt.NDArray[np.object_] = shapely.polygons(np.stack([x, y], axis=-1))
    return polys


def bev_iou_matrix(
    gt: Sequence[DetectedObject], pred: Sequence[DetectedObject]
) -> npt.NDArray[np.float64]:
    """(G, P) float64 IoU of the oriented bird's-eye-view rectangles (length × width, yaw).

    ``area(A ∩ B) / (area(A) + area(B) − area(A ∩ B))`` with the exact polygon intersection;
    0 where the union is empty (degenerate boxes).
    """
    pa_, pb_ = _bev_polygons(gt), _bev_polygons(pred)
    if pa_.size == 0 or pb_.size == 0:
        return np.zeros((pa_.size, pb_.size), dtype=np.float64)
    inter = np.asarray(
        shapely.area(shapely.intersection(pa_[:, None], pb_[None, :])), dtype=np.float64
    )
    union = (
        np.asarray(shapely.area(pa_), dtype=np.float64)[:, None]
        + np.asarray(shapely.area(pb_), dtype=np.float64)[None, :]
    )
    union = union - inter
    out = np.zeros_like(inter)
    ok = union > np.finfo(np.float64).eps
    out[ok] = inter[ok] / union[ok]
    return np.clip(out, 0.0, 1.0)


def _finite_or_nan(x: Any) -> float:
    v = float(x)
    return v if np.isfinite(v) else float("nan")


@dataclass(frozen=True, slots=True, kw_only=True)
class _Clear:
    values: dict[str, float]
    per_frame: dict[str, Series]
    bookmarks: list[Bookmark]


def check_similarity(name: str, params: Mapping[str, Any], *, distance_key: str) -> None:
    """The matching parameters the tracking metrics share: ``similarity`` (``distance`` or
    ``iou``) and a positive distance (``distance_key``, metres).

    Raises:
        ConfigError: either is out of range; the message names the metric and the parameter.
    """
    if params["similarity"] not in ("distance", "iou"):
        msg = (
            f"metric {name!r}: similarity must be 'distance' or 'iou', got {params['similarity']!r}"
        )
        raise ConfigError(msg)
    if not float(params[distance_key]) > 0:
        msg = f"metric {name!r}: {distance_key} must be > 0 m"
        raise ConfigError(msg)


class ClearMot(Metric):
    """CLEAR MOT and identity metrics of a tracker, through ``motmetrics``.

    Parameters (``ClearMot(**params)``):
        similarity: ``"distance"`` (BEV centre distance, default) or ``"iou"`` (oriented BEV IoU).
        max_distance_m: distance gate for ``"distance"``, metres (default 2.0).
        min_iou: IoU gate for ``"iou"`` (default 0.5; pairs below cannot match).
        by_class: also report every value per object class as ``NAME/class`` (default False);
            the class-agnostic values match any class to any class.

    Values (headline first): ``MOTA``, ``MOTP`` (m, or ``1 − IoU``), ``IDF1``, ``IDP``, ``IDR``,
    ``num_switches``, ``num_fragmentations``, ``mostly_tracked``, ``mostly_lost`` (ground-truth
    tracks covered ≥ 80 % / ≤ 20 % of their frames), ``num_false_positives``, ``num_misses``,
    ``num_objects`` (ground-truth boxes), ``num_predictions``, ``num_matches`` (motmetrics:
    matched pairs that are not switches), ``num_frames``.
    ``MOTA`` is NaN without ground truth (its denominator), ``MOTP`` without matches, the
    identity metrics when both sides are empty.

    Per-frame series: ``fp``, ``misses``, ``switches``.  Bookmarks: ``id_switch`` (severity 1)
    on every frame where a ground-truth object changes track.
    """

    name = "clear_mot"
    pooling = "concatenate"
    version = "1"
    role = Role.PERCEPTION
    needs = frozenset({"detections", "ground_truth"})
    unit = ""
    higher_is_better = True
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {"similarity": "distance", "max_distance_m": 2.0, "min_iou": 0.5, "by_class": False}
    )

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        check_similarity(self.name, self.params, distance_key="max_distance_m")
        if not 0.0 < float(self.params["min_iou"]) <= 1.0:
            msg = f"metric {self.name!r}: min_iou must be in (0, 1]"
            raise ConfigError(msg)

    def distances(self, frame: TrackFrame) -> npt.NDArray[np.float64]:
        """(G, P) motmetrics distances of one frame, NaN where a pair may not match."""
        if self.params["similarity"] == "iou":
            d = 1.0 - bev_iou_matrix(frame.gt, frame.pred)
            gate = 1.0 - float(self.params["min_iou"])
        else:
            d = bev_centre_distance_m(frame.gt, frame.pred)
            gate = float(self.params["max_distance_m"])
        return np.where(d <= gate, d, np.nan)

    def _compute(self, frames: Sequence[TrackFrame]) -> _Clear:
        acc = mm.MOTAccumulator(auto_id=False)
        classes = {}
        for fr in frames:
            acc.update(
                fr.gt_ids.tolist(), fr.pred_ids.tolist(), self.distances(fr), frameid=fr.frame_index
            )
            for gid, o in zip(fr.gt_ids.tolist(), fr.gt, strict=True):
                classes[gid] = o.object_class.value
        index = np.array([fr.frame_index for fr in frames], dtype=np.int64)
        counts = {k: np.zeros(index.size, dtype=np.float64) for k in ("fp", "misses", "switches")}
        values: dict[str, float] = {}
        bookmarks: list[Bookmark] = []
        n_gt = sum(len(fr.gt) for fr in frames)
        n_pred = sum(len(fr.pred) for fr in frames)
        if n_gt + n_pred == 0:
            values = {ours: 0.0 if ours in _COUNT_UNITS else float("nan") for _, ours in _MM_VALUES}
        else:
            summary = mm.metrics.create().compute(
                acc, metrics=[m for m, _ in _MM_VALUES], name="all"
            )
            for theirs, ours in _MM_VALUES:
                values[ours] = _finite_or_nan(summary[theirs].iloc[0])
            if n_gt == 0:
                values["MOTA"] = float("nan")  # 1 − (FN + FP + IDSW) / 0 is undefined
            events = acc.mot_events
            row = {int(f): k for k, f in enumerate(index.tolist())}
            last_track: dict[int, int] = {}
            kinds = {"FP": "fp", "MISS": "misses", "SWITCH": "switches"}
            for (frame_id, _), ev in zip(events.index, events.itertuples(index=False), strict=True):
                kind = str(ev.Type)
                if kind in kinds:
                    counts[kinds[kind]][row[int(frame_id)]] += 1.0
                if kind in ("MATCH", "SWITCH"):
                    oid, hid = int(ev.OId), int(ev.HId)
                    if kind == "SWITCH":
                        before = last_track.get(oid)
                        was = f"track {before}" if before is not None else "no track"
                        bookmarks.append(
                            Bookmark(
                                frame_index=int(frame_id),
                                kind="id_switch",
                                detail=(
                                    f"{classes.get(oid, 'object')} {oid} changed from "
                                    f"{was} to track {hid}"
                                ),
                                severity=1.0,
                            )
                        )
                    last_track[oid] = hid
        values["num_frames"] = float(len(frames))
        per_frame: dict[str, Series] = {k: (index, v) for k, v in counts.items()}
        return _Clear(values=values, per_frame=per_frame, bookmarks=bookmarks)

    def evaluate(self, data: EvalData) -> MetricResult:
        frames = tracking_frames(data)
        main = self._compute(frames)
        values = dict(main.values)
        motp_unit = "m" if self.params["similarity"] == "distance" else "1 - IoU"
        units = {**_COUNT_UNITS, "MOTP": motp_unit}
        if self.params["by_class"]:
            for cls, sub in by_class(frames).items():
                res = self._compute(sub)
                for key, v in res.values.items():
                    values[f"{key}/{cls}"] = v
                    if key in units:
                        units[f"{key}/{cls}"] = units[key]
        lower = {"MOTP", "num_switches", "num_fragmentations", "mostly_lost"}
        lower |= {"num_false_positives", "num_misses"}
        neither = {"num_objects", "num_predictions", "num_frames"}  # counts of the data
        directions: dict[str, bool | None] = {}
        for k in values:
            head = k.split("/", 1)[0]
            if head in lower:  # MOTP is a distance or 1 − IoU; the counts are errors
                directions[k] = False
            elif head in neither:
                directions[k] = None
        return MetricResult(
            values=values,
            units=units,
            per_frame=main.per_frame,
            bookmarks=main.bookmarks,
            higher_is_better=directions,
        )
