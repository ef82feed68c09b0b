"""``redrive run LOG`` sequential against pipelined: wall, CPU per thread and how far two cores
could take the pipelined mode, interleaved fresh processes (issue 36, item 1).

    PYTHONPATH=src .venv/bin/python -m benchmarks.pipelined_overlap LOG [--rounds 3]
        [--tree NAME=SRC ...] [--switch-interval-ms MS]

Each pass is a fresh interpreter (``PYTHONPATH`` at the tree's ``src``) that runs the reference
pipeline over LOG once to warm it, then once measured, in one mode; sequential and pipelined
alternate (which goes first rotates each round).  Inside the measured :meth:`Engine.run` it
records the wall time, the process CPU time and every thread's CPU time (``/proc/self/task/*/
schedstat``, sampled every 5 ms, threads named by ``threading``).  Printed per tree and mode:
medians of wall, CPU ÷ wall (cores in use) and thread CPU; then

- ``pipelined ÷ sequential``: the median over rounds of the two passes' wall ratio — the figure
  of the ≥ 1.6× target; meaningful only on a quiet machine (the load average is printed before
  every pass: wait for an idle core);
- ``two-core bound``: the same ratio of the least wall each pass could take on two free cores by
  its CPU time, ``max(CPU ÷ 2, busiest thread)`` — what the pipelined mode could reach at best,
  measured under any load (CPU time inflates far less than wall time), ignoring the GIL (threads
  holding it serialise, so the real figure sits below);
- ``with the GIL-held time as a floor too``: the same with each pipelined pass's CPU outside its
  GIL-free calls — the numba kernels the algorithms call (each call's thread CPU, wrapped here),
  the chunks' zstd decompression and CRC — as one more floor of its wall time: that time cannot
  overlap (numpy calls that release the GIL count as held, so it is an upper estimate).

The sequential mode uses a second core already: the MCAP reader decompresses and checks the next
chunks in a thread of its own while the frames run (``redrive-prefetch``), so ``CPU ÷ wall`` of a
sequential pass is above 1 and the two-core bound below 2.  Every results table of a round's two
passes is compared (timing columns and ``resources`` aside); a difference is reported and the
exit status is 1.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

_CHILD = r"""
import json, os, sys, threading, time
from pathlib import Path
from redrive.config import reference_pipeline
from redrive.engine import RunRequest, run_log
from redrive.engine import core

log, out, mode, switch_ms = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3], float(sys.argv[4])
if switch_ms > 0:
    sys.setswitchinterval(switch_ms / 1000)

def runtimes():
    found = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            found[int(tid)] = int(open(f"/proc/self/task/{tid}/schedstat").read().split()[0])
        except (OSError, ValueError):
            pass
    return found

names, last, stop = {}, {}, threading.Event()

def sample():
    while not stop.wait(0.005):
        for t in threading.enumerate():
            if t.native_id is not None:
                names[t.native_id] = t.name
        last.update(runtimes())

measured = {}
original = core.Engine.run

def run(self, *args, **kwargs):
    in_kernels.clear()
    before = runtimes()
    c0, w0 = time.process_time(), time.perf_counter()
    try:
        return original(self, *args, **kwargs)
    finally:
        w1, c1 = time.perf_counter(), time.process_time()
        time.sleep(0.02)
        after = {**last, **runtimes()}
        threads = {}
        for tid, ns in after.items():
            name = names.get(tid, str(tid))
            used = (ns - before.get(tid, 0)) / 1e9
            if used > 0.001:
                threads[name] = threads.get(name, 0.0) + used
        threads.pop("redrive-overlap-sampler", None)
        measured.update(wall_s=w1 - w0, cpu_s=c1 - c0, threads=threads)
        measured["kernels"] = {k: v / 1e9 for k, v in in_kernels.items()}

core.Engine.run = run

# the numba kernels (nogil) the algorithms call from Python: each call's thread CPU, per thread
import importlib, pkgutil
import numba
import redrive.algorithms.reference as reference
from redrive.io.mcap import scan

in_kernels = {}

def timed(kernel):
    def call(*args, **kwargs):
        t = time.thread_time_ns()
        try:
            return kernel(*args, **kwargs)
        finally:
            name = threading.current_thread().name
            in_kernels[name] = in_kernels.get(name, 0) + time.thread_time_ns() - t
    return call

