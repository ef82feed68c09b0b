"""``redrive bench transport``: moving large messages between two processes, every side (a
transport, :mod:`~redrive.benchmarks.transport.sides`) at every size, flat out and paced, against
the memcpy ceiling of this machine, and the targets of issues 6 and 20.  How each side sends and
consumes a message so that the numbers compare like with like: ``benchmarks/README.md``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib.metadata
import importlib.util
import logging
import math
import os
import platform
import statistics
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from redrive.benchmarks._base import Spread, fields_json
from redrive.benchmarks.transport.sides import (
    CATALOGUE,
    MIN_SIZE,
    SIDES,
    SLOTS,
    U8,
    RunResult,
    SideSpec,
    catalogue_sides,
    check_size,
    run_cell,
)
from redrive.errors import TransportError

__all__ = [
    "CATALOGUE", "DEFAULT_SIZES", "INPLACE_VS_ICEORYX2_TARGET", "MIN_SIZE", "PACED_COPIES",
    "PACED_P99_COPY_TARGET_MS", "PACED_P99_TARGET_MS", "SIDES", "SLOTS", "VS_MEMCPY_TARGET",
    "VS_PIPE_PICKLE_TARGET", "CellResult", "MemcpyResult", "RunResult", "SideSpec", "TargetCheck",
    "TargetSpread", "TransportBenchResult", "bench_memcpy", "bench_transport", "catalogue_sides",
    "check_targets", "copy_floor_ms", "parse_size", "run_cell", "side_available", "size_label",
    "target_spreads",
]  # fmt: skip

logger = logging.getLogger(__name__)

DEFAULT_SIZES = (64 << 10, 1 << 20, 4 << 20, 16 << 20)
MEMORY_POOL_BYTES = 256 << 20
#: the targets of issues 6 and 20
INPLACE_VS_ICEORYX2_TARGET = 1.0  # redrive in place / iceoryx2 in place, GB/s at 64K, 1M, 4M
VS_PIPE_PICKLE_TARGET = 10.0  # redrive / pipe + pickle, GB/s at 4 MiB
VS_MEMCPY_TARGET = 0.5  # redrive / from-memory memcpy, GB/s at 16 MiB
PACED_P99_TARGET_MS = 2.0  # redrive paced p99 one-way latency at 4 MiB
#: the target of issue 36: copy-out's paced p99 at 4 MiB, judged with the floor of its copies
PACED_P99_COPY_TARGET_MS = 1.0
#: the payload copies between the publisher's stamp and the subscriber's: copy-out copies into
#: the slot and out of it, in place fills the slot (the floor of a paced latency: that many
#: copies at the from-memory memcpy rate of the same run)
PACED_COPIES = {"redrive-copy": 2, "redrive-inplace": 1}


@dataclass(frozen=True, slots=True, kw_only=True)
class CellResult:
    """One side at one size: ``status`` is ``"ok"``, ``"not installed"`` or ``"error"``."""

    side: str
    size_bytes: int
    status: str
    error: str | None = None
    flat: RunResult | None = None
    paced: RunResult | None = None

    def to_json(self) -> dict[str, Any]:
        return fields_json(self)


@dataclass(frozen=True, slots=True, kw_only=True)
class MemcpyResult:
    """Single-thread ``np.copyto`` GB/s (10⁹ B/s) at ``size_bytes``."""

    size_bytes: int
    hot_gb_per_s: float
    from_memory_gb_per_s: float
    pool_bytes: int

    def to_json(self) -> dict[str, Any]:
        return fields_json(self)


@dataclass(frozen=True, slots=True, kw_only=True)
class TargetCheck:
    """One target of the issue: ``value`` of ``side`` against ``reference`` (a baseline's GB/s;
    for a latency, the floor of its copies in ms, :func:`copy_floor_ms`, None without the memcpy
    runs); ``met`` is None when a side needed for it did not run."""

    name: str
    side: str
    size_bytes: int
    value: float | None
    reference: float | None
    target: str  # e.g. "≥ 1.0×", "≤ 2 ms"
    met: bool | None
    note: str = ""

    @property
    def ratio(self) -> float | None:
        if self.value is None or self.reference is None or not self.reference:
            return None
        return self.value / self.reference

    def to_json(self) -> dict[str, Any]:
        return fields_json(self, ratio=self.ratio)


@dataclass(frozen=True, slots=True, kw_only=True)
class TransportBenchResult:
    sizes: tuple[int, ...]
    seconds: float
    paced_hz: float
    slots: int
    cells: tuple[CellResult, ...]
    memcpy: tuple[MemcpyResult, ...]
    targets: tuple[TargetCheck, ...]
    machine: Mapping[str, str] = field(default_factory=dict)
    versions: Mapping[str, str] = field(default_factory=dict)

    def cell(self, side: str, size_bytes: int) -> CellResult | None:
        return next((c for c in self.cells if (c.side, c.size_bytes) == (side, size_bytes)), None)

    def to_json(self) -> dict[str, Any]:
        return fields_json(self)


@dataclass(frozen=True, slots=True, kw_only=True)
class TargetSpread(Spread):
    """One target over the repetitions of ``--repeat N`` (every side at every size once per
    repetition, so load that comes and goes hits all sides alike): ``values`` are ratios (``≥``
    targets) or milliseconds (``≤`` targets), None where a side did not run."""

    side: str
    size_bytes: int
    target: str
    #: the floor of a latency target in each repetition (ms, :func:`copy_floor_ms`), else ()
    floors: tuple[float | None, ...] = ()

    @property
    def floor_median(self) -> float | None:
        got = sorted(f for f in self.floors if f is not None)
        return statistics.median(got) if got else None

    @property
    def floor_ratios(self) -> tuple[float | None, ...]:
        """Each repetition's value ÷ its floor (None where either is missing)."""
        return tuple(
            None if v is None or not f else v / f
            for v, f in zip(self.values, self.floors, strict=False)
        )


