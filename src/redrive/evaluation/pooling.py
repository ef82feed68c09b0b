"""Pooling a metric across several runs (the logs of a batch), the way its definition demands.

Each metric says how in ``Metric.pooling``:

* ``"concatenate"`` — the metric is evaluated **once over all frames of all runs together**:
  :class:`PooledEvalData` shows the runs as one, frame indices shifted so that they are unique
  per run (run k's frames follow run k−1's) and object ids made unique per run (id + k·10¹²; −1,
  "no id", stays −1), so no match, track or switch crosses from one log into the next.  This is
  what detection AP (nuScenes, KITTI: one precision/recall curve over every frame's detections,
  not a mean of per-log APs), CLEAR MOT and HOTA (their counts summed before the ratios, as
  merging motmetrics accumulators with new frame and object ids does), object-attribute errors
  and latency percentiles (over every frame) are defined on.
* ``"frame_weighted_mean"`` — each value is the mean of the runs' values weighted by their
  frame counts (NaN values left out).  Metrics of the ego's motion over time (planning, control,
  the closed-loop metrics) are per-log quantities: concatenating would join one log's last pose
  to the next log's first.
* ``"scenario_mean"`` — each value is the plain mean of the runs' values (NaN left out), every
  log counting once whatever its length: nuPlan's final score is the mean of its scenario
  scores (``WeightedAverageMetricAggregator``: per scenario type the mean, then the types
  weighted by their scenario counts — the same mean). A metric's ``pooled_name`` names the
  pooled headline (``nuplan_scenario_score`` → ``cls``, the closed-loop score).
* ``"none"`` — the metric cannot be pooled: its per-log values stand alone.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from redrive.evaluation.base import EvalData, Metric, MetricResult
from redrive.evaluation.store import closed_loop_run
from redrive.results import Run
from redrive.types import DetectedObject, RoadMap

__all__ = ["OBJECT_ID_STRIDE", "PooledEvalData", "PooledValues", "pool_metric", "rule_text"]

#: object ids of run k are shifted by k × this (ids of one log stay apart from the next's).
OBJECT_ID_STRIDE = 10**12

_V = TypeVar("_V")

_RULE_TEXT = {
    "concatenate": "all frames of all logs evaluated together",
    "frame_weighted_mean": "mean of the logs' values weighted by their frames",
    "scenario_mean": "mean of the logs' values, each log counting once",
    "none": "cannot be pooled: per-log values only",
}


def rule_text(rule: str) -> str:
    """One line saying what a pooling rule does."""
    return _RULE_TEXT.get(rule, rule)


def _shift_column(table: pa.Table, offset: int) -> pa.Table:
    if "frame_index" not in table.column_names or offset == 0:
        return table
    i = table.column_names.index("frame_index")
    shifted = pc.add(table.column(i), pa.scalar(offset, table.schema.field(i).type))
    return table.set_column(i, table.schema.field(i), shifted)


def _renumber(objects: tuple[DetectedObject, ...], k: int) -> tuple[DetectedObject, ...]:
    if k == 0:
        return objects
    return tuple(
        o
        if o.object_id < 0
        else dataclasses.replace(o, object_id=o.object_id + k * OBJECT_ID_STRIDE)
        for o in objects
    )


class PooledEvalData(EvalData):
    """Several runs seen as one, for one algorithm (``""``: the runs as a whole).

    ``run`` is the first run (its manifest names the pipeline, which every run shares);
    ``offsets[k]`` is what run k's frame indices are shifted by.
    """

    def __init__(self, runs: Sequence[Run], algorithm: str = "") -> None:
        if not runs:
            msg = "PooledEvalData needs at least one run"
            raise ValueError(msg)
        super().__init__(runs[0], algorithm)
        self.runs = tuple(runs)
        offsets, next_offset = [], 0
        for run in self.runs:
            offsets.append(next_offset)
            idx = run.table("frames").column("frame_index")
            top = pc.max(idx).as_py() if len(idx) else None
            next_offset += 0 if top is None else int(top) + 1
        self.offsets = tuple(offsets)

    def _tables(self, name: str) -> pa.Table:
        parts = [
            _shift_column(r.table(name), off)
            for r, off in zip(self.runs, self.offsets, strict=True)
        ]
        return pa.concat_tables(parts, promote_options="default")

    def _by_frame(
        self, get: Callable[[Run], Mapping[int, _V]], fix: Callable[[_V, int], _V] | None = None
    ) -> dict[int, _V]:
        out: dict[int, _V] = {}
        for k, (run, off) in enumerate(zip(self.runs, self.offsets, strict=True)):
            for f, v in get(run).items():
                out[int(f) + off] = v if fix is None else fix(v, k)
        return out

    @property
    def frame_period_s(self) -> float:
        """Median time between frames within each run (never across two runs)."""
        diffs = []
        for run in self.runs:
            stamps = np.sort(np.asarray(run.table("frames").column("stamp_ns").to_numpy()))
            diffs.append(np.diff(stamps.astype(np.int64)))
        d = np.concatenate(diffs) if diffs else np.empty(0, dtype=np.int64)
        return float(np.median(d)) / 1e9 if d.size else 0.0

    def frames(self) -> pa.Table:
        return self._cached("frames", lambda: self._tables("frames"))

    def steps(self) -> pa.Table:
        return self._cached("steps", lambda: self._tables("steps"))

    def closed_loop(self) -> pa.Table:
        return self._cached("closed_loop", lambda: self._tables("closed_loop"))

    def detections(self) -> dict[int, tuple[DetectedObject, ...]]:
        algo = self.algorithm
        return self._cached(
            "detections", lambda: self._by_frame(lambda r: r.detections(algo), _renumber)
        )

    def ground_truth(self) -> dict[int, tuple[DetectedObject, ...]]:
        return self._cached(
            "ground_truth", lambda: self._by_frame(lambda r: r.ground_truth(), _renumber)
        )

    def ego(self) -> dict[int, Any]:
        return self._cached("ego", lambda: self._by_frame(lambda r: r.ego()))

    def logged_ego(self) -> dict[int, Any]:
        return self._cached("logged_ego", lambda: self._by_frame(lambda r: r.logged_ego()))

    def road_map(self) -> RoadMap | None:
        return None  # each log has its own map: map metrics pool by their frame-weighted mean

    def traffic_lights(self) -> dict[int, Any]:
        return self._cached("traffic_lights", lambda: self._by_frame(lambda r: r.traffic_lights()))

    def paths(self) -> dict[int, Any]:
        algo = self.algorithm
        return self._cached("paths", lambda: self._by_frame(lambda r: r.paths(algo)))

    def commands(self) -> dict[int, Any]:
        algo = self.algorithm
        return self._cached("commands", lambda: self._by_frame(lambda r: r.commands(algo)))


@dataclass(frozen=True, slots=True, kw_only=True)
class PooledValues:
    """A metric's values pooled over ``logs`` runs (``frames`` frames in all) by ``rule``.

    ``values`` is empty when the rule is ``"none"``; ``note`` says why a value is missing.
    """

    metric: str
    algorithm: str
    rule: str
    values: Mapping[str, float]
    units: Mapping[str, str]
    higher_is_better: Mapping[str, bool | None]
    logs: int
    frames: int
    note: str = ""
    #: value name → whose motion or output it scores (``log``: the logged ego of open-loop runs)
    subjects: Mapping[str, str] = field(default_factory=dict)


def _weighted(results: Sequence[tuple[MetricResult, int]]) -> dict[str, float]:
    keys: list[str] = []
    for res, _ in results:
        keys += [k for k in res.values if k not in keys]
    out = {}
    for key in keys:
        num = den = 0.0
        for res, frames in results:
            v = res.values.get(key, math.nan)
            if not math.isnan(v) and frames > 0:
                num += v * frames
                den += frames
        out[key] = num / den if den > 0 else math.nan
    return out


def _scenario_mean(results: Sequence[MetricResult]) -> dict[str, float]:
    return _weighted([(res, 1) for res in results])


def pool_metric(
    metric: Metric,
    *,
    algorithm: str,
    runs: Sequence[Run],
    results: Sequence[MetricResult],
) -> PooledValues:
    """Pool ``metric`` for ``algorithm`` over ``runs`` (whose own results are ``results``, in
    the same order) by the metric's ``pooling`` rule.

    Raises whatever ``metric.evaluate`` raises for the ``"concatenate"`` rule.
    """
    if len(runs) != len(results):
        msg = f"pool_metric: {len(runs)} runs but {len(results)} results"
        raise ValueError(msg)
    frames = [int(r.manifest.frames_done) for r in runs]
    rule = metric.pooling
    units: dict[str, str] = {}
    hib: dict[str, bool | None] = {}
    closed = bool(runs) and closed_loop_run(runs[0])
    subjects: dict[str, str] = {}
    for res in results:
        units.update({k: res.units.get(k, metric.unit) for k in res.values})
        hib.update({k: res.higher_is_better.get(k, metric.higher_is_better) for k in res.values})
        for k in res.values:
            subjects.setdefault(k, metric.subject(res, k, algorithm=algorithm, closed_loop=closed))
    common = functools.partial(
        PooledValues, metric=metric.name, algorithm=algorithm, logs=len(runs), subjects=subjects
    )
    if rule == "none":
        return common(
            rule=rule,
            values={},
            units=units,
            higher_is_better=hib,
            frames=sum(frames),
            note=f"metric {metric.name!r} cannot be pooled (Metric.pooling = 'none')",
        )
    if rule == "concatenate":
        data = PooledEvalData(runs, algorithm)
        pooled = metric.evaluate(data)
        for k in pooled.values:
            subjects.setdefault(
                k, metric.subject(pooled, k, algorithm=algorithm, closed_loop=closed)
            )
        units.update({k: pooled.units.get(k, metric.unit) for k in pooled.values})
        hib.update(
            {k: pooled.higher_is_better.get(k, metric.higher_is_better) for k in pooled.values}
        )
        return common(
            rule=rule,
            values=dict(pooled.values),
            units=units,
            higher_is_better=hib,
            frames=int(data.frames().num_rows),
        )
    if rule == "scenario_mean":
        values = _scenario_mean(results)
        head = next(iter(values), None)
        if metric.pooled_name and head is not None:
            values = {metric.pooled_name: values[head], **values}
            if head in subjects:
                subjects[metric.pooled_name] = subjects[head]
            units[metric.pooled_name] = units.get(head, metric.unit)
            hib[metric.pooled_name] = hib.get(head, metric.higher_is_better)
        return common(
            rule=rule, values=values, units=units, higher_is_better=hib, frames=sum(frames)
        )
    return common(
        rule=rule,
        values=_weighted(list(zip(results, frames, strict=True))),
        units=units,
        higher_is_better=hib,
        frames=sum(frames),
    )
