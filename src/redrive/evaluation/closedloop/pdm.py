"""NAVSIM's scores of a planner: PDMS (v1.1) and EPDMS (v2), by pseudo-simulation of its
trajectory every 0.5 s (``navsim_run``; definitions and sources in ``docs/metrics.md``)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from redrive.errors import ConfigError
from redrive.evaluation.base import Bookmark, EvalData, Metric, MetricResult, MetricSkipped
from redrive.evaluation.closedloop._common import EGO_DEFAULTS
from redrive.evaluation.closedloop.navsim_closed import PDM_CLOSED_DEFAULTS
from redrive.evaluation.closedloop.navsim_run import V1_KEYS, V2_KEYS, SceneScore, navsim_scenes
from redrive.evaluation.closedloop.navsim_score import SCORER_DEFAULTS
from redrive.evaluation.closedloop.navsim_sim import SIM_DEFAULTS
from redrive.types import LightState, Role

__all__ = ["NavsimEpdms", "NavsimPdms", "light_states"]

_COMMON: Mapping[str, Any] = MappingProxyType(
    {
        **EGO_DEFAULTS,
        **SIM_DEFAULTS,
        **SCORER_DEFAULTS,
        **PDM_CLOSED_DEFAULTS,
        "scene_interval_s": 0.5,
        "route_extension_m": 100.0,
    }
)


def _check(name: str, p: Mapping[str, Any]) -> None:
    """Parameters NAVSIM's simulation cannot run with: a ConfigError naming them."""
    bad = [
        f"{k} must be > 0, got {p[k]!r}"
        for k in ("interval_s", "scene_interval_s", "ego_length_m", "ego_width_m", "wheel_base_m")
        if not float(p[k]) > 0
    ]
    if int(p["num_poses"]) < 3:
        bad.append(
            f"num_poses must be >= 3 (the LQR fits a jerk over them), got {p['num_poses']!r}"
        )
    if int(p["tracking_horizon"]) < 2:
        bad.append(f"tracking_horizon must be >= 2 steps, got {p['tracking_horizon']!r}")
    if bad:
        raise ConfigError(f"metric {name!r}: " + "; ".join(bad))


def light_states(data: EvalData) -> dict[int, dict[str, LightState]] | None:
    """frame → light id → state, from the run's logged traffic lights
    (``TrafficData.traffic_lights``) when the run stores them; None when it does not."""
    # EvalData.traffic_lights (cached) or Run.traffic_lights where this redrive has them
    reader = getattr(data, "traffic_lights", None) or getattr(data.run, "traffic_lights", None)
    if not callable(reader):
        return None
    raw = reader()
    if not isinstance(raw, Mapping):
        return None
    return {int(f): {str(t.id): t.state for t in lights} for f, lights in raw.items()}


def _bookmarks(scenes: list[SceneScore], headline: str, keys: tuple[str, ...]) -> list[Bookmark]:
    """A ``navsim_infraction`` at each proposal a binary sub-score fails (0), naming them."""
    out = []
    for s in scenes:
        failed = [k for k in keys if k != "ep" and s.parts.get(k) == 0.0]
        if failed:
            out.append(
                Bookmark(
                    frame_index=s.frame,
                    kind="navsim_infraction",
                    detail=f"{headline} {s.score:.2f}: {', '.join(failed)} 0",
                    severity=1.0 - s.score,
                )
            )
    return out


def _result(scenes: list[SceneScore], headline: str, keys: tuple[str, ...]) -> MetricResult:
    if not scenes:
        msg = (
            "no proposal could be scored: NAVSIM needs a planner trajectory, the ego's ground "
            "truth and 4 s of log after it, and a route lane near the ego"
        )
        raise MetricSkipped(msg)
    frames = np.array([s.frame for s in scenes], dtype=np.int64)
    scores = np.array([s.score for s in scenes], dtype=np.float64)
    values: dict[str, float] = {headline: float(scores.mean())}
    per_frame = {headline: (frames, scores)}
    for k in keys:
        col = np.array([s.parts[k] for s in scenes], dtype=np.float64)
        values[k] = float(np.nanmean(col)) if np.isfinite(col).any() else math.nan
        per_frame[k] = (frames, col)
    values["proposals"] = float(len(scenes))
    return MetricResult(
        values=values,
        per_frame=per_frame,
        units={"proposals": "count"},
        higher_is_better={"proposals": None},
        bookmarks=_bookmarks(scenes, headline, keys),
    )


class NavsimPdms(Metric):
    """NAVSIM v1.1's PDM score of a planner, per 0.5-s proposal and their mean:

    ``PDMS = NC · DAC · (5·EP + 5·TTC + 2·C) / 12`` of each 4-s trajectory tracked by NAVSIM's
    LQR on its kinematic bicycle and scored against the log's agents of the next 5 s, EP
    relative to the PDM-Closed reference's progress (DDC is computed, weight 0).

    Values: ``navsim_pdms`` (headline: the mean over proposals, NAVSIM's average), the mean of
    each sub-score (``nc``, ``dac``, ``ep``, ``ttc``, ``c``, ``ddc``), ``proposals``; per-frame
    series of each at the proposals' frames; a ``navsim_infraction`` bookmark where a binary
    sub-score fails."""

    name: ClassVar[str] = "navsim_pdms"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = Role.PLANNING
    needs: ClassVar[frozenset[str]] = frozenset({"paths", "ego", "ground_truth", "road_map"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True
    defaults: ClassVar[Mapping[str, Any]] = _COMMON

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        _check(self.name, self.params)

    def evaluate(self, data: EvalData) -> MetricResult:
        scenes = navsim_scenes(data, version="v1", params=self.params)
        return _result(scenes, "navsim_pdms", V1_KEYS)


class NavsimEpdms(Metric):
    """NAVSIM v2's extended PDM score of a planner, per 0.5-s proposal and their mean:

    ``EPDMS = NC · DAC · DDC · TLC · (5·EP + 5·TTC + 2·LK + 2·HC + 2·EC) / 16`` (EC left out,
    weights 14, for a proposal without one 0.5 s before it), with v2's human filter: a
    sub-score the logged ego's own future also fails is set to 1.

    Values: ``navsim_epdms`` (headline), the mean of each sub-score (``nc``, ``dac``, ``ddc``,
    ``tlc``, ``ep``, ``ttc``, ``lk``, ``hc``, ``ec``), ``proposals``; per-frame series."""

    name: ClassVar[str] = "navsim_epdms"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = Role.PLANNING
    needs: ClassVar[frozenset[str]] = frozenset({"paths", "ego", "ground_truth", "road_map"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {**_COMMON, "human_penalty_filter": True}
    )

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        _check(self.name, self.params)

    def evaluate(self, data: EvalData) -> MetricResult:
        scenes = navsim_scenes(
            data, version="v2", params=self.params, light_states=light_states(data)
        )
        return _result(scenes, "navsim_epdms", (*V2_KEYS, "ec"))
