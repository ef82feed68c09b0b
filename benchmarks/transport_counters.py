"""Load-independent counters of the shared-memory transports: a fixed number of messages.

Runs the publisher and the subscriber of one ``redrive bench transport`` side (``redrive-inplace``,
``iceoryx2``, ``redrive-copy``, …; the same sender/receiver code and per-message work as the
benchmark) as two processes that move exactly ``--count`` messages flat out, each process under a
wrapper command, so the counters of each side are its own::

    python benchmarks/transport_counters.py --side redrive-inplace --size 1M --count 2000 \
        --wrap 'perf stat -x, -e page-faults,context-switches -o {out}'
    python benchmarks/transport_counters.py ... --wrap 'strace -c -f -o {out}'
    python benchmarks/transport_counters.py ... --wrap 'valgrind --tool=callgrind \
        --callgrind-out-file={out}'

Without ``--wrap``, ``--times`` prints what each process's message loop took per message: its
thread CPU time (``time.thread_time_ns``: the work, less sensitive to other load than wall time),
its wall time and its voluntary context switches (sleeps)::

    python benchmarks/transport_counters.py --side iceoryx2 --size 4M --count 2000 --times

``{out}`` becomes ``OUTDIR/<side>.<size>.<count>.<role>.txt`` (``--outdir``, default a temporary
directory, printed). Counts per message are taken as the difference between a run of ``2N`` and one
of ``N`` messages, divided by ``N`` (``--per-message``): start-up, imports and segment creation
cancel out. Under callgrind (``--instr-atstart=no`` is added) only the message loop is
instrumented (client requests through a tiny C library built with ``cc``): total / ``N + 1``. Start and end are handshakes through FIFOs (one blocking ``open`` each), not polling,
so the system calls outside the message loop do not depend on timing.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import re
import resource
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve()

_CALLGRIND_C = """#include <valgrind/callgrind.h>
void start(void) { CALLGRIND_START_INSTRUMENTATION; }
void stop(void) { CALLGRIND_STOP_INSTRUMENTATION; }
"""


class _Instrumentation:
    """Callgrind's instrumentation switched on around the message loop only (a tiny C library
    with its client requests, built with ``cc``; a no-op when not under ``--callgrind``)."""

    def __init__(self, lib_dir: str | None) -> None:
        self.lib: ctypes.CDLL | None = None
        if lib_dir:
            self.lib = ctypes.CDLL(str(Path(lib_dir) / "libcgtoggle.so"))

    def start(self) -> None:
        if self.lib is not None:
            self.lib.start()

    def stop(self) -> None:
        if self.lib is not None:
            self.lib.stop()


class _LoopClocks:
    """Thread CPU, wall time, voluntary context switches (sleeps) and involuntary ones (the core
    taken away: a preemption, or a ``sched_yield`` that let another task run) of the message
    loop (``--times``)."""

    def __init__(self, label: str, count: int, *, show: bool) -> None:
        self.label, self.count, self.show = label, count, show
        self.cpu = self.wall = self.sleeps = self.taken = 0

    def start(self) -> None:
        self.cpu, self.wall = time.thread_time_ns(), time.monotonic_ns()
        usage = resource.getrusage(resource.RUSAGE_THREAD)
        self.sleeps, self.taken = usage.ru_nvcsw, usage.ru_nivcsw

    def stop(self) -> None:
        cpu, wall = time.thread_time_ns() - self.cpu, time.monotonic_ns() - self.wall
        usage = resource.getrusage(resource.RUSAGE_THREAD)
        sleeps, taken = usage.ru_nvcsw - self.sleeps, usage.ru_nivcsw - self.taken
        if self.show:
            n = self.count + 1
            print(
                f"{self.label}\tcpu_us_per_msg\t{cpu / n / 1e3:.1f}\twall_us_per_msg\t"
                f"{wall / n / 1e3:.1f}\tsleeps_per_msg\t{sleeps / n:.2f}\t"
                f"switched_out_per_msg\t{taken / n:.2f}",
                flush=True,
            )


def _build_toggle(where: Path) -> None:
    src = where / "cgtoggle.c"
    src.write_text(_CALLGRIND_C)
    subprocess.run(
        ["cc", "-O2", "-shared", "-fPIC", "-o", str(where / "libcgtoggle.so"), str(src)],
        check=True,
    )


def _role_main(args: argparse.Namespace) -> None:
    from benchmarks.transport_peers import SIDES
    from redrive.benchmarks.transport.sides import END_SEQ, CellConfig, _Tally

    spec = SIDES[args.side]
    cfg = CellConfig(
        side=args.side,
        size_bytes=args.size,
        seconds=0.0,
        paced_hz=None,
        verify=False,
        endpoint=args.endpoint,
    )
    start, done = Path(args.fifo_dir) / "start", Path(args.fifo_dir) / "done"
    instr = _Instrumentation(args.fifo_dir if args.callgrind else None)
    clocks = _LoopClocks(f"{args.side}\t{args.size}\t{args.role}", args.count, show=args.times)
    if args.role == "pub":
        tx = spec.make_sender(cfg, None)
        with start.open("rb") as f:  # blocks until the subscriber is attached
            f.read()
        tx.wait_connected(20.0)
        clock = time.monotonic_ns
        instr.start()
        clocks.start()
        for seq in range(args.count):
            tx.send(seq, clock())
        tx.send(END_SEQ, clock())
        clocks.stop()
        instr.stop()
        with done.open("rb") as f:  # the subscriber has everything
            f.read()
        tx.close()
        return
    tally = _Tally(cfg)
    rx = spec.make_receiver(cfg, None, tally)
    with start.open("wb") as f:
        f.write(b"go")
    deadline = time.monotonic() + 600.0
    instr.start()
    clocks.start()
    while not tally.ended and time.monotonic() < deadline:
        rx.recv(1.0)
    clocks.stop()
    instr.stop()
    got = len(tally.seen)
    with done.open("wb") as f:
        f.write(b"done")
    rx.close()
    if got != args.count or tally.corrupt:
        sys.exit(f"subscriber: {got} of {args.count} messages, {tally.corrupt} corrupt")


def run_pair(  # noqa: PLR0917
    side: str, size: int, count: int, wrap: str, outdir: Path, times: bool = False
) -> dict[str, Path]:
    """Run publisher and subscriber of ``side`` for ``count`` messages; returns the out files."""
    fifo_dir = Path(tempfile.mkdtemp(prefix="redrive-counters-"))
    os.mkfifo(fifo_dir / "start")
    os.mkfifo(fifo_dir / "done")
    callgrind = "callgrind" in wrap
    if callgrind:
        _build_toggle(fifo_dir)
    endpoint = f"counters-{os.getpid()}-{count}"
    outs: dict[str, Path] = {}
    procs = []
    for role in ("pub", "sub"):  # publisher first, as the benchmark does
        out = outdir / f"{side}.{size}.{count}.{role}.txt"
        outs[role] = out
        prefix = shlex.split(wrap.format(out=out)) if wrap else []
        if callgrind:
            prefix.insert(prefix.index("--tool=callgrind") + 1, "--instr-atstart=no")
        cmd = [*prefix, sys.executable, str(HERE), "--role", role, "--side", side]
        cmd += ["--size", str(size), "--count", str(count), "--endpoint", endpoint]
        cmd += ["--fifo-dir", str(fifo_dir)] + (["--callgrind"] if callgrind else [])
        cmd += ["--times"] if times else []
        procs.append(subprocess.Popen(cmd))
        if role == "pub":
            time.sleep(
                15.0 if "valgrind" in wrap or "py-spy" in wrap else 2.0
            )  # let it create the service
    while any(p.poll() is None for p in procs):  # one failing: stop the other (it would block)
        if any(p.returncode for p in procs):
            for p in procs:
                if p.poll() is None:
                    p.kill()
        time.sleep(0.1)
    codes = [p.returncode for p in procs]
    shutil.rmtree(fifo_dir)
    if any(codes):
        sys.exit(f"{side} {size} B × {count}: exit codes {codes}")
    return outs


def parse_counters(path: Path) -> dict[str, float]:
    """perf stat -x, / strace -c / callgrind out → {counter: value}."""
    text = path.read_text()
    out: dict[str, float] = {}
    if "events:" in text and "summary:" in text:  # callgrind
        # with instrumentation switched on and off, "summary" can be 0 and "totals" holds the sum
        m = re.search(r"^totals: (\d+)", text, re.M) or re.search(r"^summary: (\d+)", text, re.M)
        if m:
            out["instructions"] = float(m.group(1))
        return out
    if "% time" in text:  # strace -c
        for line in text.splitlines():
            parts = line.split()
            if len(parts) >= 5 and parts[0][0].isdigit() and not line.startswith("100.00"):
                name = parts[-1]
                calls = int(parts[3])
                out[f"sys:{name}"] = float(calls)
            if parts and parts[-1] == "total":
                out["syscalls"] = float(parts[2] if len(parts) == 5 else parts[3])
        return out
    for line in text.splitlines():  # perf stat -x,
        fields = line.split(",")
        if len(fields) >= 3 and fields[0].replace(".", "").isdigit():
            out[fields[2]] = float(fields[0])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--side", default="redrive-inplace")
    ap.add_argument("--size", default="1M")
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--wrap", default="", help="command prefix; {out} is the output file")
    ap.add_argument("--outdir", type=Path, default=None)
    ap.add_argument(
        "--per-message", action="store_true", help="runs of count and 2×count; prints Δ/count"
    )
    ap.add_argument(
        "--times", action="store_true", help="print each loop's CPU/wall µs and sleeps per message"
    )
    ap.add_argument("--role", choices=("pub", "sub"), help=argparse.SUPPRESS)
    ap.add_argument("--endpoint", help=argparse.SUPPRESS)
    ap.add_argument("--fifo-dir", help=argparse.SUPPRESS)
    ap.add_argument("--callgrind", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.role:
        args.size = int(args.size)
        _role_main(args)
        return
    from redrive.benchmarks.transport import parse_size

    size = parse_size(args.size)
    outdir = args.outdir or Path(tempfile.mkdtemp(prefix="redrive-counters-out-"))
    outdir.mkdir(parents=True, exist_ok=True)
    callgrind = "callgrind" in args.wrap  # counts only the message loop: no difference needed
    counts = (args.count, 2 * args.count) if args.per_message and not callgrind else (args.count,)
    results = {n: run_pair(args.side, size, n, args.wrap, outdir, args.times) for n in counts}
    print(f"# outputs in {outdir}")
    if not args.per_message:
        return
    if callgrind:
        for role in ("pub", "sub"):
            got = parse_counters(results[args.count][role])
            per = got.get("instructions", float("nan")) / (args.count + 1)
            print(f"{args.side}\t{args.size}\t{role}\tinstructions\t{per:.0f}")
        return
    for role in ("pub", "sub"):
        a = parse_counters(results[counts[0]][role])
        b = parse_counters(results[counts[1]][role])
        for key in sorted(set(a) | set(b)):
            delta = (b.get(key, 0.0) - a.get(key, 0.0)) / args.count
            if abs(delta) >= 0.005:
                print(f"{args.side}\t{args.size}\t{role}\t{key}\t{delta:.3f}")


if __name__ == "__main__":
    main()
