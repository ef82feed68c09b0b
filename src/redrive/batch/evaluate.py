"""``redrive evaluate BATCH``: every complete cell evaluated as a run, then pooled per
pipeline × loop across logs (:mod:`redrive.evaluation.pooling`), stored under
``BATCH/evaluation/``.

Layout::

    BATCH/evaluation/cells/pipeline=P/loop=L/log=LOG_ID/values.parquet
        metric, algorithm, key, value, unit, higher_is_better, frames — one row per value of
        the cell (a Hive-partitioned dataset: ``pyarrow.dataset.dataset(path,
        partitioning="hive")`` or DuckDB's ``read_parquet(..., hive_partitioning=true)`` give
        the pipeline, loop and log columns)
    BATCH/evaluation/pooled.parquet
        pipeline, loop, metric, algorithm, key, value, unit, higher_is_better, rule, logs, frames
    BATCH/evaluation/index.json
        when, which cells were evaluated, which were left out and why, each metric's rule

The folder is written beside the old one and swapped in, so a reader sees one evaluation whole.
"""

from __future__ import annotations

import math
import shutil
import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from redrive.batch.manifest import BatchManifest, CellRecord, CellStatus, read_batch_manifest
from redrive.errors import ConfigError
from redrive.evaluation.base import Metric, MetricResult
from redrive.evaluation.evaluator import (
    EvaluationSummary,
    default_metrics,
    evaluate_run,
    subjects,
)
from redrive.evaluation.pooling import PooledValues, pool_metric
from redrive.output.atomic import fsync_dir, sync_tree
from redrive.results import Run, read_manifest
from redrive.results.manifest import now_iso, write_json_atomic

__all__ = [
    "BATCH_EVALUATION",
    "CELL_VALUES",
    "POOLED",
    "BatchEvaluation",
    "CellEvaluation",
    "LeftOut",
    "evaluate_batch",
    "read_cell_values",
    "read_pooled",
]

BATCH_EVALUATION = "evaluation"

_S, _F = pa.string(), pa.float64()
CELL_VALUES = pa.schema(
    [
        ("metric", _S),
        ("algorithm", _S),
        ("key", _S),
        ("value", _F),
        ("unit", _S),
        ("higher_is_better", pa.bool_()),
        ("frames", pa.int64()),
        ("subject", _S),
    ]
)
POOLED = pa.schema(
    [
        ("pipeline", _S),
        ("loop", _S),
        ("metric", _S),
        ("algorithm", _S),
        ("key", _S),
        ("value", _F),
        ("unit", _S),
        ("higher_is_better", pa.bool_()),
        ("rule", _S),
        ("logs", pa.int64()),
        ("frames", pa.int64()),
        ("subject", _S),
    ]
)


@dataclass(frozen=True, slots=True, kw_only=True)
class CellEvaluation:
    """One complete cell, evaluated as a run."""

    cell: CellRecord
    summary: EvaluationSummary


@dataclass(frozen=True, slots=True, kw_only=True)
class LeftOut:
    """A cell not evaluated (not complete: failed, pending, interrupted) and why."""

    cell_id: str
    status: str
    reason: str


@dataclass(frozen=True, slots=True, kw_only=True)
class BatchEvaluation:
    """What :func:`evaluate_batch` did.

    Attributes:
        pooled: (pipeline, loop) → the pooled values of every metric and algorithm there.
        pool_errors: (pipeline, loop, metric, algorithm, error) of pooled evaluations that raised.
    """

    batch_dir: Path
    manifest: BatchManifest
    cells: tuple[CellEvaluation, ...]
    left_out: tuple[LeftOut, ...]
    pooled: Mapping[tuple[str, str], tuple[PooledValues, ...]]
    pool_errors: tuple[tuple[str, str, str, str, str], ...]
    folder: Path

    @property
    def failed_metrics(self) -> int:
        """Metric results that raised (in a cell, or pooled)."""
        return sum(len(c.summary.failed) for c in self.cells) + len(self.pool_errors)

    def pooled_value(
        self, pipeline: str, loop: str, metric: str, key: str, algorithm: str
    ) -> float:
        for p in self.pooled.get((pipeline, loop), ()):
            if p.metric == metric and p.algorithm == algorithm:
                return p.values.get(key, math.nan)
        return math.nan