modules = [importlib.import_module(f"redrive.algorithms.reference.{m.name}")
           for m in pkgutil.iter_modules(reference.__path__)]
modules.append(importlib.import_module("redrive.motion.idm"))
wrapped = {}
for module in modules:
    for attr, value in list(vars(module).items()):
        if isinstance(value, numba.core.registry.CPUDispatcher):
            if id(value) not in wrapped:
                wrapped[id(value)] = timed(value)
            setattr(module, attr, wrapped[id(value)])
# the chunk reads' GIL-free work: zstd / lz4 decompression and the CRC (the record parsing after
# them holds the GIL)
if hasattr(scan, "crc32"):
    scan.crc32 = timed(scan.crc32)
else:  # a tree from before the isal CRC: zlib's
    class _Zlib:
        def __init__(self, real):
            self._real = real
            self.crc32 = timed(real.crc32)
        def __getattr__(self, name):
            return getattr(self._real, name)
    scan.zlib = _Zlib(scan.zlib)
class _Zstd:
    def __init__(self, real):
        self._real = real
    def __getattr__(self, name):
        return getattr(self._real, name)
    def ZstdDecompressor(self, *args, **kwargs):
        d = self._real.ZstdDecompressor(*args, **kwargs)
        class _D:
            decompress = staticmethod(timed(lambda raw, **kw: d.decompress(raw, **kw)))
        return _D()
scan.zstandard = _Zstd(scan.zstandard)
pipeline = reference_pipeline().with_options(mode=mode)
run_log(RunRequest(log=log, pipeline=pipeline, out=out.with_name(out.name + "-warm")))
sampler = threading.Thread(target=sample, name="redrive-overlap-sampler", daemon=True)
sampler.start()
report = run_log(RunRequest(log=log, pipeline=pipeline, out=out))
stop.set()
steps = {a.name: a.cpu_mean_ms * a.ok / 1000 for a in report.algorithms}
print(json.dumps({**measured, "rtf": report.realtime_factor, "frames": report.frames, "steps": steps}))
"""

_TIMING = {"wall_ns", "late", "latency_ns", "cpu_ns"}


def _load() -> str:
    return Path("/proc/loadavg").read_text().split()[0]


def _pass(src: str, log: Path, out: Path, mode: str, switch_ms: float) -> dict[str, object]:
    env = {**os.environ, "PYTHONPATH": src}
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, str(log), str(out), mode, str(switch_ms)],
        env=env,
        check=False,
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        sys.exit(f"the {mode} pass of {src} failed:\n{done.stderr[-4000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def _differing(a: Path, b: Path) -> list[str]:
    import pyarrow.parquet as pq

    differ = []
    for table in sorted(p.name for p in a.iterdir() if p.is_dir() and p.name != "resources"):
        ta, tb = pq.read_table(a / table), pq.read_table(b / table)
        cols = [c for c in ta.column_names if c not in _TIMING]
        if ta.column_names != tb.column_names or not ta.select(cols).equals(tb.select(cols)):
            differ.append(table)
    return differ


def _least(one: dict[str, object]) -> float:
    """The least wall time a pass's CPU allows on two free cores: half its CPU, or its
    busiest thread's CPU if that is more (the GIL ignored)."""
    threads = one["threads"]
    assert isinstance(threads, dict)
    return max(float(one["cpu_s"]) / 2, *threads.values())  # type: ignore[arg-type]


