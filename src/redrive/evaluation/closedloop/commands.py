"""What moved the ego in a closed-loop run: how often the fallback had to brake because the
pipeline gave nothing usable (a NaN or empty path, a path in a frame the closed loop cannot
follow, a failed step, no command) — redrive's own measure, not one of nuPlan's (nuPlan's
planners never hand the simulator an unusable trajectory; see ``docs/metrics.md``)."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from redrive.evaluation.base import Bookmark, EvalData, Metric, MetricResult
from redrive.types import Role

__all__ = ["FallbackCommands"]


class FallbackCommands(Metric):
    """Frames in which the closed loop's fallback braked instead of the pipeline driving.

    Values: ``fallback_frames`` (headline; lower is better), ``fallback_ratio`` (of the run's
    closed-loop frames; lower is better), ``driven_frames`` (frames moved by a control
    command or the tracker on a planned path; higher is better). Per frame ``fallback`` (1 where
    the fallback braked). Bookmarks ``fallback`` at the first frame of each stretch of fallback
    frames, with the reason the closed loop recorded.
    """

    name: ClassVar[str] = "closed_loop_fallback"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"closed_loop"})
    unit: ClassVar[str] = "frames"
    higher_is_better: ClassVar[bool] = False
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType({})

    def evaluate(self, data: EvalData) -> MetricResult:
        table = data.closed_loop()
        frames = np.asarray(table.column("frame_index").to_numpy(), dtype=np.int64)
        sources = table.column("source").to_pylist()
        reasons = table.column("reason").to_pylist()
        fallback = np.array([s == "fallback" for s in sources], dtype=bool)
        n = int(fallback.size)
        bookmarks = [
            Bookmark(
                frame_index=int(frames[i]),
                kind="fallback",
                detail=f"the fallback brakes: {reasons[i]}",
                severity=float(_stretch(fallback, i)),
            )
            for i in range(n)
            if fallback[i] and (i == 0 or not fallback[i - 1])
        ]
        count = int(fallback.sum())
        return MetricResult(
            values={
                "fallback_frames": float(count),
                "fallback_ratio": count / n if n else float("nan"),
                "driven_frames": float(n - count),
            },
            units={"fallback_ratio": "ratio"},
            higher_is_better={"driven_frames": True},
            per_frame={"fallback": (frames, fallback.astype(np.float64))},
            bookmarks=bookmarks,
        )


def _stretch(flags: np.ndarray[Any, np.dtype[np.bool_]], start: int) -> int:
    """The number of consecutive True flags from ``start`` on."""
    rest = ~flags[start:]
    return int(np.argmax(rest)) if rest.any() else int(flags.size - start)
