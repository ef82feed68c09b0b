"""A run's evaluation, stored beside its outputs.

Layout (written atomically: temp file + rename, then the manifest)::

    RUN/metrics/values.parquet     metric, metric_version, algorithm, key, value, unit,
                                   higher_is_better — one row per named aggregate value
    RUN/metrics/per_frame.parquet  metric, algorithm, series, frame_index, value
    RUN/metrics/curves.parquet     metric, algorithm, curve, point, x, y
    RUN/metrics/bookmarks.parquet  frame_index, stamp_ns, kind, metric, algorithm, detail, severity
    RUN/manifest.json              ["evaluation"] = {"evaluated": ISO time, "metrics": [{name,
                                   version, role, unit, higher_is_better, params, params_hash,
                                   algorithms}]}

Evaluating again replaces the whole evaluation (never a mix of two).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from redrive.errors import ConfigError
from redrive.evaluation.base import Metric, MetricResult
from redrive.results import Run
from redrive.results.manifest import MANIFEST_NAME, now_iso, read_manifest, write_json_atomic

__all__ = [
    "BOOKMARKS",
    "CURVES",
    "METRICS_DIR",
    "PER_FRAME",
    "VALUES",
    "Evaluation",
    "Scored",
    "read_evaluation",
    "write_evaluation",
]

METRICS_DIR = "metrics"
_S, _F, _I = pa.string(), pa.float64(), pa.int64()

VALUES = pa.schema(
    [
        ("metric", _S),
        ("metric_version", _S),
        ("algorithm", _S),
        ("key", _S),
        ("value", _F),
        ("unit", _S),
        ("higher_is_better", pa.bool_()),
    ]
)
PER_FRAME = pa.schema(
    [("metric", _S), ("algorithm", _S), ("series", _S), ("frame_index", _I), ("value", _F)]
)
CURVES = pa.schema(
    [
        ("metric", _S),
        ("algorithm", _S),
        ("curve", _S),
        ("point", _I),
        ("x", _F),
        ("y", _F),
    ]
)
BOOKMARKS = pa.schema(
    [
        ("frame_index", _I),
        ("stamp_ns", _I),
        ("kind", _S),
        ("metric", _S),
        ("algorithm", _S),
        ("detail", _S),
        ("severity", _F),
    ]
)
_FILES = {"values": VALUES, "per_frame": PER_FRAME, "curves": CURVES, "bookmarks": BOOKMARKS}


@dataclass(frozen=True, slots=True, kw_only=True)
class Scored:
    """One metric's result for one algorithm ("" for run-level metrics)."""

    metric: Metric
    algorithm: str
    result: MetricResult


@dataclass(frozen=True, slots=True, kw_only=True)
class Evaluation:
    """A run's stored evaluation: the four tables and the manifest's metric list."""

    values: pa.Table
    per_frame: pa.Table
    curves: pa.Table
    bookmarks: pa.Table
    metrics: tuple[Mapping[str, Any], ...]
    evaluated: str

    def value(self, metric: str, key: str, *, algorithm: str = "") -> float:
        """One stored value (NaN when absent)."""
        for row in self.values.to_pylist():
            if row["metric"] == metric and row["key"] == key and row["algorithm"] == algorithm:
                return float(row["value"])
        return float("nan")


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
    for s in scored:
        m, algo, res = s.metric, s.algorithm, s.result
        for key, value in res.values.items():
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
                ),
                strict=True,
            ):
                values[col].append(v)
        for series, (idx, vals) in res.per_frame.items():
            n = len(idx)
            per_frame["metric"] += [m.name] * n
            per_frame["algorithm"] += [algo] * n
            per_frame["series"] += [series] * n
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


def write_evaluation(run: Run, scored: Sequence[Scored]) -> Path:
    """Store ``scored`` in ``run``'s directory (replacing an earlier evaluation); returns the
    metrics directory."""
    out = run.path / METRICS_DIR
    out.mkdir(exist_ok=True)
    for name, table in _tables(run, scored).items():
        path = out / f"{name}.parquet"
        tmp = path.with_name(path.name + ".tmp")
        pq.write_table(table, tmp)
        os.replace(tmp, path)
    metrics: dict[tuple[str, str], dict[str, Any]] = {}
    for s in scored:
        entry = metrics.setdefault(
            (s.metric.name, s.metric.describe()["params_hash"]),
            {**s.metric.describe(), "algorithms": []},
        )
        entry["algorithms"].append(s.algorithm)
    manifest = read_manifest(run.path)
    manifest["evaluation"] = {"evaluated": now_iso(), "metrics": list(metrics.values())}
    write_json_atomic(run.path / MANIFEST_NAME, manifest)
    return out


def read_evaluation(run: Run) -> Evaluation:
    """The stored evaluation of ``run``.

    Raises:
        ConfigError: the run has not been evaluated (says which command does it).
    """
    folder = run.path / METRICS_DIR
    info = read_manifest(run.path).get("evaluation")
    if info is None or not (folder / "values.parquet").is_file():
        msg = f"{run.path} has not been evaluated; run `redrive evaluate {run.path}` first"
        raise ConfigError(msg)
    tables = {
        name: pq.read_table(folder / f"{name}.parquet", schema=schema)
        for name, schema in _FILES.items()
    }
    return Evaluation(
        values=tables["values"],
        per_frame=tables["per_frame"],
        curves=tables["curves"],
        bookmarks=tables["bookmarks"],
        metrics=tuple(info.get("metrics", ())),
        evaluated=str(info.get("evaluated", "")),
    )
