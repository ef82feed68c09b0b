"""``redrive bench engine``: the engine against a bare Python loop calling the same functions
(what and against what: ``redrive bench engine --help``).  The stages' work is an in-place
``sin``, square and ``sqrt`` over a float64 array sized on this machine (:func:`calibrate_work`;
numpy releases the GIL inside each); the engine's records go to an in-memory sink, as the results
writer's buffer, or with ``writer=True`` to the real Parquet writer.  CPU time is the running
thread's (``time.thread_time``: the no-op runs are sequential), with the writer the process's.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from redrive.algorithms import Algorithm, Role, StageOutputs
from redrive.benchmarks._base import Spread
from redrive.config import AlgorithmSpec, PipelineConfig, StageSpec
from redrive.engine import Engine, LogInputs, build_graph
from redrive.results import FrameRecord, RunSetup, RunStatus, RunWriter, SourceLog
from redrive.types import ControlCommands, DetectedObject, Frame, PlannedPath

__all__ = [
    "OVERHEAD_TARGET_US", "PIPELINED_TARGET", "SEQUENTIAL_TARGET", "WRITER_TARGET_US",
    "EngineBenchResult", "bench_engine", "calibrate_work",
]  # fmt: skip

#: issue 20's targets, judged on the median of the passes
SEQUENTIAL_TARGET = 0.95
PIPELINED_TARGET = 1.5
OVERHEAD_TARGET_US = 20.0
WRITER_TARGET_US = 50.0

_WORK: dict[str, Any] = {"a": np.zeros(1), "out": np.zeros(1)}
_PATH = PlannedPath(stamp_ns=0, waypoints=np.zeros((1, 4)))
_COMMANDS = ControlCommands()


def _work() -> None:
    # in place: no per-call allocation (an 800 KB temporary would be an mmap + page faults)
    a, out = _WORK["a"], _WORK["out"]
    np.sin(a, out=out)
    np.multiply(out, out, out=out)
    np.sqrt(out, out=out)


def calibrate_work(work_ms: float) -> int:
    """Size the work array so one :func:`_work` call takes about ``work_ms`` here."""
    n = 50_000
    for _ in range(6):
        _WORK["a"] = np.linspace(0.0, 1.0, n)
        _WORK["out"] = np.empty(n)
        _work()
        t0 = time.perf_counter()
        reps = 20
        for _ in range(reps):
            _work()
        per_call_ms = (time.perf_counter() - t0) / reps * 1e3
        n = max(1000, int(n * work_ms / max(per_call_ms, 1e-6)))
    _WORK["a"] = np.linspace(0.0, 1.0, n)
    _WORK["out"] = np.empty(n)
    return n


class BusyPerception(Algorithm):
    """~work_ms of numpy work; no objects."""

    role = Role.PERCEPTION

    def step(self, frame: Frame, upstream: StageOutputs) -> tuple[DetectedObject, ...]:
        _work()
        return ()


class BusyPlanning(Algorithm):
    """~work_ms of numpy work; a one-point path."""

    role = Role.PLANNING

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        _work()
        return _PATH


class BusyControl(Algorithm):
    """~work_ms of numpy work; zero commands."""

    role = Role.CONTROL

    def step(self, frame: Frame, upstream: StageOutputs) -> ControlCommands:
        _work()
        return _COMMANDS


class NoopPerception(Algorithm):
    role = Role.PERCEPTION

    def step(self, frame: Frame, upstream: StageOutputs) -> tuple[DetectedObject, ...]:
        return ()


class NoopPlanning(Algorithm):
    role = Role.PLANNING

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        return _PATH


class NoopControl(Algorithm):
    role = Role.CONTROL

    def step(self, frame: Frame, upstream: StageOutputs) -> ControlCommands:
        return _COMMANDS


def _pipeline(kind: str, mode: str) -> PipelineConfig:
    prefix = "Busy" if kind == "busy" else "Noop"
    names = [prefix + role for role in ("Perception", "Planning", "Control")]
    return PipelineConfig(
        stages=tuple(
            StageSpec(
                name=f"s{i}",
                algorithms=(AlgorithmSpec(name=f"a{i}", plugin=f"{__name__}:{cls}"),),
            )
            for i, cls in enumerate(names)
        ),
        mode=mode,  # type: ignore[arg-type]
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class EngineBenchResult:
    """Medians over repeats; times in seconds per whole pass unless named per frame."""

    frames: int
    work_ms: float
    work_elements: int
    bare_s: float
    sequential_s: float
    pipelined_s: float
    noop_bare_s: float
    noop_engine_s: float
    writer_s: float | None
    noop_bare_cpu_s: float = 0.0
    noop_engine_cpu_s: float = 0.0
    writer_cpu_s: float | None = None
    passes: Mapping[str, list[float]] = field(default_factory=dict)

    @property
    def sequential_ratio(self) -> float:
        """Throughput of the sequential engine over the bare loop's (target ≥ 0.95)."""
        return self.bare_s / self.sequential_s

    @property
    def pipelined_ratio(self) -> float:
        """Throughput of the pipelined engine over the bare loop's (target ≥ 1.5 on 2 cores)."""
        return self.bare_s / self.pipelined_s

    @property
    def overhead_us_per_frame(self) -> float:
        """The engine's own cost per frame with no-op stages (target ≤ 20 µs)."""
        return (self.noop_engine_s - self.noop_bare_s) / self.frames * 1e6

    @property
    def writer_us_per_frame(self) -> float | None:
        """The same with the Parquet results writer recording every frame."""
        if self.writer_s is None:
            return None
        return (self.writer_s - self.noop_bare_s) / self.frames * 1e6

    @property
    def overhead_cpu_us_per_frame(self) -> float:
        """The engine's own cost per frame with no-op stages, in thread CPU time."""
        return (self.noop_engine_cpu_s - self.noop_bare_cpu_s) / self.frames * 1e6

    @property
    def writer_cpu_us_per_frame(self) -> float | None:
        """The same with the Parquet writer, in CPU time of the process (the writer's pool
        threads included; its fsyncs' waits are not CPU)."""
        if self.writer_cpu_s is None:
            return None
        return (self.writer_cpu_s - self.noop_bare_cpu_s) / self.frames * 1e6

    def spreads(self) -> tuple[Spread, ...]:
        """Each target over the passes: ratios and costs per frame computed pass by pass."""
        p, n = self.passes, self.frames

        def per_frame(key: str, base: str) -> tuple[float | None, ...]:
            return tuple((a - b) / n * 1e6 for a, b in zip(p.get(key, []), p[base], strict=False))

        def ratio(key: str) -> tuple[float | None, ...]:
            return tuple(b / s for b, s in zip(p["bare"], p[key], strict=True))

        targets = [
            ("sequential ÷ bare loop", SEQUENTIAL_TARGET, False, ratio("sequential")),
            ("pipelined ÷ bare loop", PIPELINED_TARGET, False, ratio("pipelined")),
            ("engine µs/frame, wall", OVERHEAD_TARGET_US, True, per_frame("noop_engine", "noop_bare")),
            ("engine µs/frame, CPU", OVERHEAD_TARGET_US, True, per_frame("noop_engine_cpu", "noop_bare_cpu")),
        ]  # fmt: skip
        if p.get("writer"):
            targets += [
                ("with writer µs/frame, wall", WRITER_TARGET_US, True, per_frame("writer", "noop_bare")),
                ("with writer µs/frame, CPU", WRITER_TARGET_US, True, per_frame("writer_cpu", "noop_bare_cpu")),
            ]  # fmt: skip
        return tuple(Spread(name=t, bound=b, at_most=m, values=v) for t, b, m, v in targets)

    def to_json(self) -> dict[str, Any]:
        keys = ("frames", "work_ms", "work_elements", "bare_s", "sequential_s", "pipelined_s")
        derived: tuple[str, ...] = ("sequential_ratio", "pipelined_ratio", "overhead_us_per_frame")
        derived += ("writer_us_per_frame", "overhead_cpu_us_per_frame", "writer_cpu_us_per_frame")
        return {
            **{k: getattr(self, k) for k in (*keys, *derived)},
            "spread": [t.to_json() for t in self.spreads()],
            "passes": dict(self.passes),
        }


