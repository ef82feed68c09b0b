"""The issue-6 targets, checked against what a run of the benchmark measured."""

from __future__ import annotations

import math

from redrive.benchmarks.transport.results import TargetCheck, TransportBenchResult, _finite

__all__ = [
    "INPLACE_VS_ICEORYX2_TARGET",
    "PACED_P99_TARGET_MS",
    "VS_MEMCPY_TARGET",
    "VS_PIPE_PICKLE_TARGET",
    "check_targets",
]

INPLACE_VS_ICEORYX2_TARGET = 1.0  # redrive in place / iceoryx2 in place, GB/s at 64K, 1M, 4M
VS_PIPE_PICKLE_TARGET = 10.0  # redrive / pipe + pickle, GB/s at 4 MiB
VS_MEMCPY_TARGET = 0.5  # redrive / from-memory memcpy, GB/s at 16 MiB
PACED_P99_TARGET_MS = 2.0  # redrive paced p99 one-way latency at 4 MiB


def _gb(result: TransportBenchResult, side: str, size: int, *, flat: bool = True) -> float | None:
    c = result.cell(side, size)
    run = None if c is None else (c.flat if flat else c.paced)
    if run is None or not math.isfinite(run.gb_per_s):
        return None
    return run.gb_per_s


def check_targets(result: TransportBenchResult) -> tuple[TargetCheck, ...]:
    """The issue-6 targets against what ran: both redrive sides against pipe + pickle at 4 MiB,
    the from-memory copy at 16 MiB and the paced 4 MiB p99; when iceoryx2 ran (``python -m
    benchmarks transport``), in place against iceoryx2 in place at 64 KiB (issue 20), 1 and
    4 MiB."""
    checks: list[TargetCheck] = []
    sizes = set(result.sizes)
    mib1, mib4, mib16 = 1 << 20, 4 << 20, 16 << 20
    redrive = ("redrive-copy", "redrive-inplace")

    def ratio(name: str, side: str, *, size: int, ref: float | None, bound: float) -> None:
        value = _gb(result, side, size)
        met = None if value is None or ref is None else value >= bound * ref
        checks.append(
            TargetCheck(
                name=name,
                side=side,
                size_bytes=size,
                value=value,
                reference=ref,
                target=f"≥ {bound:g}×",
                met=met,
                note="GB/s flat out",
            )
        )

    for size in (64 << 10, mib1, mib4):
        if size in sizes and result.cell("iceoryx2", size) is not None:
            ref = _gb(result, "iceoryx2", size)
            bound = INPLACE_VS_ICEORYX2_TARGET
            ratio("vs iceoryx2 in place", "redrive-inplace", size=size, ref=ref, bound=bound)
    if mib4 in sizes:
        ref = _gb(result, "pipe-pickle", mib4)
        for side in redrive:
            ratio("vs pipe + pickle", side, size=mib4, ref=ref, bound=VS_PIPE_PICKLE_TARGET)
    if mib16 in sizes:
        mem = next((m for m in result.memcpy if m.size_bytes == mib16), None)
        ref = None if mem is None else mem.from_memory_gb_per_s
        for side in redrive:
            ratio("vs memcpy from memory", side, size=mib16, ref=ref, bound=VS_MEMCPY_TARGET)
    if mib4 in sizes:
        for side in redrive:
            c = result.cell(side, mib4)
            p99 = None if c is None or c.paced is None else _finite(c.paced.latency_p99_ms)
            checks.append(
                TargetCheck(
                    name=f"paced p99 at {result.paced_hz:g} Hz",
                    side=side,
                    size_bytes=mib4,
                    value=p99,
                    reference=PACED_P99_TARGET_MS,
                    target=f"≤ {PACED_P99_TARGET_MS:g} ms",
                    met=None if p99 is None else p99 <= PACED_P99_TARGET_MS,
                    note="ms one way",
                )
            )
    return tuple(checks)
