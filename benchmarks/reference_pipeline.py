"""The reference pipeline on one log, once per mode and executor: frames/s, real-time factor and
each algorithm's mean step time (what ``redrive bench engine --log`` printed before issue 32;
``redrive run LOG --mode M`` reports the same figures for one mode).

    PYTHONPATH=src .venv/bin/python -m benchmarks.reference_pipeline LOG [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True, slots=True, kw_only=True)
class PipelineBenchResult:
    """The reference pipeline on a log: one run per mode."""

    log: str
    frames: int
    log_span_s: float
    frames_per_s: Mapping[str, float]
    realtime_factor: Mapping[str, float]
    stage_ms: Mapping[str, Mapping[str, float]]  # mode → algorithm → mean step ms

    def to_json(self) -> dict[str, Any]:
        return {
            "log": self.log,
            "frames": self.frames,
            "log_span_s": self.log_span_s,
            "frames_per_s": dict(self.frames_per_s),
            "realtime_factor": dict(self.realtime_factor),
            "stage_ms": {k: dict(v) for k, v in self.stage_ms.items()},
        }


def bench_reference_pipeline(
    log: Path,
    *,
    modes: tuple[tuple[str, str], ...] = (
        ("sequential", "threads"),
        ("pipelined", "threads"),
        ("pipelined", "processes"),
    ),
    progress: Callable[[str], None] | None = None,
) -> PipelineBenchResult:
    """Replay ``log`` through the reference pipeline once per (mode, executor), results written
    to a temporary run directory as ``redrive run`` does."""
    from redrive.config import reference_pipeline
    from redrive.engine import RunRequest, run_log

    fps: dict[str, float] = {}
    rtf: dict[str, float] = {}
    stage_ms: dict[str, dict[str, float]] = {}
    frames, span = 0, 0.0
    with tempfile.TemporaryDirectory(prefix="redrive-bench-pipeline-") as tmp:
        for mode, executor in modes:
            key = f"{mode}/{executor}"
            if progress is not None:
                progress(key)
            pipeline = reference_pipeline().with_options(mode=mode, executor=executor)
            report = run_log(RunRequest(log=log, pipeline=pipeline, out=Path(tmp) / key))
            fps[key] = report.frames_per_s
            rtf[key] = report.realtime_factor
            stage_ms[key] = {a.name: a.latency_mean_ms for a in report.algorithms}
            frames, span = report.frames, report.log_span_s
    return PipelineBenchResult(
        log=str(log),
        frames=frames,
        log_span_s=span,
        frames_per_s=fps,
        realtime_factor=rtf,
        stage_ms=stage_ms,
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", type=Path, metavar="LOG")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    args = parser.parse_args(argv)
    result = bench_reference_pipeline(args.log, progress=lambda t: print(t, file=sys.stderr))
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
        return 0
    print(f"reference pipeline on {result.log}: {result.frames} frames, {result.log_span_s:.1f} s")
    for key, fps in result.frames_per_s.items():
        rtf = result.realtime_factor[key]
        stages = ", ".join(f"{k} {v:.1f}" for k, v in result.stage_ms[key].items())
        verdict = "meets" if rtf >= 10.0 else "misses"
        print(
            f"  {key:22s} {fps:6.1f} frames/s = {rtf:5.1f}x real time {verdict} 10x  (mean ms: {stages})"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
