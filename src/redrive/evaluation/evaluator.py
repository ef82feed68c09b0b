"""Evaluate a run: every metric against every algorithm of its role, stored with the run.

>>> summary = evaluate_run("runs/first")        # doctest: +SKIP
>>> summary.scored[0].result.values             # doctest: +SKIP
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from redrive.errors import RedriveError
from redrive.evaluation.base import EvalData, Metric
from redrive.evaluation.registry import installed_metrics
from redrive.evaluation.store import Scored, write_evaluation
from redrive.results import Run, open_run

__all__ = ["EvaluationSummary", "Skipped", "default_metrics", "evaluate_run"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class Skipped:
    """A metric not computed for an algorithm, and why."""

    metric: str
    algorithm: str
    reason: str


@dataclass(frozen=True, slots=True, kw_only=True)
class EvaluationSummary:
    run: Run
    scored: tuple[Scored, ...]
    skipped: tuple[Skipped, ...]
    metrics_dir: Path

    @property
    def bookmarks(self) -> int:
        return sum(len(s.result.bookmarks) for s in self.scored)


def default_metrics() -> list[Metric]:
    """One instance, with default parameters, of every installed metric."""
    return [cls() for cls in installed_metrics().values()]


def _has(run: Run, data: EvalData, need: str) -> str | None:
    """None if the run provides ``need`` for ``data.algorithm``, else why not."""
    if need == "ground_truth" and run.table("ground_truth").num_rows == 0:
        frames = run.table("frames")
        if frames.num_rows == 0 or frames.column("n_ground_truth").null_count == frames.num_rows:
            return "the log has no ground truth"
    if need == "ego" and run.table("ego").num_rows == 0:
        return "the log has no ego state"
    return None


def evaluate_run(
    run_dir: str | Path,
    *,
    metrics: Sequence[Metric] | None = None,
    algorithms: Sequence[str] | None = None,
) -> EvaluationSummary:
    """Run ``metrics`` (default: every installed one) on the algorithms of their role and store
    the results in the run directory (replacing an earlier evaluation).

    A metric that cannot score an algorithm (its run lacks ground truth, a detector has no track
    ids for a tracking metric …) is listed in ``skipped`` with the reason, not silently dropped.
    """
    run = open_run(run_dir)
    chosen = list(metrics) if metrics is not None else default_metrics()
    roles = {str(a["name"]): str(a.get("role", "")) for a in run.manifest.get("algorithms", ())}
    if algorithms is not None:
        unknown = sorted(set(algorithms) - set(roles))
        if unknown:
            from redrive.errors import ConfigError

            msg = f"{run.path}: no algorithm {', '.join(unknown)} (run has: {', '.join(roles)})"
            raise ConfigError(msg)
        roles = {k: v for k, v in roles.items() if k in algorithms}
    scored: list[Scored] = []
    skipped: list[Skipped] = []
    for metric in chosen:
        targets = (
            [""] if metric.role == "run" else [a for a, r in roles.items() if r == metric.role]
        )
        for algo in targets:
            data = EvalData(run, algo)
            missing = next((why for n in sorted(metric.needs) if (why := _has(run, data, n))), None)
            if missing is not None:
                skipped.append(Skipped(metric=metric.name, algorithm=algo, reason=missing))
                continue
            try:
                result = metric.evaluate(data)
            except (RedriveError, ValueError) as err:
                skipped.append(Skipped(metric=metric.name, algorithm=algo, reason=str(err)))
                continue
            logger.debug(
                "%s on %s: %s", metric.name, algo or "run", dict(list(result.values.items())[:3])
            )
            scored.append(Scored(metric=metric, algorithm=algo, result=result))
    folder = write_evaluation(run, scored)
    return EvaluationSummary(
        run=run, scored=tuple(scored), skipped=tuple(skipped), metrics_dir=folder
    )


def headline(scored: Scored) -> tuple[str, float, str]:
    """(name, value, unit) of a result's headline value."""
    key = scored.result.headline
    value = scored.result.values.get(key, math.nan)
    return key, value, scored.result.units.get(key, scored.metric.unit)
