"""The aggregate closed-loop score, structured as NAVSIM's PDM score (see ``docs/metrics.md``)."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from redrive.evaluation.base import EvalData, Metric, MetricResult
from redrive.evaluation.closedloop._common import collision_score, find_collisions, scene
from redrive.evaluation.closedloop.collisions import TTC_DEFAULTS, time_to_collision_series
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
    drivable_area_score,
    driving_direction_score,
)
from redrive.types import Role

__all__ = ["PdmScore"]


class PdmScore(Metric):
    """NAVSIM's PDM score over a whole run: multiplicative gates × a weighted average,

    ``pdm_score = NC · DAC · MP · (5·TTC + 5·EP + 2·C + 0·DDC) / 12``

    with NC = ``at_fault_collisions``' score (1, 0.5, 0), DAC = ``drivable_area`` (1/0),
    MP = nuPlan's ``ego_is_making_progress`` gate (EP > 0.2; NAVSIM scores 4 s proposals against
    PDM-Closed's progress instead, where a stopped ego scores EP = 0 — over a whole run the
    logged route is the reference, so nuPlan's gate keeps a never-moving ego from scoring 7/12),
    TTC = ``time_to_collision``'s within-bound (1/0), EP = ``ego_progress``'s ratio, C =
    ``comfort`` (1/0), DDC = ``driving_direction`` (weight 0, as NAVSIM v1; reported).  Each
    part is computed here by the same functions as its own metric (never read from stored
    values), with the same default parameters.

    Values: ``pdm_score`` (headline) and each part (``nc``, ``dac``, ``mp``, ``ttc``, ``ep``,
    ``c``, ``ddc``). Needs a road map (DAC is a gate).
    """

    name: ClassVar[str] = "pdm_score"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego", "ground_truth", "road_map"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True  # the headline; per value in the result
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {
            **TTC_DEFAULTS,
            **DAC_DEFAULTS,
            **DDC_DEFAULTS,
            **PROGRESS_DEFAULTS,
            **COMFORT_DEFAULTS,
            "min_progress_ratio": 0.2,
            "weight_ttc": 5.0,
            "weight_ep": 5.0,
            "weight_c": 2.0,
            "weight_ddc": 0.0,
        }
    )

    def evaluate(self, data: EvalData) -> MetricResult:
        p = self.params
        collisions = find_collisions(scene(data, p))
        nc = collision_score(collisions)
        dac, _, _ = drivable_area_score(data, p)
        ddc, _, _ = driving_direction_score(data, p)
        ep, _, _, _, _ = progress_ratio(data, p)
        mp = float(ep > float(p["min_progress_ratio"]))
        _, ttc_values, _ = time_to_collision_series(data, p, collisions)
        min_ttc = float(ttc_values.min()) if ttc_values.size else np.inf
        ttc = float(min_ttc > float(p["least_min_ttc_s"]))
        kin = comfort_kinematics(scene(data, p).ego, p)
        c = 1.0 if kin is None else float(all(v.all() for v in comfort_verdicts(kin, p).values()))
        weights = {k: float(p[f"weight_{k}"]) for k in ("ttc", "ep", "c", "ddc")}
        parts = {"ttc": ttc, "ep": ep, "c": c, "ddc": ddc}
        weighted = sum(weights[k] * parts[k] for k in weights) / sum(weights.values())
        score = nc * dac * mp * weighted
        return MetricResult(
            values={"pdm_score": score, "nc": nc, "dac": dac, "mp": mp, **parts},
        )
