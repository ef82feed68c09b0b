"""``python -m benchmarks eval``: nuScenes detection evaluation, vectorised against a plain Python loop.

A synthetic, seeded data set (``frames`` frames × about ``boxes`` ground-truth objects of the five
mapped classes, with as many detections: noisy copies of most objects and false positives, with
tied confidences) is evaluated twice in the same run under the nuScenes definition
(:func:`redrive.evaluation.detection.evaluate_nuscenes`):

- *vectorised*: redrive's implementation (padded per-frame tables, a loop over the k-th detection
  of every frame at once);
- *baseline*: the straightforward implementation of the same definition — the devkit's
  ``accumulate`` structure, a Python loop over the detections in confidence order and, inside it,
  over the ground truth of the detection's frame; the curve arithmetic after matching
  (``calc_ap``, ``calc_tp``, cumulative means) is the same numpy in both.

Both must give the same values (largest absolute difference reported); the ratio is baseline time
over vectorised time (target ≥ 10×).
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from redrive.evaluation.detection.arrays import boxes_by_frame, class_codes
from redrive.evaluation.detection.classes import NUSCENES_CLASS_RANGE_M, NUSCENES_CLASSES
from redrive.evaluation.detection.nuscenes_core import (
    NELEM,
    TP_METRICS,
    TP_SHORT,
    MetricData,
    band_name,
    calc_ap,
    calc_tp,
    cummean,
    evaluate_nuscenes,
    nd_score_without_attributes,
    thr_name,
)
from redrive.types import ObjectColumns

__all__ = ["EvalBenchResult", "baseline_nuscenes", "bench_eval", "synthetic_detections"]

TARGET_RATIO = 10.0
DIST_THS_M = (0.5, 1.0, 2.0, 4.0)
BANDS_M: tuple[tuple[float, float | None], ...] = ((0.0, 20.0), (20.0, 40.0), (40.0, None))
_CLASSES = ("vehicle", "truck", "pedestrian", "bicycle", "motorcycle")


def synthetic_detections(
    frames: int, boxes: int, *, seed: int = 0
) -> tuple[ObjectColumns, ObjectColumns]:
    """Ground truth (``boxes`` ± 20 % per frame, within 60 m) and detections: 85 % of the objects
    found with 0.1–1 m of noise in position, 10 % in size, 0.2 rad in yaw, 1 m/s in velocity, plus
    15 % false positives; confidences rounded to 0.01 (so there are ties)."""
    rng = np.random.default_rng(seed)
    per = rng.integers(int(boxes * 0.8), int(boxes * 1.2) + 1, size=frames)
    n = int(per.sum())
    frame = np.repeat(np.arange(frames), per)
    codes = class_codes(_CLASSES)
    cls = codes[rng.choice(len(_CLASSES), size=n, p=[0.45, 0.1, 0.3, 0.1, 0.05])]
    r = 60.0 * np.sqrt(rng.uniform(0, 1, n))
    phi = rng.uniform(-np.pi, np.pi, n)
    center = np.c_[r * np.cos(phi), r * np.sin(phi), rng.normal(0.8, 0.2, n)]
    size = np.c_[rng.uniform(0.5, 6, n), rng.uniform(0.5, 2.5, n), rng.uniform(1, 3, n)]
    yaw = rng.uniform(-np.pi, np.pi, n)
    vel = np.c_[rng.normal(0, 3, (n, 2)), np.zeros(n)]
    pts = rng.choice(np.array([-1, 0, 3, 50]), size=n, p=[0.5, 0.05, 0.15, 0.3])
    gt = boxes_by_frame(
        frame_index=frame, object_class=cls, center_m=center, size_m=size, yaw_rad=yaw, velocity_mps=vel,
        num_lidar_points=pts,
    )  # fmt: skip
    found = rng.uniform(0, 1, n) < 0.85
    k = int(found.sum())
    noise = rng.uniform(0.1, 1.0, (k, 1))
    tp_center = center[found] + np.c_[rng.normal(0, 1, (k, 2)) * noise, rng.normal(0, 0.1, k)]
    n_fp = int(0.15 * n)
    fp_frame = rng.integers(0, frames, n_fp)
    fr = 60.0 * np.sqrt(rng.uniform(0, 1, n_fp))
    fphi = rng.uniform(-np.pi, np.pi, n_fp)
    pred = boxes_by_frame(
        frame_index=np.r_[frame[found], fp_frame],
        object_class=np.r_[cls[found], codes[rng.integers(0, len(_CLASSES), n_fp)]],
        center_m=np.r_[tp_center, np.c_[fr * np.cos(fphi), fr * np.sin(fphi), np.full(n_fp, 0.8)]],
        size_m=np.r_[size[found] * rng.uniform(0.9, 1.1, (k, 3)), rng.uniform(0.5, 5, (n_fp, 3))],
        yaw_rad=np.r_[yaw[found] + rng.normal(0, 0.2, k), rng.uniform(-np.pi, np.pi, n_fp)],
        velocity_mps=np.r_[vel[found] + np.c_[rng.normal(0, 1, (k, 2)), np.zeros(k)], np.zeros((n_fp, 3))],
        confidence=np.round(np.r_[rng.uniform(0.3, 1, k), rng.uniform(0, 0.7, n_fp)], 2),
    )  # fmt: skip
    return gt, pred


# ------------------------------------------------------------------------------------------------
# the baseline: the same definition, per-frame Python loops


def _baseline_class(
    gts: Mapping[int, list[tuple[float, ...]]],
    preds: list[tuple[float, ...]],
    npos: int,
    dist_th: float,
    name: str,
) -> MetricData:
    # preds: (frame, score, x, y, yaw, l, w, h, vx, vy); gts[frame]: (x, y, yaw, l, w, h, vx, vy)
    if npos == 0:
        return MetricData.no_predictions()
    sortind = [i for (_, i) in sorted((p[1], i) for i, p in enumerate(preds))][::-1]
    taken: set[tuple[int, int]] = set()
    tp: list[int] = []
    conf: list[float] = []
    errs: dict[str, list[float]] = {k: [] for k in TP_METRICS}
    mconf: list[float] = []
    period = math.pi if name == "barrier" else 2 * math.pi
    for ind in sortind:
        p = preds[ind]
        f = int(p[0])
        min_dist, match = math.inf, -1
        for gi, g in enumerate(gts.get(f, ())):
            if (f, gi) in taken:
                continue
            d = math.sqrt((p[2] - g[0]) * (p[2] - g[0]) + (p[3] - g[1]) * (p[3] - g[1]))
            if d < min_dist:
                min_dist, match = d, gi
        conf.append(p[1])
        if min_dist < dist_th:
            taken.add((f, match))
            tp.append(1)
            g = gts[f][match]
            errs["trans_err"].append(min_dist)
            errs["vel_err"].append(math.hypot(p[8] - g[6], p[9] - g[7]))
            inter = min(p[5], g[3]) * min(p[6], g[4]) * min(p[7], g[5])
            union = p[5] * p[6] * p[7] + g[3] * g[4] * g[5] - inter
            errs["scale_err"].append(1.0 - (inter / union if union > 0 else 0.0))
            diff = (g[2] - p[4] + period / 2) % period - period / 2
            errs["orient_err"].append(abs(diff - 2 * math.pi if diff > math.pi else diff))
            mconf.append(p[1])
        else:
            tp.append(0)
    if not mconf:
        return MetricData.no_predictions()
    tpa = np.cumsum(tp).astype(float)
    fpa = np.cumsum([1 - t for t in tp]).astype(float)
    rec = tpa / float(npos)
    r = np.linspace(0, 1, NELEM)
    conf_i = np.interp(r, rec, np.array(conf), right=0)
    return MetricData(
        recall=r,
        precision=np.interp(r, rec, tpa / (fpa + tpa), right=0),
        confidence=conf_i,
        errors={
            k: np.interp(conf_i[::-1], np.array(mconf)[::-1], cummean(np.array(v))[::-1])[::-1]
            for k, v in errs.items()
        },
    )


def baseline_nuscenes(gt: ObjectColumns, pred: ObjectColumns) -> dict[str, float]:
    """The nuScenes values of :func:`evaluate_nuscenes` (default parameters) by loops."""
    code_to_name = {int(class_codes([v])[0]): n for v, n in NUSCENES_CLASSES.items()}
    names = list(dict.fromkeys(NUSCENES_CLASSES.values()))

    def rows(a: ObjectColumns) -> list[tuple[str, float, tuple[float, ...]]]:
        out: list[tuple[str, float, tuple[float, ...]]] = []
        codes = a.class_code()
        for i in range(len(a)):
            name = code_to_name.get(int(codes[i]))
            x, y = float(a.center_m[i, 0]), float(a.center_m[i, 1])
            dist = math.sqrt(x * x + y * y)
            if name is None or dist >= NUSCENES_CLASS_RANGE_M[name] or a.num_lidar_points[i] == 0:
                continue
            s = a.size_m[i]
            v = a.velocity_mps[i]
            rec = (float(a.frame_index[i]), float(a.confidence[i]), x, y, float(a.yaw_rad[i]),
                   float(s[0]), float(s[1]), float(s[2]), float(v[0]), float(v[1]))  # fmt: skip
            out.append((name, dist, rec))
        return out

    g_rows, p_rows = rows(gt), rows(pred)

    def aps(lo: float, hi: float) -> tuple[dict[str, dict[float, MetricData]], set[str]]:
        out: dict[str, dict[float, MetricData]] = {}
        present: set[str] = set()
        for name in names:
            per_frame: dict[int, list[tuple[float, ...]]] = {}
            npos = 0
            for n, d, r in g_rows:
                if n == name and lo <= d < hi:
                    per_frame.setdefault(int(r[0]), []).append(r[2:])
                    npos += 1
            preds = [r for n, d, r in p_rows if n == name and lo <= d < hi]
            if npos or preds:
                present.add(name)
                out[name] = {
                    th: _baseline_class(per_frame, preds, npos, th, name) for th in DIST_THS_M
                }
        return out, present

    values: dict[str, float] = {}
    mds, present = aps(0.0, math.inf)
    class_ap = {}
    tp_err: dict[str, dict[str, float]] = {}
    for name in present:
        for th in DIST_THS_M:
            values[f"AP/{name}/{thr_name(th)}"] = calc_ap(mds[name][th], 0.1, 0.1)
        class_ap[name] = float(np.mean([values[f"AP/{name}/{thr_name(th)}"] for th in DIST_THS_M]))
        values[f"AP/{name}"] = class_ap[name]
        tp_err[name] = {k: calc_tp(mds[name][2.0], 0.1, k) for k in TP_METRICS}
        for k in TP_METRICS:
            values[f"{TP_SHORT[k]}/{name}"] = tp_err[name][k]
    if class_ap:
        values["mAP"] = float(np.mean(list(class_ap.values())))
        means = {k: float(np.nanmean([tp_err[n][k] for n in tp_err])) for k in TP_METRICS}
        for k in TP_METRICS:
            values[f"m{TP_SHORT[k]}"] = means[k]
        values["NDS_no_AAE"] = nd_score_without_attributes(values["mAP"], means, mean_ap_weight=5.0)
    for lo, hi in BANDS_M:
        b_mds, b_present = aps(lo, math.inf if hi is None else hi)
        for th in DIST_THS_M:
            vals = [calc_ap(b_mds[n][th], 0.1, 0.1) for n in names if n in b_present]
            values[f"AP/{band_name(lo, hi)}/{thr_name(th)}"] = (
                float(np.mean(vals)) if vals else math.nan
            )
    return values


# ------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class EvalBenchResult:
    """Times are seconds (median of ``repeats`` for the vectorised path, one baseline pass)."""

    frames: int
    boxes_per_frame: int
    gt_objects: int
    detections: int
    vectorised_s: float
    baseline_s: float
    max_abs_diff: float
    values_compared: int
    mean_ap: float
    repeats: int

    @property
    def ratio(self) -> float:
        return self.baseline_s / self.vectorised_s if self.vectorised_s > 0 else math.inf

    @property
    def vectorised_s_per_10k_frames(self) -> float:
        return self.vectorised_s * 10_000 / max(1, self.frames)

    @property
    def baseline_s_per_10k_frames(self) -> float:
        return self.baseline_s * 10_000 / max(1, self.frames)

    def to_json(self) -> dict[str, Any]:
        return {
            "frames": self.frames,
            "boxes_per_frame": self.boxes_per_frame,
            "gt_objects": self.gt_objects,
            "detections": self.detections,
            "vectorised_s": self.vectorised_s,
            "baseline_s": self.baseline_s,
            "ratio": self.ratio,
            "vectorised_s_per_10k_frames": self.vectorised_s_per_10k_frames,
            "baseline_s_per_10k_frames": self.baseline_s_per_10k_frames,
            "max_abs_diff": self.max_abs_diff,
            "values_compared": self.values_compared,
            "mAP": self.mean_ap,
            "repeats": self.repeats,
            "target_ratio": TARGET_RATIO,
        }


def compare_values(fast: Mapping[str, float], slow: Mapping[str, float]) -> tuple[float, int]:
    """Largest absolute difference over the baseline's values (NaN equal to NaN; a NaN against
    a number counts as ∞) and how many were compared."""
    worst = 0.0
    for key, ref in slow.items():
        got = fast[key]
        if math.isnan(ref) and math.isnan(got):
            continue
        worst = max(worst, math.inf if math.isnan(ref) or math.isnan(got) else abs(got - ref))
    return worst, len(slow)


def bench_eval(
    frames: int = 10_000,
    boxes: int = 30,
    *,
    seed: int = 0,
    repeats: int = 3,
    progress: Callable[[str], None] | None = None,
) -> EvalBenchResult:
    """Time both implementations on one synthetic data set and compare their values."""
    say = progress or (lambda _text: None)
    say("making the data set")
    gt, pred = synthetic_detections(frames, boxes, seed=seed)
    times: list[float] = []
    fast: dict[str, float] = {}
    for i in range(max(1, repeats)):
        say(f"vectorised pass {i + 1}/{repeats}")
        t0 = time.perf_counter()
        fast = evaluate_nuscenes(
            gt, pred, class_map=NUSCENES_CLASSES, class_range_m=NUSCENES_CLASS_RANGE_M,
            dist_ths_m=DIST_THS_M, distance_bands_m=BANDS_M,
        ).values  # fmt: skip
        times.append(time.perf_counter() - t0)
    say("baseline pass (Python loops)")
    t0 = time.perf_counter()
    slow = baseline_nuscenes(gt, pred)
    baseline_s = time.perf_counter() - t0
    worst, compared = compare_values(fast, slow)
    return EvalBenchResult(
        frames=frames,
        boxes_per_frame=boxes,
        gt_objects=len(gt),
        detections=len(pred),
        vectorised_s=statistics.median(times),
        baseline_s=baseline_s,
        max_abs_diff=worst,
        values_compared=compared,
        mean_ap=float(fast["mAP"]),
        repeats=max(1, repeats),
    )
