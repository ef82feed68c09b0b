"""Deviation as part of the verdict: how many of a closed-loop metric's frames the driven ego
was past the deviation threshold from the logged one, and the caveat ``redrive evaluate`` prints
for a log-backed closed loop that deviated.

In a log-backed closed loop (``closed_loop.backend = "log"``) the other road users and the
sensors are the log's, moved to the driven pose; once the driven ego is far from the logged one
they no longer describe what it would have met, so its collisions, TTC, progress and comfort are
scored against a world that was not there.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt

from redrive.evaluation.base import EvalData, MetricResult
from redrive.results import Run

__all__ = ["deviated_frames", "deviation_caveat", "with_deviation"]


def deviated_frames(data: EvalData, frames: npt.NDArray[np.int64]) -> int | None:
    """How many of ``frames`` a log-backed closed loop flagged ``deviated`` (its driven ego past
    the deviation threshold from the logged one); None when the run has no such flags (open
    loop, or a closed loop without a logged ego)."""
    table = data.closed_loop()
    if table.num_rows == 0 or "deviated" not in table.column_names:
        return None
    flags = table.column("deviated").to_pylist()
    if all(f is None for f in flags):
        return None
    flagged = {
        int(f) for f, d in zip(table.column("frame_index").to_pylist(), flags, strict=True) if d
    }
    return int(sum(int(f) in flagged for f in np.asarray(frames).tolist()))


def with_deviation(
    result: MetricResult, data: EvalData, frames: npt.NDArray[np.int64]
) -> MetricResult:
    """``result`` with ``deviated_frames`` (of the frames it was computed on) added when the run
    is a log-backed closed loop: a score over frames whose ego left the logged one is a score
    against a log that no longer describes what the ego would have met."""
    n = deviated_frames(data, frames)
    if n is None:
        return result
    return dataclasses.replace(
        result,
        values={**result.values, "deviated_frames": float(n)},
        units={**result.units, "deviated_frames": "frames"},
        higher_is_better={**result.higher_is_better, "deviated_frames": None},
    )


def deviation_caveat(run: Run) -> str | None:
    """The caveat for ``run`` when it is a log-backed closed loop whose driven ego passed the
    deviation threshold on some frame; None otherwise."""
    manifest = run.manifest
    if manifest.closed_loop.get("backend") != "log" or manifest.summary is None:
        return None
    dev = manifest.summary.closed_loop
    n = int(dev.get("deviated_frames") or 0)
    if n == 0:
        return None
    thr_m = dev.get("deviation_threshold_m")
    thr_rad = dev.get("deviation_threshold_rad")
    past = (
        f" past {float(thr_m):g} m / {math.degrees(float(thr_rad)):g}°"
        if thr_m is not None and thr_rad is not None
        else " past its threshold"
    )
    first = dev.get("first_deviated_frame")
    worst = dev.get("max_deviation_m")
    return (
        f"caveat: this log-backed closed loop drove {n} of {manifest.summary.frames} frames{past}"
        f" from the logged ego"
        + (f" (first at frame {first}" if first is not None else " (")
        + (f", at most {float(worst):.1f} m)" if worst is not None else ")")
        + ": there the log's agents and sensors no longer show what the ego would have met, "
        "so collisions, TTC, progress and comfort are scored against a world that was not "
        "there; each closed-loop metric reports its deviated_frames"
    )