def _bare(frames: list[Frame], fns: tuple[Callable[[], Any], ...]) -> tuple[float, float]:
    """Wall and thread CPU seconds of the loop."""
    a, b, c = fns
    cpu0 = time.thread_time()
    t0 = time.perf_counter()
    for _frame in frames:
        a()
        b()
        c()
    return time.perf_counter() - t0, time.thread_time() - cpu0


def _noop() -> None:
    return None


def _engine(
    frames: list[Frame], kind: str, mode: str, writer_dir: Path | None = None
) -> tuple[float, float]:
    """Wall and CPU seconds of the run (and the writer's close).  The CPU time is this
    thread's — the whole cost only in sequential mode, where everything runs on this thread —
    and with the writer the whole process's: the writer encodes and writes its Parquet parts on
    a pool's threads."""
    pipeline = _pipeline(kind, mode)
    graph = build_graph(pipeline, LogInputs())
    engine = Engine(graph, pipeline, inputs=LogInputs())
    kept: list[FrameRecord] = []
    writer = None
    if writer_dir is not None:
        writer = RunWriter(
            writer_dir,
            setup=RunSetup(log=SourceLog(path="(in memory)", format="bench", sha256=None)),
        )
        sink: Callable[[FrameRecord], None] = writer.write_frame
    else:
        sink = kept.append
    cpu_time = time.thread_time if writer is None else time.process_time
    cpu0 = cpu_time()
    t0 = time.perf_counter()
    report = engine.run(frames, sink=sink)
    if writer is not None:
        writer.close(status=RunStatus.COMPLETE)
    elapsed = time.perf_counter() - t0
    cpu = cpu_time() - cpu0
    engine.close()
    if report.frames != len(frames):
        msg = f"engine processed {report.frames} of {len(frames)} frames"
        raise RuntimeError(msg)
    return elapsed, cpu


