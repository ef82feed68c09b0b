"""At-fault collisions and time-to-collision of the driven ego (nuPlan's definitions; see
``docs/metrics.md``)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from redrive.evaluation._kinematics import rectangles_overlap
from redrive.evaluation.base import Bookmark, EvalData, Metric, MetricResult
from redrive.evaluation.closedloop._common import (
    AHEAD_ANGLE_RAD,
    BEHIND_ANGLE_RAD,
    COLLISION_DEFAULTS,
    Collision,
    bearing_rad,
    collision_params,
    collision_score,
    corners,
    find_collisions,
    road_index,
    scene,
    series,
)
from redrive.evaluation.closedloop.deviation import with_deviation
from redrive.types import Role

__all__ = ["AtFaultCollisions", "TimeToCollision", "time_to_collision_series"]

#: nuPlan ``compute_time_to_collision``'s ``stopped_speed_threshold``, m/s.
TTC_STOPPED_SPEED_MPS = 5e-3


class AtFaultCollisions(Metric):
    """nuPlan ``no_ego_at_fault_collisions``: contacts of the ego footprint with ground-truth
    boxes, split into stopped_ego, stopped_track, active_front, active_rear, active_lateral;
    at fault: active_front, stopped_track, and active_lateral while the footprint is not in one
    common or connected lane (nuPlan's "in multiple lanes or nondrivable area", on the map's lane
    graph: :mod:`redrive.evaluation.closedloop.lanes`; without a map a lateral collision is
    never at fault). Score thresholds ``max_violations_vru`` 0, ``max_violations_vehicle`` 0,
    ``max_violations_object`` 1; stopped below ``stopped_speed_mps`` 0.05 m/s.

    Values: ``no_at_fault_collisions`` (headline: nuPlan's score, 1, 0.5 or 0),
    ``at_fault_collisions``, ``collisions`` and one count per kind. Per frame:
    ``collision``, ``at_fault_collision`` (new contacts). Bookmarks ``collision``.
    """

    name: ClassVar[str] = "at_fault_collisions"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego", "ground_truth"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True
    defaults: ClassVar[Mapping[str, Any]] = COLLISION_DEFAULTS

    def evaluate(self, data: EvalData) -> MetricResult:
        sc = scene(data, self.params)
        found = find_collisions(sc, stopped_speed_mps=float(self.params["stopped_speed_mps"]))
        frames = sorted(sc.objects)
        new = {f: [c for c in found if c.frame == f] for f in frames}
        values = {
            "no_at_fault_collisions": collision_score(found, **collision_params(self.params)),
            "at_fault_collisions": float(sum(c.at_fault for c in found)),
            "collisions": float(len(found)),
        }
        for kind in (
            "stopped_ego",
            "stopped_track",
            "active_front",
            "active_rear",
            "active_lateral",
        ):
            values[kind] = float(sum(c.kind == kind for c in found))
        counts = {k: "collisions" for k in values if k != "no_at_fault_collisions"}
        result = MetricResult(
            values=values,
            units=counts,
            higher_is_better=dict.fromkeys(counts, False),
            per_frame={
                "collision": series(frames, [float(bool(new[f])) for f in frames]),
                "at_fault_collision": series(
                    frames, [float(any(c.at_fault for c in new[f])) for f in frames]
                ),
            },
            bookmarks=[_bookmark(c) for c in found],
        )
        return with_deviation(result, data, np.asarray(frames, dtype=np.int64))


def _bookmark(c: Collision) -> Bookmark:
    return Bookmark(
        frame_index=c.frame,
        kind="collision",
        detail=(
            f"ego hits {c.object_class.value} {c.object_id} ({c.kind}, "
            f"{'at fault' if c.at_fault else 'not at fault'}, {c.relative_speed_mps:.1f} m/s relative)"
        ),
        severity=c.relative_speed_mps + (100.0 if c.at_fault else 0.0),
    )


def time_to_collision_series(
    data: EvalData, params: Mapping[str, Any], collisions: Sequence[Collision] | None = None
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], dict[int, int]]:
    """nuPlan's per-sample TTC: frames with ground truth, TTC in s (``inf``: none within the
    horizon or the ego stopped) and the object hit per frame with a finite TTC."""
    sc = scene(data, params)
    road = road_index(data)
    found = (
        find_collisions(sc, stopped_speed_mps=float(params["stopped_speed_mps"]))
        if collisions is None
        else list(collisions)
    )
    step, horizon = float(params["ttc_step_s"]), float(params["ttc_horizon_s"])
    times = np.arange(step, horizon, step)
    at_fault_frames = {c.frame for c in found if c.at_fault}
    collided_at: dict[int, int] = {c.object_id: c.frame for c in found}
    ego = sc.ego
    frames: list[int] = []
    values: list[float] = []
    hit: dict[int, int] = {}
    for i, frame in enumerate(ego.frames.tolist()):
        objs = sc.objects.get(frame)
        if objs is None:
            continue
        frames.append(frame)
        if frame in at_fault_frames:
            values.append(0.0)
            continue
        speed = float(ego.speed_mps[i])
        if len(objs) == 0 or speed <= float(params["ttc_stopped_speed_mps"]):
            values.append(math.inf)
            continue
        xy, h = ego.xy[i], float(ego.heading_rad[i])
        angle = bearing_rad(xy, h, objs.center_m[:, :2])
        wide = bool(sc.straddling.get(frame)) or (road is not None and road.in_intersection(xy))
        keep = np.array(
            [collided_at.get(int(o), frame + 1) > frame for o in objs.object_id.tolist()],
            dtype=bool,
        ) & ((angle <= AHEAD_ANGLE_RAD) | (wide & (angle <= BEHIND_ANGLE_RAD)))
        idx = np.flatnonzero(keep)
        if idx.size == 0 or times.size == 0:
            values.append(math.inf)
            continue
        ego_v = speed * np.array([math.cos(h), math.sin(h)])
        ego_c = sc.corners[i][None] + times[:, None, None] * ego_v  # (T, 4, 2)
        base = corners(objs)[idx]  # (M, 4, 2)
        obj_c = (
            base[None] + times[:, None, None, None] * objs.velocity_mps[idx, :2][None, :, None, :]
        )
        contact = rectangles_overlap(ego_c[:, None], obj_c)  # (T, M)
        first = np.flatnonzero(contact.any(axis=1))
        if first.size == 0:
            values.append(math.inf)
            continue
        t = int(first[0])
        values.append(float(times[t]))
        hit[frame] = int(objs.object_id[idx[int(np.argmax(contact[t]))]])
    return np.array(frames, dtype=np.int64), np.array(values, dtype=np.float64), hit


TTC_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {
        **COLLISION_DEFAULTS,
        "ttc_step_s": 0.1,
        "ttc_horizon_s": 3.0,
        "least_min_ttc_s": 0.95,
        "ttc_stopped_speed_mps": TTC_STOPPED_SPEED_MPS,
    }
)


class TimeToCollision(Metric):
    """nuPlan ``time_to_collision_within_bound``: at each frame the ego (along its heading at
    its speed) and the relevant ground-truth objects (at their velocity) are moved forward in
    ``ttc_step_s`` steps up to ``ttc_horizon_s``; TTC is the first step at which they touch.

    Values: ``ttc_within_bound`` (headline: 1 when the smallest TTC is above
    ``least_min_ttc_s``, else 0), ``min_ttc_s``, ``low_ttc_frames``. Per frame ``ttc_s``
    (``inf`` when nothing is hit). Bookmarks ``low_ttc``.
    """

    name: ClassVar[str] = "time_to_collision"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego", "ground_truth"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True
    defaults: ClassVar[Mapping[str, Any]] = TTC_DEFAULTS

    def evaluate(self, data: EvalData) -> MetricResult:
        frames, ttc, hit = time_to_collision_series(data, self.params)
        bound = float(self.params["least_min_ttc_s"])
        low = ttc <= bound
        min_ttc = float(ttc.min()) if ttc.size else math.inf
        result = MetricResult(
            values={
                "ttc_within_bound": float(min_ttc > bound),
                "min_ttc_s": min_ttc,
                "low_ttc_frames": float(low.sum()),
            },
            units={"min_ttc_s": "s", "low_ttc_frames": "frames"},
            higher_is_better={"low_ttc_frames": False},
            per_frame={"ttc_s": (frames, ttc)},
            bookmarks=[
                Bookmark(
                    frame_index=int(f),
                    kind="low_ttc",
                    detail=f"TTC {v:.1f} s"
                    + (f" to object {hit[int(f)]}" if int(f) in hit else " (at-fault collision)"),
                    severity=1.0 / max(float(v), 1e-3),
                )
                for f, v in zip(frames[low], ttc[low], strict=True)
            ],
        )
        return with_deviation(result, data, frames)