def copy_floor_ms(result: TransportBenchResult, side: str, size: int) -> float | None:
    """The least a paced message of ``side`` at ``size`` can take one way on this host: its
    :data:`PACED_COPIES` copies at the from-memory memcpy rate of the same run (ms; None
    without the memcpy runs or for a side not listed)."""
    mem = next((m for m in result.memcpy if m.size_bytes == size), None)
    copies = PACED_COPIES.get(side)
    if mem is None or copies is None or not mem.from_memory_gb_per_s > 0:
        return None
    return copies * size / (mem.from_memory_gb_per_s * 1e9) * 1e3


def _gb(result: TransportBenchResult, side: str, size: int) -> float | None:
    c = result.cell(side, size)
    if c is None or c.flat is None or not math.isfinite(c.flat.gb_per_s):
        return None
    return c.flat.gb_per_s


def check_targets(result: TransportBenchResult) -> tuple[TargetCheck, ...]:
    """The issue-6 targets against what ran: both redrive sides against pipe + pickle at 4 MiB,
    the from-memory copy at 16 MiB and the paced 4 MiB p99; when iceoryx2 ran (``python -m
    benchmarks transport``), in place against iceoryx2 in place at 64 KiB (issue 20), 1 and
    4 MiB."""
    checks: list[TargetCheck] = []
    sizes = set(result.sizes)
    mib4, mib16 = 4 << 20, 16 << 20
    redrive = ("redrive-copy", "redrive-inplace")

    def ratio(name: str, side: str, *, size: int, ref: float | None, bound: float) -> None:
        value = _gb(result, side, size)
        met = None if value is None or ref is None else value >= bound * ref
        checks.append(
            TargetCheck(
                name=name, side=side, size_bytes=size, value=value, reference=ref,
                target=f"≥ {bound:g}×", met=met, note="GB/s flat out",
            )
        )  # fmt: skip

    for size in (64 << 10, 1 << 20, mib4):
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
        bounds = [(f"paced p99 at {result.paced_hz:g} Hz", s, PACED_P99_TARGET_MS) for s in redrive]
        bounds.append(("paced p99 (issue 36)", "redrive-copy", PACED_P99_COPY_TARGET_MS))
        for name, side, bound in bounds:
            c = result.cell(side, mib4)
            p99 = None if c is None or c.paced is None else c.paced.latency_p99_ms
            p99 = None if p99 is None or not math.isfinite(p99) else p99
            floor = copy_floor_ms(result, side, mib4)
            note = f"ms one way; against: {PACED_COPIES[side]} copies from memory"
            checks.append(
                TargetCheck(
                    name=name, side=side, size_bytes=mib4, value=p99, reference=floor,
                    target=f"≤ {bound:g} ms", met=None if p99 is None else p99 <= bound, note=note,
                )
            )  # fmt: skip
    return tuple(checks)


