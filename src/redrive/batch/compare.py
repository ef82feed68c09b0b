"""A/B over a fleet: two pipelines of one evaluated batch, or two evaluated batches.

The pooled values of A and B are set side by side; for one chosen value the per-log
differences Δ = B − A (logs paired by their id and loop mode) are ranked, B's worst first, with
a paired percentile bootstrap over logs (:func:`redrive.evaluation.bootstrap.paired_bootstrap`:
the logs are resampled with replacement; 95 % CI of the mean per-log Δ).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from redrive.batch.evaluate import read_cell_values, read_pooled
from redrive.errors import ConfigError
from redrive.evaluation.bootstrap import Bootstrap, paired_bootstrap
from redrive.evaluation.deltas import pair_subject, verdict

__all__ = ["BatchComparison", "LogDelta", "PooledDelta", "compare_batches"]


@dataclass(frozen=True, slots=True, kw_only=True)
class PooledDelta:
    """One pooled value of A and B (same metric, key and loop mode). ``subject``: whose
    motion or output it scores; ``log`` — the logged ego of open-loop runs — is the same
    whatever the pipelines did: the log's, not a result of A or B."""

    metric: str
    key: str
    loop: str
    algorithm_a: str
    algorithm_b: str
    unit: str
    higher_is_better: bool | None
    a: float
    b: float
    subject: str = ""

    @property
    def delta(self) -> float:
        return self.b - self.a

    @property
    def verdict(self) -> str:
        return verdict(self.a, self.b, self.higher_is_better)


@dataclass(frozen=True, slots=True, kw_only=True)
class LogDelta:
    """The chosen value on one log: A, B, Δ = B − A and how much worse B is (> 0: worse)."""

    log: str
    loop: str
    a: float
    b: float
    worse_by: float

    @property
    def delta(self) -> float:
        return self.b - self.a


@dataclass(frozen=True, slots=True, kw_only=True)
class BatchComparison:
    """A against B: ``pooled`` values side by side; ``logs``: the chosen ``metric.key`` per
    log, B's worst first; ``bootstrap`` over the logs' Δ; ``unpaired``: logs only one side has."""

    side_a: str
    side_b: str
    metric: str
    key: str
    higher_is_better: bool | None
    pooled: tuple[PooledDelta, ...]
    logs: tuple[LogDelta, ...]
    bootstrap: Bootstrap
    unpaired: tuple[str, ...]


def _only(values: set[str], what: str, flag: str, where: str) -> str:
    if len(values) == 1:
        return next(iter(values))
    msg = f"{where} has {len(values)} {what}s ({', '.join(sorted(values))}): choose one with {flag}"
    raise ConfigError(msg)


def _side(
    batch_dir: Path, pipeline: str | None, flag: str
) -> tuple[str, list[dict[str, Any]], list[dict[str, Any]]]:
    pooled = read_pooled(batch_dir).to_pylist()
    cells = read_cell_values(batch_dir).to_pylist()
    names = {r["pipeline"] for r in pooled}
    if pipeline is None:
        pipeline = _only(names, "pipeline", flag, str(batch_dir))
    elif pipeline not in names:
        msg = f"{batch_dir}: no evaluated pipeline {pipeline!r} (it has {', '.join(sorted(names))})"
        raise ConfigError(msg)
    return (
        pipeline,
        [r for r in pooled if r["pipeline"] == pipeline],
        [r for r in cells if r["pipeline"] == pipeline],
    )


def _algorithm(rows: Sequence[dict[str, Any]], metric: str, chosen: str | None, flag: str) -> str:
    names = {r["algorithm"] for r in rows if r["metric"] == metric}
    if chosen is not None:
        if chosen not in names:
            msg = (
                f"metric {metric!r} has no algorithm {chosen!r} (it has {', '.join(sorted(names))})"
            )
            raise ConfigError(msg)
        return chosen
    return _only(names, f"algorithm scored by {metric}", flag, "the pipeline")