def bench_engine(
    *,
    frames: int = 500,
    work_ms: float = 1.0,
    repeats: int = 5,
    writer: bool = True,
    progress: Callable[[str], None] | None = None,
) -> EngineBenchResult:
    """Run every variant ``repeats`` times, interleaved, and keep the medians."""
    elements = calibrate_work(work_ms)
    data = [Frame(stamp_ns=i * 100_000_000, index=i) for i in range(frames)]
    keys = ("bare", "sequential", "pipelined", "noop_bare", "noop_engine", "writer")
    passes: dict[str, list[float]] = {
        k: [] for k in (*keys, "noop_bare_cpu", "noop_engine_cpu", "writer_cpu")
    }

    def keep(key: str, measured: tuple[float, float], *, cpu: bool = False) -> None:
        passes[key].append(measured[0])
        if cpu:
            passes[key + "_cpu"].append(measured[1])

    with tempfile.TemporaryDirectory(prefix="redrive-bench-engine-") as tmp:
        for r in range(repeats):
            if progress is not None:
                progress(f"pass {r + 1}/{repeats}")
            keep("bare", _bare(data, (_work, _work, _work)))
            keep("sequential", _engine(data, "busy", "sequential"))
            keep("pipelined", _engine(data, "busy", "pipelined"))
            keep("noop_bare", _bare(data, (_noop, _noop, _noop)), cpu=True)
            keep("noop_engine", _engine(data, "noop", "sequential"), cpu=True)
            if writer:
                run_dir = Path(tmp) / f"run{r}"
                keep("writer", _engine(data, "noop", "sequential", writer_dir=run_dir), cpu=True)
    passes = {k: v for k, v in passes.items() if v}
    med = {k: statistics.median(v) for k, v in passes.items()}
    return EngineBenchResult(
        frames=frames, work_ms=work_ms, work_elements=elements, bare_s=med["bare"],
        sequential_s=med["sequential"], pipelined_s=med["pipelined"], noop_bare_s=med["noop_bare"],
        noop_engine_s=med["noop_engine"], writer_s=med.get("writer"),
        noop_bare_cpu_s=med["noop_bare_cpu"], noop_engine_cpu_s=med["noop_engine_cpu"],
        writer_cpu_s=med.get("writer_cpu"), passes=passes,
    )  # fmt: skip