def target_spreads(results: Sequence[TransportBenchResult]) -> tuple[TargetSpread, ...]:
    """Every target of the repetitions ``results``, in the order of the first repetition's."""
    first: dict[tuple[str, str, int], TargetCheck] = {}
    values: dict[tuple[str, str, int], list[float | None]] = {}
    floors: dict[tuple[str, str, int], list[float | None]] = {}
    for i, result in enumerate(results):
        for t in result.targets:
            key = (t.name, t.side, t.size_bytes)
            first.setdefault(key, t)
            at_most = t.target.startswith("≤")
            values.setdefault(key, [None] * i).append(t.value if at_most else t.ratio)
            floors.setdefault(key, [None] * i).append(t.reference if at_most else None)
        for got in (*values.values(), *floors.values()):  # a target this repetition did not check
            got.extend([None] * (i + 1 - len(got)))
    return tuple(
        TargetSpread(
            name=t.name, side=t.side, size_bytes=t.size_bytes, target=t.target,
            bound=float(t.target.strip("≥≤ ×ms")), at_most=t.target.startswith("≤"),
            values=tuple(values[k]),
            floors=tuple(floors[k]) if t.target.startswith("≤") else (),
        )
        for k, t in first.items()
    )  # fmt: skip


def _copy_rate(dst_pool: U8, src_pool: U8, size: int, seconds: float) -> float:
    k = max(1, min(len(src_pool), len(dst_pool)) // size)
    dsts = [dst_pool[i * size : (i + 1) * size] for i in range(k)]
    srcs = [src_pool[i * size : (i + 1) * size] for i in range(k)]
    for i in range(min(k, 2)):
        np.copyto(dsts[i], srcs[i])
    copies = 0
    t0 = time.perf_counter()
    deadline = t0 + seconds
    while True:
        for _ in range(max(1, k)):
            np.copyto(dsts[copies % k], srcs[(copies * 7 + 3) % k] if k > 1 else srcs[0])
            copies += 1
        now = time.perf_counter()
        if now >= deadline and copies >= 4:
            break
    return copies * size / (now - t0) / 1e9


def bench_memcpy(
    sizes: Sequence[int], *, seconds: float = 1.0, pool_bytes: int = MEMORY_POOL_BYTES
) -> tuple[MemcpyResult, ...]:
    """Single-thread ``np.copyto`` GB/s at each size: cache-hot (the same two buffers) and from
    memory (rotating over two ``pool_bytes`` pools, source and destination; the source index
    strides so consecutive copies do not walk the pool in order)."""
    nbytes = max(pool_bytes, 2 * max(sizes, default=0))
    src_pool, dst_pool = np.empty(nbytes, np.uint8), np.empty(nbytes, np.uint8)
    src_pool.fill(1)  # pre-touched: no page faults inside the timing
    dst_pool.fill(2)
    out = []
    for size in sizes:
        hot = _copy_rate(dst_pool[:size], src_pool[:size], size, seconds / 2)
        cold = _copy_rate(dst_pool, src_pool, size, seconds / 2)
        out.append(
            MemcpyResult(
                size_bytes=size, hot_gb_per_s=hot, from_memory_gb_per_s=cold, pool_bytes=nbytes
            )
        )
    return tuple(out)


def side_available(side: str, catalogue: str = CATALOGUE) -> bool:
    """Whether the package ``side`` needs imports here."""
    module = catalogue_sides(catalogue)[side].module
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # a parent package is missing
        return False


def _versions(packages: Sequence[str]) -> dict[str, str]:
    out = {"python": platform.python_version(), "numpy": np.__version__}
    for dist in dict.fromkeys([*packages, "redrive"]):
        if dist.startswith("("):  # "(standard library)"
            continue
        with contextlib.suppress(importlib.metadata.PackageNotFoundError):
            out[dist] = importlib.metadata.version(dist)
    return out


def _machine() -> dict[str, str]:
    model = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    mem = ""
    with contextlib.suppress(OSError, ValueError, IndexError):
        kb = int(Path("/proc/meminfo").read_text().split()[1])
        mem = f"{kb / 2**20:.0f} GiB"
    system = f"{platform.system()} {platform.release()}"
    return {"cpu": model, "cpus": str(os.cpu_count()), "memory": mem, "system": system}


def bench_transport(
    sizes: Sequence[int] = DEFAULT_SIZES,
    *,
    sides: Sequence[str] | None = None,
    catalogue: str = CATALOGUE,
    seconds: float = 2.0,
    paced_hz: float = 100.0,
    paced: bool = True,
    memcpy: bool = True,
    verify: bool = False,
    progress: Callable[[str], None] | None = None,
) -> TransportBenchResult:
    """Every side (default: every one of ``catalogue``, a module with ``SIDES``) at every size,
    flat out and paced, plus the memcpy ceiling.

    Each run lasts about ``seconds`` (plus process start-up); a side that is not installed or
    fails is recorded as such and the benchmark goes on.
    """
    say = progress or (lambda _text: None)
    known = catalogue_sides(catalogue)
    sides = tuple(known) if sides is None else sides
    unknown = [s for s in sides if s not in known]
    if unknown:
        msg = f"unknown transport side(s) {', '.join(unknown)}; known: {', '.join(known)}"
        raise TransportError(msg)
    for size in sizes:
        check_size(size)
    cells: list[CellResult] = []
    for side in sides:
        spec = known[side]
        if not side_available(side, catalogue):
            missing = f"{spec.module} does not import: pip install {spec.package}"
            cells += (
                CellResult(side=side, size_bytes=n, status="not installed", error=missing)
                for n in sizes
            )
            continue
        for size in sizes:
            runs: dict[str, RunResult | None] = {"flat": None, "paced": None}
            error: str | None = None
            try:
                for mode, hz in (("flat", None), ("paced", paced_hz))[: 2 if paced else 1]:
                    say(
                        f"{spec.label}, {size_label(size)}, "
                        + (f"paced at {hz:g} Hz" if hz else "flat out")
                    )
                    runs[mode] = run_cell(
                        side, size, seconds=seconds, paced_hz=hz, verify=verify, catalogue=catalogue
                    )
            except TransportError as err:
                logger.warning("%s at %s failed: %s", side, size_label(size), err)
                error = str(err)
            cells.append(
                CellResult(
                    side=side, size_bytes=size, status="ok" if error is None else "error", error=error,
                    flat=runs["flat"], paced=runs["paced"],
                )
            )  # fmt: skip
    mem: tuple[MemcpyResult, ...] = ()
    if memcpy:
        say("memcpy ceiling")
        mem = bench_memcpy(sizes, seconds=min(2.0, max(0.2, seconds)))
    result = TransportBenchResult(
        sizes=tuple(sizes), seconds=seconds, paced_hz=paced_hz, slots=SLOTS, cells=tuple(cells),
        memcpy=mem, targets=(), machine=_machine(), versions=_versions([known[s].package for s in sides]),
    )  # fmt: skip
    return dataclasses.replace(result, targets=check_targets(result))


def size_label(size: int) -> str:
    """``65536`` → ``"64 KiB"``, ``4194304`` → ``"4 MiB"``."""
    if size % (1 << 20) == 0:
        return f"{size >> 20} MiB"
    if size % (1 << 10) == 0:
        return f"{size >> 10} KiB"
    return f"{size} B"


def parse_size(text: str) -> int:
    """``"64K"``, ``"64KiB"``, ``"4M"``, ``"4MiB"``, ``"1G"`` or plain bytes → bytes (binary
    units)."""
    t = text.strip().upper().removesuffix("B").removesuffix("I")
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}
    try:
        if t and t[-1] in units:
            return round(float(t[:-1]) * units[t[-1]])
        return int(t)
    except ValueError as err:
        msg = f"not a message size: {text!r} (write e.g. 64K, 4M or 4MiB)"
        raise TransportError(msg) from err
