"""``redrive bench eval``: the CPU seconds of each metric on a run.

The metrics are evaluated as ``redrive evaluate`` evaluates them (one ``EvalData`` per
algorithm shared by the metrics, in the order given), after the run's tables are read, each
timed with ``time.process_time`` (the process's CPU over all threads); a metric's figure is
what it costs after the metrics before it (work they share, as NAVSIM's PDMS and EPDMS share
their simulated proposals, counts for the first).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from redrive.evaluation import EvalData, Metric, MetricSkipped
from redrive.results import open_run

__all__ = ["EvalBench", "MetricCost", "bench_eval"]


@dataclass(frozen=True, slots=True, kw_only=True)
class MetricCost:
    metric: str
    algorithm: str
    cpu_s: float
    outcome: str  # "scored", "skipped: …" or "error: …"


@dataclass(frozen=True, slots=True, kw_only=True)
class EvalBench:
    run: str
    load_cpu_s: float
    costs: tuple[MetricCost, ...]

    @property
    def metrics_cpu_s(self) -> float:
        return sum(c.cpu_s for c in self.costs)

    def to_json(self) -> dict[str, Any]:
        return {
            "run": self.run,
            "load_cpu_s": self.load_cpu_s,
            "metrics_cpu_s": self.metrics_cpu_s,
            "metrics": [dataclasses.asdict(c) for c in self.costs],
        }


def bench_eval(run_dir: str | Path, metrics: Sequence[Metric]) -> EvalBench:
    """Time each of ``metrics`` on the run at ``run_dir`` (nothing is stored)."""
    run = open_run(run_dir)
    roles = {a.name: a.role.value for a in run.manifest.algorithms}
    datas: dict[str, EvalData] = {}
    t0 = time.process_time()
    for algo in ["", *roles]:
        data = datas[algo] = EvalData(run, algo)
        data.frames()
        data.ego()
        data.logged_ego()
        data.ground_truth()
        data.road_map()
        if roles.get(algo) == "planning":
            data.paths()
    load = time.process_time() - t0
    costs: list[MetricCost] = []
    for metric in metrics:
        targets = (
            [""] if metric.role is None else [a for a, r in roles.items() if r == metric.role.value]
        )
        for algo in targets:
            t = time.process_time()
            try:
                metric.evaluate(datas[algo])
                outcome = "scored"
            except MetricSkipped as skip:
                outcome = f"skipped: {skip.reason}"
            except Exception as err:
                outcome = f"error: {type(err).__name__}: {err}"
            cpu_s = time.process_time() - t
            costs.append(
                MetricCost(metric=metric.name, algorithm=algo, cpu_s=cpu_s, outcome=outcome)
            )
    return EvalBench(run=str(run.path), load_cpu_s=load, costs=tuple(costs))
