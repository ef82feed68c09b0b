"""The whole benchmark: every side at every size, flat out and paced, the memcpy ceiling, the
machine and package versions, the targets; message sizes as text."""

from __future__ import annotations

import contextlib
import importlib.metadata
import importlib.util
import logging
import os
import platform
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from redrive.benchmarks.transport.cell import run_cell
from redrive.benchmarks.transport.memcpy import bench_memcpy
from redrive.benchmarks.transport.payload import MIN_SIZE, SLOTS
from redrive.benchmarks.transport.results import CellResult, MemcpyResult, TransportBenchResult
from redrive.benchmarks.transport.sides import CATALOGUE, catalogue_sides
from redrive.benchmarks.transport.targets import check_targets
from redrive.errors import TransportError

__all__ = ["DEFAULT_SIZES", "bench_transport", "parse_size", "side_available", "size_label"]

logger = logging.getLogger(__name__)

DEFAULT_SIZES = (64 << 10, 1 << 20, 4 << 20, 16 << 20)


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
    return {
        "cpu": model,
        "cpus": str(os.cpu_count()),
        "memory": mem,
        "system": f"{platform.system()} {platform.release()}",
    }


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
        if size < MIN_SIZE:
            msg = f"message size {size} B is below the {MIN_SIZE} B minimum of the benchmark"
            raise TransportError(msg)
    cells: list[CellResult] = []
    for side in sides:
        spec = known[side]
        if not side_available(side, catalogue):
            cells.extend(
                CellResult(
                    side=side,
                    size_bytes=size,
                    status="not installed",
                    error=f"{spec.module} does not import: pip install {spec.package}",
                )
                for size in sizes
            )
            continue
        for size in sizes:
            flat_run = paced_run = None
            try:
                say(f"{spec.label}, {size_label(size)}, flat out")
                flat_run = run_cell(side, size, seconds=seconds, verify=verify, catalogue=catalogue)
                if paced:
                    say(f"{spec.label}, {size_label(size)}, paced at {paced_hz:g} Hz")
                    paced_run = run_cell(
                        side,
                        size,
                        seconds=seconds,
                        paced_hz=paced_hz,
                        verify=verify,
                        catalogue=catalogue,
                    )
            except TransportError as err:
                logger.warning("%s at %s failed: %s", side, size_label(size), err)
                cells.append(
                    CellResult(
                        side=side,
                        size_bytes=size,
                        status="error",
                        error=str(err),
                        flat=flat_run,
                        paced=paced_run,
                    )
                )
                continue
            cells.append(
                CellResult(side=side, size_bytes=size, status="ok", flat=flat_run, paced=paced_run)
            )
    mem: tuple[MemcpyResult, ...] = ()
    if memcpy:
        say("memcpy ceiling")
        mem = bench_memcpy(sizes, seconds=min(2.0, max(0.2, seconds)))
    partial = TransportBenchResult(
        sizes=tuple(sizes),
        seconds=seconds,
        paced_hz=paced_hz,
        slots=SLOTS,
        cells=tuple(cells),
        memcpy=mem,
        targets=(),
        machine=_machine(),
        versions=_versions([known[s].package for s in sides]),
    )
    return TransportBenchResult(
        sizes=partial.sizes,
        seconds=seconds,
        paced_hz=paced_hz,
        slots=SLOTS,
        cells=partial.cells,
        memcpy=mem,
        targets=check_targets(partial),
        machine=partial.machine,
        versions=partial.versions,
    )


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
