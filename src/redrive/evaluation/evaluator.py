"""Evaluate a run: every metric against every algorithm of its role, stored with the run.

>>> summary = evaluate_run("runs/first")        # doctest: +SKIP
>>> summary.scored[0].result.values             # doctest: +SKIP
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from redrive.errors import ConfigError
from redrive.evaluation.base import NEED_SOURCES, EvalData, Metric, MetricSkipped
from redrive.evaluation.registry import installed_metrics
from redrive.evaluation.store import MetricOutcome, Scored, closed_loop_run, write_evaluation
from redrive.results import MAP_NAME, Run, open_run

__all__ = [
    "EvaluationSummary",
    "MetricOutcome",
    "default_metrics",
    "evaluate_run",
    "headline",
    "subjects",
]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class EvaluationSummary:
    """What one ``evaluate_run`` did: the results, the skips (the metric does not apply, with
    why) and the failures (the metric raised: a bug to fix, never silent)."""

    run: Run
    scored: tuple[Scored, ...]
    skipped: tuple[MetricOutcome, ...]
    failed: tuple[MetricOutcome, ...]
    metrics_dir: Path

    @property
    def bookmarks(self) -> int:
        return sum(len(s.result.bookmarks) for s in self.scored)

    @property
    def closed_loop(self) -> bool:
        """The run's ego was driven by its pipeline (else the ego is the log's)."""
        return closed_loop_run(self.run)


def default_metrics() -> list[Metric]:
    """One instance, with default parameters, of every installed metric."""
    return [cls() for cls in installed_metrics().values()]


#: the role whose algorithms produce each output a metric may need.
_OUTPUT_ROLES = {"detections": "perception", "paths": "planning", "commands": "control"}


class _Provides:
    """What a run provides, read once per evaluation: which needs each algorithm meets."""

    def __init__(self, run: Run, roles: Mapping[str, str]) -> None:
        self.run = run
        self.roles = roles
        steps = run.table("steps")
        ok = [s == "ok" for s in steps.column("status").to_pylist()]
        self.ok_algorithms = {
            a for a, good in zip(steps.column("algorithm").to_pylist(), ok, strict=True) if good
        }
        self.has_steps = steps.num_rows > 0
        frames = run.table("frames")
        self.has_frames = frames.num_rows > 0
        self.has_ground_truth = run.table("ground_truth").num_rows > 0 or (
            self.has_frames and frames.column("n_ground_truth").null_count < frames.num_rows
        )
        self.has_ego = run.table("ego").num_rows > 0
        self.has_logged_ego = run.table("ego_logged").num_rows > 0
        self.has_closed_loop = run.table("closed_loop").num_rows > 0
        self.has_traffic_lights = run.table("traffic_lights").num_rows > 0
        # the file's presence: a damaged map is the metric's error to report, with the file
        self.has_road_map = (run.path / MAP_NAME).is_file()

    def missing(self, need: str, algorithm: str) -> str | None:
        """None if the run provides ``need`` for ``algorithm``, else why not."""
        have = {
            "ground_truth": self.has_ground_truth,
            "ego": self.has_ego,
            "logged_ego": self.has_logged_ego,
            "closed_loop": self.has_closed_loop,
            "road_map": self.has_road_map,
            "traffic_lights": self.has_traffic_lights,
            "steps": self.has_steps,
            "frames": self.has_frames,
        }.get(need)
        if have is None:  # detections, paths, commands: an algorithm's own output
            role = _OUTPUT_ROLES[need]
            if algorithm:
                have = self.roles.get(algorithm) == role and algorithm in self.ok_algorithms
                what = f"{algorithm!r} produced no {need}"
            else:
                have = any(r == role and a in self.ok_algorithms for a, r in self.roles.items())
                what = f"the run has no {need}"
        else:
            what = f"the run has no {need.replace('_', ' ')}"
        if have:
            return None
        # the log had it, on another clock than the frames' (the run's manifest says why)
        source = {"ego": "vehicle_state", "ground_truth": "ground_truth"}.get(need, "")
        if why := self.run.manifest.pipeline.unusable_inputs.get(source):
            return f"{what}: {why}"
        if need == "road_map":
            return "no road map in the run (runs of a synthetic scenario or its log store one; recorded logs have none)"
        return f"{what} (needs {NEED_SOURCES.get(need, need)})"


def evaluate_run(
    run_dir: str | Path,
    *,
    metrics: Sequence[Metric] | None = None,
    algorithms: Sequence[str] | None = None,
) -> EvaluationSummary:
    """Run ``metrics`` (default: every installed one) on the algorithms of their role and store
    each metric's results in the run directory, replacing only that metric's earlier results
    (other stored metrics stay).

    A metric whose declared ``needs`` the run does not meet, or that raises
    :class:`MetricSkipped`, is listed in ``skipped`` with the reason.  A metric that raises
    anything else is listed in ``failed`` with the exception; the other metrics still run and
    are stored.
    """
    run = open_run(run_dir)
    chosen = list(metrics) if metrics is not None else default_metrics()
    roles = {a.name: a.role.value for a in run.manifest.algorithms}
    if algorithms is not None:
        unknown = sorted(set(algorithms) - set(roles))
        if unknown:
            msg = f"{run.path}: no algorithm {', '.join(unknown)} (run has: {', '.join(roles)})"
            raise ConfigError(msg)
        roles = {k: v for k, v in roles.items() if k in algorithms}
    provides = _Provides(run, roles)
    scored: list[Scored] = []
    outcomes: list[MetricOutcome] = []
    # one EvalData per algorithm, shared by the metrics: each table is read once, and what
    # metrics compute in common (closed-loop scenes, NAVSIM's simulated proposals) once
    datas: dict[str, EvalData] = {}
    for metric in chosen:
        targets = (
            [""] if metric.role is None else [a for a, r in roles.items() if r == metric.role.value]
        )
        for algo in targets:
            missing = next(
                (why for n in sorted(metric.needs) if (why := provides.missing(n, algo))), None
            )
            if missing is not None:
                outcomes.append(MetricOutcome(metric=metric.name, algorithm=algo, reason=missing))
                continue
            try:
                data = datas.get(algo)
                if data is None:
                    data = datas[algo] = EvalData(run, algo)
                result = metric.evaluate(data)
            except MetricSkipped as skip:
                outcomes.append(
                    MetricOutcome(metric=metric.name, algorithm=algo, reason=skip.reason)
                )
                continue
            except Exception as err:  # a metric's bug: reported, never silent
                logger.debug("metric %s on %s raised", metric.name, algo or "run", exc_info=True)
                outcomes.append(
                    MetricOutcome(
                        metric=metric.name,
                        algorithm=algo,
                        reason=f"{type(err).__name__}: {err}",
                        error=True,
                    )
                )
                continue
            logger.debug(
                "%s on %s: %s", metric.name, algo or "run", dict(list(result.values.items())[:3])
            )
            scored.append(Scored(metric=metric, algorithm=algo, result=result))
    folder = write_evaluation(run, scored, metrics=chosen, outcomes=outcomes)
    return EvaluationSummary(
        run=run,
        scored=tuple(scored),
        skipped=tuple(o for o in outcomes if not o.error),
        failed=tuple(o for o in outcomes if o.error),
        metrics_dir=folder,
    )


def headline(scored: Scored) -> tuple[str, float, str]:
    """(name, value, unit) of a result's headline value."""
    key = scored.result.headline
    value = scored.result.values.get(key, math.nan)
    return key, value, scored.result.units.get(key, scored.metric.unit)


def subjects(scored: Scored, *, closed_loop: bool) -> dict[str, str]:
    """value name → whose motion or output it scores (stored as ``subject``): the algorithm's
    name, ``run`` for a whole-run metric, ``log`` for the logged ego of an open-loop run."""
    return {
        k: scored.metric.subject(
            scored.result, k, algorithm=scored.algorithm, closed_loop=closed_loop
        )
        for k in scored.result.values
    }
