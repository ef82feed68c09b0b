"""nuPlan's per-scenario score of a closed-loop run, and its mean over the scenarios of a batch
(CLS), as ``WeightedAverageMetricAggregator`` computes them with the closed-loop challenges'
configuration (see ``docs/metrics.md``)."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from redrive.evaluation.base import EvalData, Metric, MetricResult
from redrive.evaluation.closedloop._common import (
    COLLISION_DEFAULTS,
    collision_params,
    collision_score,
    find_collisions,
    scene,
)
from redrive.evaluation.closedloop.collisions import TTC_DEFAULTS, time_to_collision_series
from redrive.evaluation.closedloop.deviation import with_deviation
from redrive.evaluation.closedloop.motion import (
    COMFORT_DEFAULTS,
    PROGRESS_DEFAULTS,
    comfort_kinematics,
    comfort_verdicts,
    progress_ratio,
)
from redrive.evaluation.closedloop.road import (
    DAC_DEFAULTS,
    DDC_DEFAULTS,
    SL_DEFAULTS,
    drivable_area_score,
    driving_direction_score,
    speed_limit_score,
)
from redrive.types import Role

__all__ = ["MULTIPLIERS", "WEIGHTED", "NuplanScenarioScore", "nuplan_scenario_score"]

#: ``multiple_metrics`` of ``closed_loop_{non,}reactive_agents_weighted_average.yaml``: their
#: scores multiply the weighted average (driving direction's 0.5 included, as it is).
MULTIPLIERS = (
    "no_ego_at_fault_collisions",
    "drivable_area_compliance",
    "ego_is_making_progress",
    "driving_direction_compliance",
)
#: ``metric_weights`` of the same files, name → the parameter holding its weight.
WEIGHTED = {
    "ego_progress_along_expert_route": "weight_progress",
    "time_to_collision_within_bound": "weight_ttc",
    "speed_limit_compliance": "weight_speed_limit",
    "ego_is_comfortable": "weight_comfort",
}


def nuplan_scenario_score(
    scores: Mapping[str, float | None], weights: Mapping[str, float]
) -> tuple[float, float, float]:
    """(score, multiplier, weighted average) of one scenario: nuPlan's
    ``WeightedAverageMetricAggregator._compute_scenario_score``.

    ``scores``: metric name → its score (None: not computed, left out as the devkit leaves out a
    metric whose score is None); the names in :data:`MULTIPLIERS` multiply, every other one is
    averaged with its weight from ``weights`` (``weights["default"]`` for the others); the
    average is 0 when the weights sum to 0.
    """
    multiplier = 1.0
    total = weight_sum = 0.0
    for name, value in scores.items():
        if value is None:
            continue
        if name in MULTIPLIERS:
            multiplier *= value
        else:
            w = float(weights.get(name, weights.get("default", 1.0)))
            weight_sum += w
            total += w * value
    average = total / weight_sum if weight_sum else 0.0
    return multiplier * average, multiplier, average


class NuplanScenarioScore(Metric):
    """nuPlan's closed-loop scenario score:

    ``score = NC · DAC · MP · DDC · (5·EP + 5·TTC + 4·SL + 2·C) / 16``

    NC ``no_ego_at_fault_collisions`` (1, 0.5, 0), DAC ``drivable_area_compliance`` (1/0), MP
    ``ego_is_making_progress`` (1/0), DDC ``driving_direction_compliance`` (1, 0.5, 0), EP
    ``ego_progress_along_expert_route`` ([0, 1]), TTC ``time_to_collision_within_bound`` (1/0),
    SL ``speed_limit_compliance`` ([0, 1]), C ``ego_is_comfortable`` (1/0) — each computed here
    by the same functions as its own metric (``at_fault_collisions``, ``drivable_area``,
    ``ego_progress``, ``driving_direction``, ``time_to_collision``, ``speed_limit``,
    ``comfort``) with the same default parameters, never read from stored values. A part that
    cannot be computed (comfort on fewer than 4 states) is left out of the average, as the
    devkit leaves out a score of None.

    Values: ``nuplan_scenario_score`` (headline), ``multiplier``, ``weighted_average``, each part
    under its nuPlan name, and in a log-backed closed loop ``deviated_frames``. Pooled over the
    logs of a batch by their plain mean (each scenario counts once): nuPlan's final score,
    the closed-loop score ``cls``.
    """

    name: ClassVar[str] = "nuplan_scenario_score"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego", "ground_truth", "road_map"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True
    pooling: ClassVar[str] = "scenario_mean"
    pooled_name: ClassVar[str | None] = "cls"
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {
            **COLLISION_DEFAULTS,
            **TTC_DEFAULTS,
            **DAC_DEFAULTS,
            **DDC_DEFAULTS,
            **SL_DEFAULTS,
            **PROGRESS_DEFAULTS,
            **COMFORT_DEFAULTS,
            "min_progress_ratio": 0.2,
            "weight_progress": 5.0,
            "weight_ttc": 5.0,
            "weight_speed_limit": 4.0,
            "weight_comfort": 2.0,
        }
    )

    def evaluate(self, data: EvalData) -> MetricResult:
        p = self.params
        sc = scene(data, p)
        collisions = find_collisions(sc, stopped_speed_mps=float(p["stopped_speed_mps"]))
        ep, _, _, _, _ = progress_ratio(data, p)
        _, ttc_values, _ = time_to_collision_series(data, p, collisions)
        min_ttc = float(ttc_values.min()) if ttc_values.size else np.inf
        kin = comfort_kinematics(sc.ego, p)
        comfortable = (
            None
            if kin is None
            else float(np.logical_and.reduce(list(comfort_verdicts(kin, p).values())).all())
        )
        scores: dict[str, float | None] = {
            "no_ego_at_fault_collisions": collision_score(collisions, **collision_params(p)),
            "drivable_area_compliance": drivable_area_score(data, p)[0],
            "ego_is_making_progress": float(ep >= float(p["min_progress_ratio"])),
            "driving_direction_compliance": driving_direction_score(data, p)[0],
            "ego_progress_along_expert_route": ep,
            "time_to_collision_within_bound": float(min_ttc > float(p["least_min_ttc_s"])),
            "speed_limit_compliance": speed_limit_score(data, p)[0],
            "ego_is_comfortable": comfortable,
        }
        weights = {name: float(p[key]) for name, key in WEIGHTED.items()}
        score, multiplier, average = nuplan_scenario_score(scores, weights)
        values = {
            "nuplan_scenario_score": score,
            "multiplier": multiplier,
            "weighted_average": average,
            **{k: (np.nan if v is None else v) for k, v in scores.items()},
        }
        return with_deviation(MetricResult(values=values), data, sc.ego.frames)
