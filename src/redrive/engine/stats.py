"""What a run did, counted as it goes: frames, rates, per-algorithm outcomes and latencies."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from redrive.engine.graph import PlannedAlgorithm
from redrive.io.damage import LogDamage
from redrive.results import FrameRecord, RunStatus, StepRecord

__all__ = ["AlgorithmStats", "RunReport", "StatsCollector"]


@dataclass(frozen=True, slots=True, kw_only=True)
class AlgorithmStats:
    """One algorithm over a run.  Latencies in milliseconds of wall time per step."""

    name: str
    stage: str
    role: str
    ok: int
    error: int
    timeout: int
    skipped: int
    outputs: int  # objects (perception), paths (planning) or commands (control) produced
    latency_mean_ms: float
    latency_p50_ms: float
    latency_p95_ms: float
    latency_max_ms: float
    cpu_mean_ms: float
    first_error: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__slots__}


@dataclass(frozen=True, slots=True, kw_only=True)
class RunReport:
    """The outcome of :meth:`Engine.run`.

    Attributes:
        status: complete, interrupted or failed.
        frames: frames processed in this invocation.
        wall_s: wall time of the run.
        log_span_s: log time covered by those frames (last stamp − first stamp + one period).
        late_frames: frames released after their due time (real-time pacing only).
        failure: (frame index, step) that stopped a ``fail_fast`` run.
        failed_frames: frames in which at least one step failed (error or timeout).
        missing_inputs: input → frames that had no sample of it within the tolerance.
        damage: the damaged parts of the log that were skipped (a run with ``strict=False``).
        skipped: the algorithms left out because the log cannot feed them (name → why; a run
            with ``skip_unfed=True``).
        non_finite_points: topic → the NaN / ±inf points of its clouds, for the topics with any
            (:meth:`redrive.assembly.non_finite.NonFiniteCounter.summary`).
    """

    status: RunStatus
    frames: int
    wall_s: float
    log_span_s: float
    late_frames: int
    algorithms: tuple[AlgorithmStats, ...] = ()
    failure: tuple[int, StepRecord] | None = field(default=None)
    failed_frames: int = 0
    missing_inputs: Mapping[str, int] = field(default_factory=dict)
    damage: tuple[LogDamage, ...] = ()
    skipped: Mapping[str, str] = field(default_factory=dict)
    non_finite_points: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    @property
    def nothing_succeeded(self) -> bool:
        """Frames were processed and no step of any algorithm succeeded in any of them."""
        return self.frames > 0 and bool(self.algorithms) and not any(a.ok for a in self.algorithms)

    @property
    def frames_per_s(self) -> float:
        return self.frames / self.wall_s if self.wall_s > 0 else 0.0

    @property
    def realtime_factor(self) -> float:
        """Log seconds processed per wall second (10 = ten times faster than real time)."""
        return self.log_span_s / self.wall_s if self.wall_s > 0 else 0.0

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "status": self.status.value,
            "frames": self.frames,
            "wall_s": round(self.wall_s, 3),
            "frames_per_s": round(self.frames_per_s, 2),
            "log_span_s": round(self.log_span_s, 3),
            "realtime_factor": round(self.realtime_factor, 2),
            "late_frames": self.late_frames,
            "failed_frames": self.failed_frames,
            "missing_inputs": dict(self.missing_inputs),
            "algorithms": [a.as_dict() for a in self.algorithms],
        }
        if self.failure is not None:
            index, step = self.failure
            out["failure"] = {
                "frame_index": index,
                "algorithm": step.algorithm,
                "status": step.status,
                "error_type": step.error_type,
                "error_message": step.error_message,
            }
        return out


class StatsCollector:
    """Accumulates :class:`FrameRecord`s (cheaply: counters and latency lists)."""

    def __init__(self, planned: Sequence[PlannedAlgorithm]) -> None:
        self._planned = list(planned)
        self._status: dict[str, dict[str, int]] = {p.name: {} for p in planned}
        self._latency: dict[str, list[int]] = {p.name: [] for p in planned}
        self._cpu: dict[str, list[int]] = {p.name: [] for p in planned}
        # per algorithm, what an ok step updates, found by one lookup: [ok steps, outputs,
        # latency_list.append, cpu_list.append]
        self._acc: dict[str, list[Any]] = {
            p.name: [0, 0, self._latency[p.name].append, self._cpu[p.name].append] for p in planned
        }
        self._first_error: dict[str, str] = {}
        self.frames = 0
        self.failed_frames = 0
        self.missing_inputs: dict[str, int] = {}
        self._first_stamp: int | None = None
        self._last_stamp = 0

    def add(self, record: FrameRecord) -> None:
        self.frames += 1
        if self._first_stamp is None:
            self._first_stamp = record.stamp_ns
        self._last_stamp = record.stamp_ns
        if record.missing:
            self.add_missing(record.missing)
        failed = False
        acc_of = self._acc
        for step in record.steps:
            acc = acc_of[step.algorithm]
            if step.status == "ok":
                acc[0] += 1
                output = step.output
                acc[1] += len(output) if type(output) is tuple else 1
                acc[2](step.latency_ns)
                acc[3](step.cpu_ns)
                continue
            if self._not_ok(record.frame_index, step):
                failed = True  # error or timeout
        if failed:
            self.failed_frames += 1

    # -- counted by the caller: the short replay path hands its frames on a chain at a time --

    def ok_lists(self, name: str) -> tuple[Callable[[int], None], Callable[[int], None]]:
        """The appends of ``name``'s latency and CPU lists: an ok step's times go there, in
        frame order, when the caller counts for itself (:meth:`add_counted`)."""
        return self._latency[name].append, self._cpu[name].append

    def take_back_ok(self, name: str) -> None:
        """Remove the last times appended through :meth:`ok_lists` for ``name``."""
        self._latency[name].pop()
        self._cpu[name].pop()

    def add_counted(
        self,
        *,
        first_stamp_ns: int,
        last_stamp_ns: int,
        frames: int,
        failed_frames: int,
        ok: Sequence[tuple[str, int, int]],
    ) -> None:
        """What :meth:`add` counts of ``frames`` consecutive frames, counted by the caller:
        their first and last stamps, how many had a failed step, and per algorithm
        ``(name, ok steps, their outputs)``; the ok steps' times were appended through
        :meth:`ok_lists`, the other steps added by :meth:`add_step` and the missing inputs by
        :meth:`add_missing`, frame by frame."""
        if not frames:
            return
        self.frames += frames
        if self._first_stamp is None:
            self._first_stamp = first_stamp_ns
        self._last_stamp = last_stamp_ns
        self.failed_frames += failed_frames
        acc_of = self._acc
        for name, steps, outputs in ok:
            acc = acc_of[name]
            acc[0] += steps
            acc[1] += outputs

    def add_missing(self, missing: Sequence[str]) -> None:
        """Count a frame's missing inputs."""
        counts = self.missing_inputs
        for name in missing:
            counts[name] = counts.get(name, 0) + 1

    def add_step(self, frame_index: int, step: StepRecord) -> bool:
        """Count one step as :meth:`add` does; True when it failed (error or timeout)."""
        if step.status == "ok":
            acc = self._acc[step.algorithm]
            acc[0] += 1
            output = step.output
            acc[1] += len(output) if type(output) is tuple else 1
            acc[2](step.latency_ns)
            acc[3](step.cpu_ns)
            return False
        return self._not_ok(frame_index, step)

    def _not_ok(self, frame_index: int, step: StepRecord) -> bool:
        """Count a step that did not succeed; True for an error or timeout (not skipped)."""
        name, status = step.algorithm, step.status
        counts = self._status[name]
        counts[status] = counts.get(status, 0) + 1
        if name not in self._first_error:
            self._first_error[name] = (
                f"frame {frame_index}: {step.error_type}: {step.error_message}"
            )
        if status == "skipped":
            return False
        self._latency[name].append(step.latency_ns)
        self._cpu[name].append(step.cpu_ns)
        return True

    def report(
        self,
        *,
        status: RunStatus,
        wall_s: float,
        late_frames: int,
        failure: tuple[int, StepRecord] | None,
    ) -> RunReport:
        span_s = 0.0
        if self._first_stamp is not None and self.frames > 0:
            span = self._last_stamp - self._first_stamp
            period = span / (self.frames - 1) if self.frames > 1 else 0.0
            span_s = (span + period) / 1e9
        names = [p.name for p in self._planned]
        lat_ms, cpu_ms = (
            _per_algorithm_ms([self._latency[n] for n in names]),
            _per_algorithm_ms([self._cpu[n] for n in names]),
        )
        quantiles = _p50_p95(lat_ms)
        algos = []
        for k, p in enumerate(self._planned):
            lat, cpu = lat_ms[k], cpu_ms[k]
            counts = self._status[p.name]
            acc = self._acc[p.name]
            algos.append(
                AlgorithmStats(
                    name=p.name,
                    stage=p.stage,
                    role=p.role.value,
                    ok=acc[0],
                    error=counts.get("error", 0),
                    timeout=counts.get("timeout", 0),
                    skipped=counts.get("skipped", 0),
                    outputs=acc[1],
                    latency_mean_ms=float(lat.mean()) if lat.size else 0.0,
                    latency_p50_ms=quantiles[k][0],
                    latency_p95_ms=quantiles[k][1],
                    latency_max_ms=float(lat.max()) if lat.size else 0.0,
                    cpu_mean_ms=float(cpu.mean()) if cpu.size else 0.0,
                    first_error=self._first_error.get(p.name, ""),
                )
            )
        return RunReport(
            status=status,
            frames=self.frames,
            wall_s=wall_s,
            log_span_s=span_s,
            late_frames=late_frames,
            algorithms=tuple(algos),
            failure=failure,
            failed_frames=self.failed_frames,
            missing_inputs=dict(self.missing_inputs),
        )


