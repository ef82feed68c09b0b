"""Latency percentiles and deadline misses on known latencies.

Percentiles are numpy's default (``method="linear"``, Hyndman & Fan type 7): for sorted values
x_0 … x_{n−1}, the q-th percentile sits at rank r = q/100 · (n − 1), interpolated linearly
between x_⌊r⌋ and x_⌈r⌉.

Five frames 0.1 s apart (deadline 100 ms), latencies in ms:

=====  ====  =====  =====  =======  =====
frame  det   det2   plan   (stage)  wall
=====  ====  =====  =====  =======  =====
0      10    50     1      50       70
1      20    50     2      50       80
2      30    50     skip   50       90
3      40    50     3      50       100
4      150   50     4      150      260
=====  ====  =====  =====  =======  =====

det and det2 run side by side in stage ``perception``; plan's skipped step (999 ms) is left out.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from redrive.errors import ConfigError
from redrive.evaluation.base import EvalData
from redrive.evaluation.latency import Latency, latency_stats_ms
from redrive.results import (
    AlgorithmEntry,
    FrameRecord,
    PipelineInfo,
    RunSetup,
    RunWriter,
    SourceLog,
    StepRecord,
    open_run,
)
from redrive.types import Role

T0_NS = 1_700_000_000_000_000_000
MS = 1_000_000
DET = [10, 20, 30, 40, 150]
DET2 = [50] * 5
PLAN = [1, 2, 999, 3, 4]
WALL = [70, 80, 90, 100, 260]
SETUP = RunSetup(
    log=SourceLog(path="synthetic", sha256="x", format="synthetic"),
    seed=0,
    pipeline=PipelineInfo(first_frame=0),
    algorithms=(
        AlgorithmEntry(name="det", version="1", config_hash="a", role=Role.PERCEPTION),
        AlgorithmEntry(name="det2", version="1", config_hash="b", role=Role.PERCEPTION),
        AlgorithmEntry(name="plan", version="1", config_hash="c", role=Role.PLANNING),
    ),
)


def make_run(tmp_path: Path) -> Path:
    out = tmp_path / "run"
    with RunWriter(out, setup=SETUP) as writer:
        for i in range(5):
            steps = (
                StepRecord(
                    algorithm="det",
                    stage="perception",
                    role="perception",
                    status="ok",
                    latency_ns=DET[i] * MS,
                    output=(),
                ),
                StepRecord(
                    algorithm="det2",
                    stage="perception",
                    role="perception",
                    status="ok",
                    latency_ns=DET2[i] * MS,
                    output=(),
                ),
                StepRecord(
                    algorithm="plan",
                    stage="planning",
                    role="planning",
                    status="skipped" if i == 2 else "ok",
                    latency_ns=PLAN[i] * MS,
                ),
            )
            writer.write_frame(
                FrameRecord(
                    frame_index=i,
                    stamp_ns=T0_NS + i * 100 * MS,
                    steps=steps,
                    wall_ns=WALL[i] * MS,
                )
            )
    return out


def test_percentiles_and_deadline_misses(tmp_path: Path) -> None:
    res = Latency().evaluate(EvalData(open_run(make_run(tmp_path)), ""))
    v = res.values
    assert res.headline == "frame_p95_ms"
    assert v["deadline_ms"] == pytest.approx(100.0)
    # det: sorted 10 20 30 40 150; p50 rank 2 → 30; p95 rank 3.8 → 40 + 0.8·110 = 128;
    # p99 rank 3.96 → 40 + 0.96·110 = 145.6
    assert v["p50_ms/det"] == pytest.approx(30.0)
    assert v["p95_ms/det"] == pytest.approx(128.0)
    assert v["p99_ms/det"] == pytest.approx(145.6)
    assert v["max_ms/det"] == pytest.approx(150.0)
    assert v["deadline_misses/det"] == 1  # 150 > 100
    assert v["deadline_miss_fraction/det"] == pytest.approx(0.2)
    assert v["deadline_misses/det2"] == 0
    # plan: the skipped step is not counted: 1 2 3 4 → p50 rank 1.5 → 2.5
    assert v["p50_ms/plan"] == pytest.approx(2.5)
    assert v["max_ms/plan"] == pytest.approx(4.0)
    assert v["deadline_miss_fraction/plan"] == 0.0
    # stage perception = max(det, det2) per frame: 50 50 50 50 150;
    # p95 rank 3.8 → 50 + 0.8·100 = 130
    assert v["p50_ms/stage:perception"] == pytest.approx(50.0)
    assert v["p95_ms/stage:perception"] == pytest.approx(130.0)
    # frame wall: 70 80 90 100 260; p95 → 100 + 0.8·160 = 228; 100 is not over 100 (strict)
    assert v["frame_p95_ms"] == pytest.approx(228.0)
    assert v["frame_p50_ms"] == pytest.approx(90.0)
    assert v["frame_deadline_misses"] == 1
    assert v["frame_deadline_miss_fraction"] == pytest.approx(0.2)
    (bookmark,) = res.bookmarks
    assert bookmark.kind == "deadline_miss"
    assert bookmark.frame_index == 4
    assert bookmark.severity == pytest.approx(160.0)  # 260 − 100 ms
    assert "slowest det 150.0 ms" in bookmark.detail
    # per-frame series
    frames, ms = res.per_frame["latency_ms/plan"]
    assert frames.tolist() == [0, 1, 3, 4]
    assert ms.tolist() == pytest.approx([1.0, 2.0, 3.0, 4.0])
    assert res.per_frame["frame_ms"][1].tolist() == pytest.approx(WALL)
    # value names in pipeline order
    assert [k for k in v if k.startswith("p95_ms/")] == [
        "p95_ms/det",
        "p95_ms/det2",
        "p95_ms/plan",
        "p95_ms/stage:perception",
        "p95_ms/stage:planning",
    ]


def test_sum_of_a_stage_and_a_given_deadline(tmp_path: Path) -> None:
    res = Latency(deadline_s=0.075, stage_combine="sum").evaluate(
        EvalData(open_run(make_run(tmp_path)), "")
    )
    v = res.values
    # stage perception = det + det2: 60 70 80 90 200 → p50 80, p95 90 + 0.8·110 = 178
    assert v["p50_ms/stage:perception"] == pytest.approx(80.0)
    assert v["p95_ms/stage:perception"] == pytest.approx(178.0)
    # over 75 ms: frames 80 90 100 260 → 4 of 5; det: 150 only
    assert v["frame_deadline_misses"] == 4
    assert v["deadline_misses/det"] == 1
    assert [b.frame_index for b in res.bookmarks] == [1, 2, 3, 4]
    assert [b.severity for b in res.bookmarks] == pytest.approx([5.0, 15.0, 25.0, 185.0])


def test_stats_edge_cases_and_parameters() -> None:
    assert all(math.isnan(x) for x in latency_stats_ms([]).values())
    assert latency_stats_ms([7.0]) == {"p50_ms": 7.0, "p95_ms": 7.0, "p99_ms": 7.0, "max_ms": 7.0}
    with pytest.raises(ConfigError):
        Latency(stage_combine="mean")
    with pytest.raises(ConfigError):
        Latency(deadline_s=0)


def test_unknown_deadline_gives_nan_misses(tmp_path: Path) -> None:
    out = tmp_path / "one"
    with RunWriter(out, setup=SETUP) as writer:
        step = StepRecord(
            algorithm="det", stage="perception", role="perception", status="ok", latency_ns=MS
        )
        writer.write_frame(FrameRecord(frame_index=0, stamp_ns=T0_NS, steps=(step,), wall_ns=MS))
    res = Latency().evaluate(EvalData(open_run(out), ""))
    assert math.isnan(res.values["deadline_ms"])
    assert math.isnan(res.values["frame_deadline_misses"])
    assert res.values["frame_p95_ms"] == pytest.approx(1.0)
    assert res.bookmarks == ()


def test_demo_run_gives_finite_values(demo_run: Path) -> None:
    res = Latency().evaluate(EvalData(open_run(demo_run), ""))
    assert all(math.isfinite(v) for v in res.values.values()), dict(res.values)
    assert res.values["deadline_ms"] == pytest.approx(100.0)  # 10 Hz LiDAR