def compare_batches(
    batch_a: Path,
    batch_b: Path,
    *,
    pipeline_a: str | None = None,
    pipeline_b: str | None = None,
    value: str | None = None,
    algorithm_a: str | None = None,
    algorithm_b: str | None = None,
    resamples: int = 2000,
    seed: int = 0,
) -> BatchComparison:
    """Compare pipeline B of ``batch_b`` against pipeline A of ``batch_a`` (the same directory
    for two pipelines of one batch); both evaluated (``redrive evaluate BATCH``).

    Args:
        value: ``METRIC.KEY`` ranked per log (default: the headline of the first metric both
            sides pooled that scores an algorithm, else of the first metric).

    Raises:
        ConfigError: a batch not evaluated, a pipeline, metric or algorithm not there or not
            named when there are several, no log in common.
    """
    name_a, pooled_a, cells_a = _side(batch_a, pipeline_a, "--pipeline-a")
    name_b, pooled_b, cells_b = _side(batch_b, pipeline_b, "--pipeline-b")
    if value is None:
        in_b = {x["metric"] for x in pooled_b}
        common = [r for r in pooled_a if r["metric"] in in_b]
        if not common:
            msg = "A and B have no pooled metric in common"
            raise ConfigError(msg)
        # an algorithm's own metric first (detection, tracking …), before the run's
        # (never a value of the logged ego: the same whatever the pipelines did)
        mine = [r for r in common if r.get("subject") != "log"] or common
        first = next((r for r in mine if r["algorithm"]), mine[0])
        metric, key = first["metric"], first["key"]
    else:
        metric, dot, key = value.partition(".")
        if not dot:
            msg = f"--value {value!r}: expected METRIC.KEY, e.g. nuscenes_detection.mAP"
            raise ConfigError(msg)
    algo_a = _algorithm(pooled_a, metric, algorithm_a, "--algorithm-a")
    algo_b = _algorithm(pooled_b, metric, algorithm_b or algorithm_a, "--algorithm-b")

    # the pooled values side by side: every (metric, key, loop) both have
    def pooled_index(rows: list[dict[str, Any]], algo_of: dict[str, str]) -> dict[Any, Any]:
        out: dict[Any, Any] = {}
        for r in rows:
            if r["metric"] in algo_of and r["algorithm"] != algo_of[r["metric"]]:
                continue
            out.setdefault((r["metric"], r["key"], r["loop"]), r)
        return out

    ia = pooled_index(pooled_a, {metric: algo_a})
    ib = pooled_index(pooled_b, {metric: algo_b})
    pooled = tuple(
        PooledDelta(
            metric=m,
            key=k,
            loop=loop,
            algorithm_a=ra["algorithm"],
            algorithm_b=ib[(m, k, loop)]["algorithm"],
            unit=ra["unit"],
            higher_is_better=ra["higher_is_better"],
            a=float(ra["value"]),
            b=float(ib[(m, k, loop)]["value"]),
            subject=pair_subject(ra.get("subject"), ib[(m, k, loop)].get("subject")),
        )
        for (m, k, loop), ra in ia.items()
        if (m, k, loop) in ib
    )

    def per_log(rows: list[dict[str, Any]], algo: str) -> dict[tuple[str, str], dict[str, Any]]:
        return {
            (r["log"], r["loop"]): r
            for r in rows
            if r["metric"] == metric and r["key"] == key and r["algorithm"] == algo
        }

    la, lb = per_log(cells_a, algo_a), per_log(cells_b, algo_b)
    if not la or not lb:
        msg = f"no log has a value {metric}.{key} on {'A' if not la else 'B'}"
        raise ConfigError(msg)
    paired = sorted(set(la) & set(lb))
    if not paired:
        msg = f"A and B have no log in common (A: {len(la)} logs, B: {len(lb)})"
        raise ConfigError(msg)
    hib = next(iter(la.values()))["higher_is_better"]
    deltas = []
    for log, loop in paired:
        a, b = float(la[(log, loop)]["value"]), float(lb[(log, loop)]["value"])
        worse = (a - b if hib else b - a) if hib is not None else abs(b - a)
        deltas.append(LogDelta(log=log, loop=loop, a=a, b=b, worse_by=worse))
    deltas.sort(key=lambda d: (-d.worse_by if not math.isnan(d.worse_by) else math.inf, d.log))
    boot = paired_bootstrap(
        np.array([d.delta for d in deltas], dtype=np.float64), resamples=resamples, seed=seed
    )
    unpaired = sorted(f"{log} ({loop})" for log, loop in set(la) ^ set(lb))
    return BatchComparison(
        side_a=f"{batch_a} pipeline {name_a}",
        side_b=f"{batch_b} pipeline {name_b}",
        metric=metric,
        key=key,
        higher_is_better=hib,
        pooled=pooled,
        logs=tuple(deltas),
        bootstrap=boot,
        unpaired=tuple(unpaired),
    )