def _gil(one: dict[str, object]) -> float:
    """CPU time a pass spent outside its GIL-free calls (numba kernels, decompression, CRC):
    an upper estimate of the time it held the GIL (numpy calls that release it count as held),
    which no number of cores shortens."""
    threads, kernels = one["threads"], one["kernels"]
    assert isinstance(threads, dict)
    assert isinstance(kernels, dict)
    return float(sum(threads.values()) - sum(kernels.values()))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", type=Path, metavar="LOG")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument(
        "--tree",
        action="append",
        default=[],
        metavar="NAME=SRC",
        help="a source tree to measure (repeatable; default: this tree's src)",
    )
    parser.add_argument(
        "--switch-interval-ms",
        type=float,
        default=0.0,
        help="sys.setswitchinterval in every pass (0: the interpreter's default)",
    )
    args = parser.parse_args(argv)
    trees = [t.split("=", 1) for t in args.tree] or [["this", "src"]]
    modes = ("sequential", "pipelined")
    passes: dict[tuple[str, str], list[dict[str, object]]] = {}
    bad = 0
    with tempfile.TemporaryDirectory(prefix="redrive-overlap-") as tmp:
        for r in range(args.rounds):
            for name, src in trees:
                order = modes if r % 2 == 0 else modes[::-1]
                for mode in order:
                    print(f"round {r + 1} {name} {mode}: load {_load()}", file=sys.stderr)
                    out = Path(tmp) / f"{name}-{mode}-{r}"
                    got = _pass(src, args.log, out, mode, args.switch_interval_ms)
                    passes.setdefault((name, mode), []).append(got)
                differ = _differing(
                    Path(tmp) / f"{name}-sequential-{r}", Path(tmp) / f"{name}-pipelined-{r}"
                )
                if differ:
                    bad = 1
                    print(f"round {r + 1} {name}: tables differ: {', '.join(differ)}")
    for name, _src in trees:
        for mode in modes:
            got = passes[(name, mode)]
            wall = statistics.median(float(p["wall_s"]) for p in got)  # type: ignore[arg-type]
            cores = statistics.median(
                float(p["cpu_s"]) / float(p["wall_s"])  # type: ignore[arg-type]
                for p in got
            )
            names = sorted({t for p in got for t in p["threads"]})  # type: ignore[attr-defined]
            threads = {
                t: statistics.median(float(p["threads"].get(t, 0.0)) for p in got)  # type: ignore[attr-defined]
                for t in names
            }
            shown = ", ".join(
                f"{t.removeprefix('redrive-')} {s:.2f}"
                for t, s in sorted(threads.items(), key=lambda kv: -kv[1])
                if s >= 0.01
            )
            step_names = list(got[0]["steps"])  # type: ignore[call-overload]
            steps = ", ".join(
                f"{a} {statistics.median(float(p['steps'][a]) for p in got):.2f}"  # type: ignore[index]
                for a in step_names
            )
            free = {
                t.removeprefix("redrive-"): statistics.median(
                    float(p["kernels"].get(t, 0.0))  # type: ignore[attr-defined]
                    for p in got
                )
                for t in sorted({t for p in got for t in p["kernels"]})  # type: ignore[attr-defined]
            }
            gil = statistics.median(_gil(p) for p in got)
            print(
                f"{name} {mode:10s}: GIL-free calls (kernels, decompression, CRC) s: "
                + ", ".join(f"{t} {v:.2f}" for t, v in free.items() if v >= 0.01)
                + f"; the rest (GIL held, at most) {gil:.2f} s"
            )
            print(
                f"{name} {mode:10s}: wall {wall:.2f} s, {cores:.2f} cores (CPU / wall), CPU "
                f"{statistics.median(float(p['cpu_s']) for p in got):.2f} s; "  # type: ignore[arg-type]
                f"thread CPU s: {shown}; in the steps: {steps}"
            )
        seq, pip = passes[(name, "sequential")], passes[(name, "pipelined")]
        ratios = [float(s["wall_s"]) / float(p["wall_s"]) for s, p in zip(seq, pip, strict=True)]  # type: ignore[arg-type]
        bounds = [_least(s) / _least(p) for s, p in zip(seq, pip, strict=True)]
        gil_bounds = [_least(s) / max(_least(p), _gil(p)) for s, p in zip(seq, pip, strict=True)]
        print(
            f"{name}: pipelined ÷ sequential {statistics.median(ratios):.2f}× "
            f"({' '.join(f'{x:.2f}' for x in ratios)}); two-core bound by CPU "
            f"{statistics.median(bounds):.2f}× ({' '.join(f'{x:.2f}' for x in bounds)}); "
            f"with the GIL-held time as a floor too {statistics.median(gil_bounds):.2f}×"
        )
    print(f"load {_load()}")
    return bad


if __name__ == "__main__":
    raise SystemExit(main())