def _cell_rows(summary: EvaluationSummary, frames: int) -> pa.Table:
    rows: dict[str, list[Any]] = {n: [] for n in CELL_VALUES.names}
    closed = summary.closed_loop
    for s in summary.scored:
        whose = subjects(s, closed_loop=closed)
        for key, value in s.result.values.items():
            rows["subject"].append(whose[key])
            rows["metric"].append(s.metric.name)
            rows["algorithm"].append(s.algorithm)
            rows["key"].append(key)
            rows["value"].append(value)
            rows["unit"].append(s.result.units.get(key, s.metric.unit))
            rows["higher_is_better"].append(
                s.result.higher_is_better.get(key, s.metric.higher_is_better)
            )
            rows["frames"].append(frames)
    return pa.table(rows, schema=CELL_VALUES)


def _pooled_rows(pooled: Mapping[tuple[str, str], Sequence[PooledValues]]) -> pa.Table:
    rows: dict[str, list[Any]] = {n: [] for n in POOLED.names}
    for (pipeline, loop), items in pooled.items():
        for p in items:
            for key, value in p.values.items():
                for name, v in (
                    ("pipeline", pipeline),
                    ("loop", loop),
                    ("metric", p.metric),
                    ("algorithm", p.algorithm),
                    ("key", key),
                    ("value", value),
                    ("unit", p.units.get(key, "")),
                    ("higher_is_better", p.higher_is_better.get(key)),
                    ("rule", p.rule),
                    ("logs", p.logs),
                    ("frames", p.frames),
                    ("subject", p.subjects.get(key, p.algorithm or "run")),
                ):
                    rows[name].append(v)
    return pa.table(rows, schema=POOLED)


def evaluate_batch(
    batch_dir: Path,
    *,
    metrics: Sequence[Metric] | None = None,
    algorithms: Sequence[str] | None = None,
) -> BatchEvaluation:
    """Evaluate every complete cell of the batch in ``batch_dir`` (each stored in its own run
    directory, as ``redrive evaluate RUN`` does), pool each metric per pipeline × loop across
    the logs (the metric's ``pooling`` rule), and store both under ``BATCH/evaluation/``.

    Raises:
        ConfigError: not a batch directory, or no cell is complete.
    """
    manifest = read_batch_manifest(batch_dir)
    chosen = list(metrics) if metrics is not None else default_metrics()
    evaluated: list[CellEvaluation] = []
    left_out: list[LeftOut] = []
    for cell in manifest.cells:
        if cell.status not in (CellStatus.COMPLETE, CellStatus.SKIPPED):
            reason = cell.error or f"the cell is {cell.status.value}"
            left_out.append(LeftOut(cell_id=cell.cell_id, status=cell.status.value, reason=reason))
            continue
        run_algos = None
        if algorithms is not None:  # those of this cell's pipeline (pipelines differ)
            names = set(read_manifest(batch_dir / cell.run_dir).names())
            run_algos = [a for a in algorithms if a in names]
        summary = evaluate_run(batch_dir / cell.run_dir, metrics=chosen, algorithms=run_algos)
        evaluated.append(CellEvaluation(cell=cell, summary=summary))
    if not evaluated:
        msg = (
            f"{batch_dir}: no cell of the batch is complete "
            f"({', '.join(f'{o.cell_id} {o.status}' for o in left_out[:5])}); nothing to evaluate"
        )
        raise ConfigError(msg)

    groups: dict[tuple[str, str], list[CellEvaluation]] = {}
    for ce in evaluated:
        groups.setdefault((ce.cell.pipeline, ce.cell.loop), []).append(ce)
    pooled: dict[tuple[str, str], tuple[PooledValues, ...]] = {}
    errors: list[tuple[str, str, str, str, str]] = []
    for (pipeline, loop), members in groups.items():
        items: list[PooledValues] = []
        for metric in chosen:
            per_algo: dict[str, list[tuple[Run, MetricResult]]] = {}
            for ce in members:
                for s in ce.summary.scored:
                    if s.metric is metric:
                        per_algo.setdefault(s.algorithm, []).append((ce.summary.run, s.result))
            for algo, pairs in per_algo.items():
                try:
                    items.append(
                        pool_metric(
                            metric,
                            algorithm=algo,
                            runs=[r for r, _ in pairs],
                            results=[res for _, res in pairs],
                        )
                    )
                except Exception as err:  # a metric's bug: reported, never silent
                    errors.append(
                        (pipeline, loop, metric.name, algo, f"{type(err).__name__}: {err}")
                    )
        pooled[(pipeline, loop)] = tuple(items)
    folder = _store(batch_dir, evaluated, pooled, left_out, chosen)
    return BatchEvaluation(
        batch_dir=batch_dir,
        manifest=manifest,
        cells=tuple(evaluated),
        left_out=tuple(left_out),
        pooled=pooled,
        pool_errors=tuple(errors),
        folder=folder,
    )


