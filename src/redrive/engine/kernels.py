"""Compile the numba kernels of ``make demo``'s path once, ahead of the first run.

The reference algorithms (and the simulated world behind ``redrive synth``) are numba kernels
with ``cache=True``: compiled on first use and written to numba's on-disk cache (``__pycache__``
next to each kernel's file, or ``NUMBA_CACHE_DIR``), then loaded from it by every later process.
On a fresh machine the first use was the user's first ``redrive synth`` / ``redrive run`` — tens of
seconds of compiling, some of it inside the first frames.  :func:`compile_kernels` takes that cost
at install time (the Makefile runs ``python -m redrive.engine.kernels`` after ``pip install``): it
synthesizes a one-second ``urban`` log into a temporary directory and replays it through the
reference pipeline, so every kernel is compiled with exactly the argument types a real synth and
a real run give it (a read-only decoded cloud and a strided one are different types to numba),
then loads each reference algorithm's own warm-up (its ``warm_kernels``, what ``bind`` runs).
The install step the Makefile runs is ``python -m redrive.closedloop.kernels``: this, then the
closed loop's own kernels (a layer above the engine).

A kernel whose source file changes is compiled again on its next use (numba compares the file's
stamp); ``make clean-kernels`` drops the cache.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

__all__ = ["KernelReport", "compile_kernels", "compiled_during", "main", "print_report"]

#: the log :func:`compile_kernels` synthesizes and replays (the demo's scenario, shorter)
WARM_SCENARIO = "urban"
WARM_DURATION_S = 1.0


@dataclass(frozen=True, slots=True, kw_only=True)
class KernelReport:
    """What :func:`compile_kernels` did.

    Attributes:
        compiled: the redrive kernels compiled (``module.function``, one entry a signature).
        wall_s: how long it took.
    """

    compiled: tuple[str, ...]
    wall_s: float


@contextmanager
def compiled_during() -> Iterator[list[str]]:
    """The redrive kernels numba compiles (not loads from its cache) inside the ``with`` block,
    one ``module.function`` entry a signature, in the order compiled; numba's own helpers that
    a kernel's compilation compiles with it are left out."""
    from numba.core import event

    compiled: list[str] = []

    class _Listener(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            pass

        def on_end(self, ev: event.Event) -> None:
            func = ev.data["dispatcher"].py_func
            if func.__module__.startswith("redrive."):
                compiled.append(f"{func.__module__}.{func.__qualname__}")

    listener = _Listener()
    event.register("numba:compile", listener)  # type: ignore[no-untyped-call]
    try:
        yield compiled
    finally:
        event.unregister("numba:compile", listener)  # type: ignore[no-untyped-call]


def compile_kernels(*, workdir: Path | None = None) -> KernelReport:
    """Compile (or load, when cached) every kernel of the synth → run path of the reference
    pipeline, as the module text says; ``workdir`` holds the throwaway log and run (default: a
    temporary directory, removed after)."""
    from redrive.config import reference_pipeline
    from redrive.engine.run import RunRequest, run_log
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize

    t0 = time.perf_counter()
    with compiled_during() as compiled, tempfile.TemporaryDirectory(dir=workdir) as tmp:
        log = Path(tmp) / "kernels.mcap"
        synthesize(load_scenario(WARM_SCENARIO), log, duration_s=WARM_DURATION_S)
        for mode in ("sequential", "pipelined"):
            pipeline = reference_pipeline().with_options(mode=mode)
            run_log(RunRequest(log=log, pipeline=pipeline, out=Path(tmp) / mode))
    return KernelReport(compiled=tuple(compiled), wall_s=time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m redrive.engine.kernels",
        description=(
            "Compile the numba kernels of `redrive synth` and of the reference pipeline into "
            "numba's on-disk cache, so that the first `redrive run` loads them instead of "
            "compiling them (make venv / make demo run this after installing)."
        ),
    )
    parser.parse_args(argv)
    print_report(compile_kernels())
    return 0


def print_report(report: KernelReport) -> None:
    """The install step's one line: how many signatures were compiled, in how long."""
    if report.compiled:
        print(
            f"compiled {len(report.compiled)} kernel signatures in {report.wall_s:.1f} s "
            "(numba's cache; later runs load them)"
        )
    else:
        print(f"kernels already compiled (loaded from numba's cache in {report.wall_s:.1f} s)")


if __name__ == "__main__":
    sys.exit(main())