def _per_algorithm_ms(values: list[list[int]]) -> list[np.ndarray]:
    """Each algorithm's ns values as float64 ms; one conversion for all of them when they have
    as many values each (the common case: every step ran), else one per algorithm."""
    if values and len({len(v) for v in values}) == 1:
        # int64 first, list by list: numpy reads a flat list of ints ≈ 2.5× faster than it
        # discovers the shape and type of a nested one (the same float64 values: ns ints
        # below 2**53 convert exactly either way)
        stacked = np.stack([np.array(v, dtype=np.int64) for v in values])
        return list(stacked.astype(np.float64) / 1e6)
    return [np.array(v, dtype=np.int64).astype(np.float64) / 1e6 for v in values]


def _p50_p95(lat_ms: list[np.ndarray]) -> list[tuple[float, float]]:
    """The 50th and 95th percentiles of each array (0 for an empty one): one
    ``np.percentile`` call along the rows when they have one length (the same values as one
    call per array: each row is partitioned and interpolated alike)."""
    if lat_ms and lat_ms[0].size and len({a.size for a in lat_ms}) == 1:
        q = np.percentile(np.stack(lat_ms), [50, 95], axis=1)  # shape (2, algorithms)
        return [(float(a), float(b)) for a, b in zip(q[0], q[1], strict=True)]
    return [
        (float(q[0]), float(q[1]))
        for q in (np.percentile(a, [50, 95]) if a.size else np.zeros(2) for a in lat_ms)
    ]