def _store(
    batch_dir: Path,
    cells: Sequence[CellEvaluation],
    pooled: Mapping[tuple[str, str], Sequence[PooledValues]],
    left_out: Sequence[LeftOut],
    metrics: Sequence[Metric],
) -> Path:
    final = batch_dir / BATCH_EVALUATION
    tmp = batch_dir / f".{BATCH_EVALUATION}.{uuid.uuid4().hex[:8]}.tmp"
    tmp.mkdir()
    try:
        for ce in cells:
            part = (
                tmp / "cells" / f"pipeline={ce.cell.pipeline}" / f"loop={ce.cell.loop}"
                / f"log={ce.cell.log_id}"
            )  # fmt: skip
            part.mkdir(parents=True)
            frames = int(ce.summary.run.manifest.frames_done)
            pq.write_table(_cell_rows(ce.summary, frames), part / "values.parquet")
        pq.write_table(_pooled_rows(pooled), tmp / "pooled.parquet")
        write_json_atomic(
            tmp / "index.json",
            {
                "evaluated": now_iso(),
                "cells": [ce.cell.cell_id for ce in cells],
                "left_out": [
                    {"cell_id": o.cell_id, "status": o.status, "reason": o.reason} for o in left_out
                ],
                "pooling": {m.name: m.pooling for m in metrics},
            },
        )
        old = batch_dir / f".{BATCH_EVALUATION}.{uuid.uuid4().hex[:8]}.old"
        sync_tree(tmp)
        if final.exists():
            final.rename(old)
        tmp.rename(final)
        fsync_dir(batch_dir)
        shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return final


def read_cell_values(batch_dir: Path) -> pa.Table:
    """Every evaluated cell's values with their ``pipeline``, ``loop`` and ``log`` columns.

    Raises:
        ConfigError: the batch has not been evaluated.
    """
    folder = batch_dir / BATCH_EVALUATION / "cells"
    if not folder.is_dir():
        msg = f"{batch_dir} has not been evaluated; run `redrive evaluate {batch_dir}` first"
        raise ConfigError(msg)
    part = ds.partitioning(pa.schema([("pipeline", _S), ("loop", _S), ("log", _S)]), flavor="hive")
    return _with_subject(ds.dataset(folder, format="parquet", partitioning=part).to_table())


def _with_subject(table: pa.Table) -> pa.Table:
    """``table`` with its ``subject`` column; a batch evaluated before values had one gets the
    algorithm (``run`` for a whole-run metric), what those values were then taken to be."""
    if "subject" in table.column_names:
        return table
    fill = [a or "run" for a in table.column("algorithm").to_pylist()]
    return table.append_column("subject", pa.array(fill, type=_S))


def read_pooled(batch_dir: Path) -> pa.Table:
    """The pooled values of an evaluated batch (schema :data:`POOLED`).

    Raises:
        ConfigError: the batch has not been evaluated.
    """
    path = batch_dir / BATCH_EVALUATION / "pooled.parquet"
    if not path.is_file():
        msg = f"{batch_dir} has not been evaluated; run `redrive evaluate {batch_dir}` first"
        raise ConfigError(msg)
    return _with_subject(pq.read_table(path)).select(POOLED.names).cast(POOLED)
