"""Latency of a run: per algorithm, per stage and per frame, and deadline misses.

Definitions:

* An algorithm's latency is ``steps.latency_ns`` (wall time of its ``step``), over the steps
  that ran (every status but ``skipped``, as ``Run.summary()`` counts them).
* A stage's latency on a frame combines its algorithms' latencies on that frame:
  ``stage_combine="max"`` (default) — the engine runs the algorithms of one stage side by side
  (thread pool or worker processes, ``redrive.engine.core``), so the stage waits for the slowest;
  ``"sum"`` — for a pipeline that ran them one after another.
* The whole frame's latency is ``frames.wall_ns`` (engine wall time on the frame, including its
  own overhead).
* Percentiles p50/p95/p99 use ``numpy.percentile``'s default method (``"linear"``: Hyndman &
  Fan's type 7, linear interpolation between the two nearest ranks, as ``Run.summary()``); all
  in milliseconds.
* Deadline: ``deadline_s`` if given, else the driving sensor's period (``EvalData.frame_period_s``,
  the median time between frames): a real-time system must finish a frame before the next one
  arrives. A step or frame misses when its latency is strictly greater than the deadline.

Bookmarks: ``deadline_miss`` for every frame whose wall time exceeds the deadline (severity = ms
over the deadline; the detail names the slowest algorithm).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from redrive.errors import ConfigError
from redrive.evaluation.base import Bookmark, EvalData, Metric, MetricResult, Series
from redrive.types import Role

__all__ = ["Latency", "latency_stats_ms"]

F64 = npt.NDArray[np.float64]


def latency_stats_ms(latency_ms: npt.ArrayLike) -> dict[str, float]:
    """``{"p50_ms", "p95_ms", "p99_ms", "max_ms"}`` of ``latency_ms`` (numpy's default linear
    percentile); NaN each when empty."""
    x = np.asarray(latency_ms, dtype=np.float64).reshape(-1)
    if x.size == 0:
        return {"p50_ms": math.nan, "p95_ms": math.nan, "p99_ms": math.nan, "max_ms": math.nan}
    p50, p95, p99 = np.percentile(x, [50.0, 95.0, 99.0])
    return {
        "p50_ms": float(p50),
        "p95_ms": float(p95),
        "p99_ms": float(p99),
        "max_ms": float(x.max()),
    }


class Latency(Metric):
    """Per-algorithm, per-stage and whole-frame latency percentiles and deadline misses of a run.

    Parameters (defaults): ``deadline_s`` None (the driving sensor's period),
    ``stage_combine`` "max" ("max" | "sum").

    Values: ``frame_p95_ms`` (headline), ``frame_p50_ms``, ``frame_p99_ms``, ``frame_max_ms``,
    ``deadline_ms``, ``frame_deadline_misses``, ``frame_deadline_miss_fraction``; per algorithm
    ``p50_ms/ALGO``, ``p95_ms/ALGO``, ``p99_ms/ALGO``, ``max_ms/ALGO``, ``deadline_misses/ALGO``,
    ``deadline_miss_fraction/ALGO``; per stage the same four percentiles as
    ``p95_ms/stage:STAGE`` …. Misses are NaN when the deadline is unknown (fewer than two
    frames and no ``deadline_s``). Per-frame series: ``frame_ms``, ``latency_ms/ALGO``,
    ``latency_ms/stage:STAGE``.
    """

    name: ClassVar[str] = "latency"
    pooling: ClassVar[str] = "concatenate"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"steps", "frames"})
    unit: ClassVar[str] = "ms"
    higher_is_better: ClassVar[bool] = False
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {"deadline_s": None, "stage_combine": "max"}
    )

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        if self.params["stage_combine"] not in ("max", "sum"):
            msg = (
                f"metric 'latency': stage_combine must be 'max' or 'sum', "
                f"got {self.params['stage_combine']!r}"
            )
            raise ConfigError(msg)
        deadline = self.params["deadline_s"]
        if deadline is not None and not float(deadline) > 0:
            msg = f"metric 'latency': deadline_s must be > 0 seconds, got {deadline!r}"
            raise ConfigError(msg)

    def evaluate(self, data: EvalData) -> MetricResult:
        deadline_s = (
            float(self.params["deadline_s"])
            if self.params["deadline_s"] is not None
            else data.frame_period_s
        )
        deadline_ms = deadline_s * 1e3 if deadline_s > 0 else math.nan
        steps = data.steps()
        frames_tab = data.frames()
        status = np.asarray(steps.column("status").to_pylist(), dtype=object)
        ran = status != "skipped"
        s_frame = np.asarray(steps.column("frame_index").to_numpy(), dtype=np.int64)[ran]
        s_algo = np.asarray(steps.column("algorithm").to_pylist(), dtype=object)[ran]
        s_stage = np.asarray(steps.column("stage").to_pylist(), dtype=object)[ran]
        s_ms = np.asarray(steps.column("latency_ns").to_numpy(), dtype=np.float64)[ran] / 1e6

        values: dict[str, float] = {}
        units: dict[str, str] = {}
        per_frame: dict[str, Series] = {}

        f_idx = np.asarray(frames_tab.column("frame_index").to_numpy(), dtype=np.int64)
        f_ms = np.asarray(frames_tab.column("wall_ns").to_numpy(), dtype=np.float64) / 1e6
        frame_stats = latency_stats_ms(f_ms)
        values["frame_p95_ms"] = frame_stats["p95_ms"]  # the headline first
        for key, val in frame_stats.items():
            values[f"frame_{key}"] = val
        values["deadline_ms"] = deadline_ms
        over = f_ms - deadline_ms
        miss = over > 0
        values["frame_deadline_misses"] = float(miss.sum()) if deadline_s > 0 else math.nan
        values["frame_deadline_miss_fraction"] = (
            float(miss.mean()) if deadline_s > 0 and f_ms.size else math.nan
        )
        units.update(frame_deadline_misses="frames", frame_deadline_miss_fraction="ratio")
        per_frame["frame_ms"] = (f_idx, f_ms)
        # each percentile is of a per-frame series: `compare` bootstraps that percentile
        statistics: dict[str, tuple[str, str]] = {}

        def of_series(suffix: str, series: str) -> None:
            for stat in ("p50", "p95", "p99", "max"):
                statistics[f"{stat}_ms{suffix}"] = (series, stat)

        of_series("", "frame_ms")
        statistics = {f"frame_{k}": v for k, v in statistics.items()}

        manifest = data.run.manifest
        in_order = manifest.names()
        present = set(s_algo.tolist())
        algorithms = [a for a in in_order if a in present]
        algorithms += sorted(present - set(algorithms))
        for algo in algorithms:
            sel = s_algo == algo
            for key, val in latency_stats_ms(s_ms[sel]).items():
                values[f"{key}/{algo}"] = val
            misses = s_ms[sel] > deadline_ms
            values[f"deadline_misses/{algo}"] = float(misses.sum()) if deadline_s > 0 else math.nan
            values[f"deadline_miss_fraction/{algo}"] = (
                float(misses.mean()) if deadline_s > 0 else math.nan
            )
            units[f"deadline_misses/{algo}"] = "steps"
            units[f"deadline_miss_fraction/{algo}"] = "ratio"
            per_frame[f"latency_ms/{algo}"] = (s_frame[sel], s_ms[sel])
            of_series(f"/{algo}", f"latency_ms/{algo}")

        combine = np.maximum if self.params["stage_combine"] == "max" else np.add
        stages_present = set(s_stage.tolist())
        stages = [x for x in manifest.pipeline.stages if x in stages_present]
        stages += sorted(stages_present - set(stages))
        for stage in stages:
            sel = s_stage == stage
            frames_u, inverse = np.unique(s_frame[sel], return_inverse=True)
            stage_ms = (
                np.zeros(frames_u.size) if combine is np.add else np.full(frames_u.size, -np.inf)
            )
            combine.at(stage_ms, inverse, s_ms[sel])
            for key, val in latency_stats_ms(stage_ms).items():
                values[f"{key}/stage:{stage}"] = val
            per_frame[f"latency_ms/stage:{stage}"] = (frames_u, stage_ms)
            of_series(f"/stage:{stage}", f"latency_ms/stage:{stage}")

        bookmarks: list[Bookmark] = []
        if deadline_s > 0:
            for i in np.flatnonzero(miss):
                frame = int(f_idx[i])
                sel = s_frame == frame
                slowest = ""
                if sel.any():
                    j = int(np.argmax(s_ms[sel]))
                    slowest = f"; slowest {s_algo[sel][j]} {s_ms[sel][j]:.1f} ms"
                bookmarks.append(
                    Bookmark(
                        frame_index=frame,
                        kind="deadline_miss",
                        detail=(
                            f"frame took {f_ms[i]:.1f} ms, deadline {deadline_ms:.1f} ms{slowest}"
                        ),
                        severity=float(over[i]),
                    )
                )
        return MetricResult(
            values=values,
            units=units,
            higher_is_better={"deadline_ms": None},  # the parameter, echoed
            per_frame=per_frame,
            bookmarks=bookmarks,
            statistics={k: v for k, v in statistics.items() if k in values},
        )
