"""A run's evaluation, stored beside its outputs, one metric at a time.

The on-disk format (one folder per metric, an index, atomic replacement of one metric without
touching the others) is :mod:`redrive.results.evaluation`; this module turns metric results
into its tables.  Storing a metric again replaces only that metric's results.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from redrive.errors import ConfigError
from redrive.evaluation.base import Metric, MetricResult
from redrive.results import Run
from redrive.results.evaluation import (
    BOOKMARKS,
    CURVES,
    METRICS_DIR,
    PER_FRAME,
    VALUES,
    Evaluation,
    store_metric,
)
from redrive.results.evaluation import read_evaluation as _read_stored
from redrive.results.manifest import now_iso

__all__ = [
    "BOOKMARKS",
    "CURVES",
    "METRICS_DIR",
    "PER_FRAME",
    "VALUES",
    "Evaluation",
    "MetricOutcome",
    "Scored",
    "closed_loop_run",
    "read_evaluation",
    "write_evaluation",
]


@dataclass(frozen=True, slots=True, kw_only=True)
class Scored:
    """One metric's result for one algorithm ("" for run-level metrics)."""

    metric: Metric
    algorithm: str
    result: MetricResult


@dataclass(frozen=True, slots=True, kw_only=True)
class MetricOutcome:
    """A metric that did not score an algorithm ("" for the run): skipped (it does not apply,
    ``error`` False) or failed (it raised, ``error`` True), and why."""

    metric: str
    algorithm: str
    reason: str
    error: bool = False


def _tables(run: Run, scored: Sequence[Scored]) -> dict[str, pa.Table]:
    stamps: dict[int, int] = {}
    frames = run.table("frames")
    if frames.num_rows:
        stamps = dict(
            zip(
                frames.column("frame_index").to_pylist(),
                frames.column("stamp_ns").to_pylist(),
                strict=True,
            )
        )
    values: dict[str, list[Any]] = {n: [] for n in VALUES.names}
    per_frame: dict[str, Any] = {n: [] for n in PER_FRAME.names}
    curves: dict[str, Any] = {n: [] for n in CURVES.names}
    marks: list[tuple[Any, ...]] = []
    closed = closed_loop_run(run)
    for s in scored:
        m, algo, res = s.metric, s.algorithm, s.result
        for key, value in res.values.items():
            series, statistic = res.statistics.get(key, ("", ""))
            for col, v in zip(
                VALUES.names,
                (
                    m.name,
                    m.version,
                    algo,
                    key,
                    value,
                    res.units.get(key, m.unit),
                    res.higher_is_better.get(key, m.higher_is_better),
                    m.subject(res, key, algorithm=algo, closed_loop=closed),
                    series,
                    statistic,
                ),
                strict=True,
            ):
                values[col].append(v)
        for series, (idx, vals) in res.per_frame.items():
            n = len(idx)
            per_frame["metric"] += [m.name] * n
            per_frame["algorithm"] += [algo] * n
            per_frame["series"] += [series] * n
            per_frame["subject"] += [m.subject(res, series, algorithm=algo, closed_loop=closed)] * n
            per_frame["frame_index"].append(np.asarray(idx, dtype=np.int64))
            per_frame["value"].append(np.asarray(vals, dtype=np.float64))
        for curve, (x, y) in res.curves.items():
            n = len(x)
            curves["metric"] += [m.name] * n
            curves["algorithm"] += [algo] * n
            curves["curve"] += [curve] * n
            curves["point"].append(np.arange(n, dtype=np.int64))
            curves["x"].append(np.asarray(x, dtype=np.float64))
            curves["y"].append(np.asarray(y, dtype=np.float64))
        for b in res.bookmarks:
            marks.append(
                (
                    b.frame_index,
                    stamps.get(b.frame_index, 0),
                    b.kind,
                    m.name,
                    algo,
                    b.detail,
                    float(b.severity),
                )
            )
    for table in (per_frame, curves):
        for col in ("frame_index", "value", "point", "x", "y"):
            if col in table:
                parts = table[col]
                dtype = np.int64 if col in ("frame_index", "point") else np.float64
                table[col] = np.concatenate(parts) if parts else np.zeros(0, dtype=dtype)
    marks.sort(key=lambda r: (-r[6], r[0]))
    bookmarks = {n: [r[i] for r in marks] for i, n in enumerate(BOOKMARKS.names)}
    return {
        "values": pa.table(values, schema=VALUES),
        "per_frame": pa.table(per_frame, schema=PER_FRAME),
        "curves": pa.table(curves, schema=CURVES),
        "bookmarks": pa.table(bookmarks, schema=BOOKMARKS),
    }


def closed_loop_run(run: Run) -> bool:
    """True for a run of the closed-loop mode, whose ego the pipeline drove; in any other run
    the ``ego`` table is the logged ego (values of its motion are the log's)."""
    m = run.manifest
    return bool(m.closed_loop) or m.pipeline.mode_manager == "closed_loop"


def write_evaluation(
    run: Run,
    scored: Sequence[Scored],
    *,
    metrics: Sequence[Metric] = (),
    outcomes: Sequence[MetricOutcome] = (),
) -> Path:
    """Store the results of every metric in ``scored`` and ``metrics`` (a metric that scored
    nothing is stored with its skips and failures from ``outcomes``), replacing only those
    metrics' earlier results; returns the metrics folder."""
    by_name: dict[str, Metric] = {m.name: m for m in metrics}
    for s in scored:
        known = by_name.setdefault(s.metric.name, s.metric)
        if known.describe()["version"] != s.metric.describe()["version"] or (
            known.describe()["params_hash"] != s.metric.describe()["params_hash"]
        ):
            msg = (
                f"{run.path}: metric {s.metric.name!r} given with two definitions (versions or "
                "parameters differ); a run stores one definition per metric name"
            )
            raise ConfigError(msg)
    folder = run.path / METRICS_DIR
    evaluated = now_iso()
    for name, metric in by_name.items():
        mine = [s for s in scored if s.metric.name == name]
        record: dict[str, Any] = {
            **metric.describe(),
            "evaluated": evaluated,
            "algorithms": [s.algorithm for s in mine],
            "skipped": [
                {"algorithm": o.algorithm, "reason": o.reason}
                for o in outcomes
                if o.metric == name and not o.error
            ],
            "failed": [
                {"algorithm": o.algorithm, "error": o.reason}
                for o in outcomes
                if o.metric == name and o.error
            ],
        }
        folder = store_metric(run.path, record=record, tables=_tables(run, mine))
    return folder


def read_evaluation(run: Run) -> Evaluation:
    """The stored evaluation of ``run`` (every stored metric).

    Raises:
        ConfigError: the run has not been evaluated (says which command does it).
    """
    return _read_stored(run.path)
