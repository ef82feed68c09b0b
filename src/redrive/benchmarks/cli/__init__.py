"""``redrive bench …``: the argument parsers and reports of the benchmarks (``transport`` in
its module); :func:`register` adds the ``bench`` command group to redrive's CLI (which imports this
package only to register it).  Each handler imports its benchmark when it runs; ``python -m
benchmarks`` builds ``read-synth`` on :func:`add_read_arguments` and :func:`run_read`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from redrive.benchmarks.cli._console import (
    add_command,
    flag,
    option,
    print_json,
    report_console,
    spinner,
    spread_table,
    verdict,
)
from redrive.benchmarks.cli.transport import add_transport_parser

__all__ = ["EPILOG", "LEVELS", "add_read_arguments", "register", "run_read"]

#: redrive.benchmarks.closed_loop.LEVELS, kept here so building the parser imports no simulator
#: (tests/bench checks they agree)
LEVELS = ("object", "sensor")

EPILOG = """\
examples:
  redrive bench read drive.bag                       all PointCloud2 topics, 3 repeats
  redrive bench read drive.bag --topic /velodyne_points --repeat 5 --json
  redrive bench read recording.mcap --tune-malloc    multi-MB clouds: no allocator page faults

Every pass runs in a fresh Python process (so peak RSS is per pass); the page cache is warmed by
reading the log once first. Only the message loop is timed: imports and redrive's once-a-process
decoder lookup come before it, opening is shown apart. The ratio is redrive's throughput over the
raw read's (target ≥ 0.8).
"""

_READ_DESCRIPTION = """\
Time reading every sensor_msgs/PointCloud2 message of a log two ways, in the same run: raw
(rosbags for ROS 1 / ROS 2 bags, mcap for .mcap files, no deserialisation) and redrive (open_log +
decode to a PointCloud). Prints messages/s, MB/s of payload, the redrive/raw ratio and the peak
resident memory of each pass. (A synthetic bag of any size to run it on:
`PYTHONPATH=src python -m benchmarks read-synth SIZE_GB OUT.bag` in a checkout.)
"""


def _mb(n: float) -> str:
    return f"{n / 1e6:,.1f}"


def _print_report(result: Any, *, synth: Any | None) -> None:
    from rich.table import Table

    raw, ours = result.raw, result.redrive
    repeats = len(result.redrive_passes)
    env = " ".join(f"{k}={v}" for k, v in result.pass_env.items())
    lines = [
        f"[bold]log[/]:       {result.path} ({result.log_format}, {_mb(result.file_bytes)} MB)",
        f"[bold]topics[/]:    {', '.join(result.topics)}",
        f"[bold]read[/]:      {result.messages} messages, {_mb(result.payload_bytes)} MB payload, "
        f"{result.points:,} points",
        f"[bold]method[/]:    median of {repeats} repeats, each pass a fresh process; page cache "
        + ("warmed by one full read first" if result.warmed else "NOT warmed"),
        f"[bold]malloc[/]:    {f'tuned ({env})' if result.pass_env else 'glibc defaults'}",
    ]
    if synth is not None:
        lines.insert(1, f"[bold]synthetic[/]: {synth.messages} × {synth.points_per_message:,} "
                     f"points, {_mb(synth.payload_bytes)} MB payload")  # fmt: skip
    console = report_console()
    console.print("\n".join(lines))
    table = Table()
    cols = ("msgs/s", "MB/s", "best MB/s", "loop s", "open s", "RSS start MB", "peak RSS MB")
    table.add_column("pass", justify="left")
    for col in cols:
        table.add_column(col, justify="right")
    for name, side in (("raw (baseline)", raw), ("redrive (decode)", ours)):
        table.add_row(
            name, f"{side.msgs_per_s:,.1f}", f"{side.mb_per_s:,.0f}", f"{side.best_mb_per_s:,.0f}",
            f"{side.median_loop_s:.4f}", f"{side.median_open_s:.4f}", _mb(side.rss_start_bytes),
            _mb(side.peak_rss_bytes),
        )  # fmt: skip
    console.print(table)
    from redrive.benchmarks.read import TARGET_RATIO

    console.print(
        f"[bold]ratio[/] redrive/raw: {result.ratio:.2f}× (best-of-{repeats}: "
        f"{result.best_ratio:.2f}×) — {verdict(result.ratio >= TARGET_RATIO)} the {TARGET_RATIO}× "
        "target"
    )


def run_read(
    args: argparse.Namespace, *, synth: Any | None = None, synth_json: dict[str, Any] | None = None
) -> int:
    """Benchmark ``args.log`` and print the report or JSON; ``synth``: the synthetic log it was
    written as (``python -m benchmarks read-synth``), shown and put in the JSON as ``synth_json``."""
    from redrive.benchmarks.read import TUNED_MALLOC_ENV, bench_read

    with spinner() as progress:
        result = bench_read(
            args.log, topics=args.topic, repeats=args.repeat, warm=not args.no_warm,
            pass_env=TUNED_MALLOC_ENV if args.tune_malloc else None, progress=progress,
        )  # fmt: skip
    if args.json:
        out = result.to_json()
        if synth_json is not None:
            out["synthetic"] = synth_json
        print_json(out)
    else:
        _print_report(result, synth=synth)
    return 0


def add_read_arguments(read: Any) -> None:
    """The options of a read benchmark (``redrive bench read`` and ``read-synth``)."""
    read.add_argument(
        "--topic",
        action="append",
        default=None,
        metavar="T",
        help="a PointCloud2 topic to read (repeatable; default: every PointCloud2 topic)",
    )
    option(read, "--repeat", 3, "N", "passes per side (default 3)")
    flag(read, "--json", "print JSON (every pass) instead of a table")
    flag(read, "--no-warm", "do not read the log once before measuring")
    flag(read, "--tune-malloc", "run both passes with glibc MALLOC_MMAP_THRESHOLD_=64MiB, "
         "MALLOC_TRIM_THRESHOLD_=256MiB (no page-fault churn on multi-MB messages: measures CPU "
         "work, not the allocator)")  # fmt: skip


def add_read_parser(bench_sub: Any) -> None:
    read = add_command(
        bench_sub, "read", "read + decode PointCloud2 messages against a raw rosbags/mcap read",
        _READ_DESCRIPTION, EPILOG,
    )  # fmt: skip
    read.add_argument("log", type=Path, metavar="LOG", help="a .bag, .mcap or ROS 2 bag directory")
    add_read_arguments(read)
    read.set_defaults(func=run_read)


_ENGINE = """\
Three stages each doing ~1 ms of numpy work over frames already in memory, run by the engine
(sequential and pipelined) and by a bare Python loop calling the same three functions, in the same
run, interleaved; the ratios are the engine's throughput over the loop's (targets: >= 0.95
sequential, >= 1.5 pipelined on 2 cores). With no-op stages, the engine's own cost per frame
(timing, output checks, records; target <= 20 us), and with the Parquet results writer added
(target <= 50 us), in wall time and in CPU time: of the thread running them, and with the
writer of the whole process, whose pool threads write the Parquet parts (a loaded machine
inflates wall time far more). Every variant runs once per pass, passes interleaved; the figures
are medians, and with --repeat N > 1 a table gives each target's min / median / max over the
N passes (verdict on the median). (The reference pipeline on a log of yours: `redrive run LOG
--mode sequential|pipelined` reports its frames/s and real-time factor.)
"""

_CLOSED_LOOP = """\
Run a scenario closed loop (default: urban, 20 s, object level) with noisy-oracle -> idm-planner
-> pure-pursuit-pid, results written to a run directory as `redrive run SCENARIO --closed-loop`
does, and report the real-time factor (simulated s / wall s; target >= 100x at object level) and
the split of the wall time between simulation (the simulator's observe and step), algorithms (the
step latencies of the run's steps table) and other (engine records, results writer). Baseline,
in the same run and interleaved: the scenario's world stepped alone with its scripted driver to
the same end, the cost floor of the simulation (the closed loop steps two worlds: the expert one
and the driven one). CPU seconds beside the wall times (the process's over the call, the
simulation's and the algorithms', the world alone's): on a shared machine they are the figures
that tell the code's cost from the load. Medians of --repeat passes.

--level sensor runs the reference pipeline (cluster-detector -> kalman-tracker -> idm-planner ->
pure-pursuit-pid) on the scenario's rig re-rendered from the driven ego every step, its first 3D
LiDAR swapped for --lidar (default HDL-64E, 64 beams; target >= 1x real time), and splits
rendering (the sensor models and handing their messages to the frames and to the run's
sensors.mcap) out of simulation (the worlds' physics and the rest).
"""

_EVAL = """\
Evaluate RUN's metrics as `redrive evaluate` does (one set of loaded tables per algorithm shared
by the metrics, in the order given; nothing is stored) and report the process CPU seconds of
reading the run's tables and of each metric. A metric's figure is its cost after the metrics
before it: work they share (NAVSIM's PDMS and EPDMS share their simulated proposals) counts for
the first.
"""


def _engine_report(result: Any, repeats: int) -> None:
    from redrive.benchmarks.engine import OVERHEAD_TARGET_US as US
    from redrive.benchmarks.engine import PIPELINED_TARGET, SEQUENTIAL_TARGET

    seq, pipe = result.sequential_ratio, result.pipelined_ratio
    us, writer_us = result.overhead_us_per_frame, result.writer_us_per_frame
    cpu_us = result.writer_cpu_us_per_frame
    lines = [
        f"[bold]frames[/] {result.frames}, 3 stages × {result.work_ms:g} ms of numpy work "
        f"({result.work_elements:,} float64 elements), medians of {repeats} passes",
        f"bare loop {result.bare_s:.3f} s | sequential {result.sequential_s:.3f} s → "
        f"{seq:.2f}x {verdict(seq >= SEQUENTIAL_TARGET)} {SEQUENTIAL_TARGET}x | pipelined "
        f"{result.pipelined_s:.3f} s → {pipe:.2f}x {verdict(pipe >= PIPELINED_TARGET)} "
        f"{PIPELINED_TARGET}x",
        f"engine cost per frame (3 no-op stages): {us:.1f} µs {verdict(us <= US)} {US:g} µs"
        + ("" if writer_us is None else f"; with the Parquet writer: {writer_us:.1f} µs"),
        f"the same in thread CPU time: {result.overhead_cpu_us_per_frame:.1f} µs"
        + ("" if cpu_us is None else f"; with the Parquet writer (process CPU): {cpu_us:.1f} µs"),
    ]
    console = report_console()
    console.print("\n".join(lines))
    if repeats > 1:

        def row(t: Any) -> list[str]:
            unit, fmt = (" µs", ".1f") if t.at_most else ("x", ".2f")
            cells = ("—" if v is None else f"{v:{fmt}}{unit}" for v in (t.min, t.median, t.max))
            bound = f"{'≤' if t.at_most else '≥'} {t.bound:g}{unit}"
            return [t.name, *cells, bound, "—" if t.met is None else verdict(t.met)]

        title = f"targets over {repeats} interleaved passes (verdict on the median)"
        console.print(spread_table(title, result.spreads(), ("target",), row))


def _run_engine(args: argparse.Namespace) -> int:
    from redrive.benchmarks.engine import bench_engine
    from redrive.errors import ConfigError

    if args.repeat < 1 or args.frames < 1:
        msg = "--repeat and --frames must be at least 1"
        raise ConfigError(msg)
    with spinner() as progress:
        result = bench_engine(
            frames=args.frames, work_ms=args.work_ms, repeats=args.repeat, progress=progress
        )
    if args.json:
        print_json({"engine": result.to_json()})
    else:
        _engine_report(result, args.repeat)
    return 0


def _closed_loop_report(result: Any) -> None:
    lidar = f" ({result.lidar} LiDAR)" if result.lidar else ""
    rtf = result.realtime_factor
    parts = ("rendering", "simulation", "algorithms", "other")[result.level != "sensor" :]
    split = (f"{p} {getattr(result, f'{p}_s'):.3f} s ({result.share(p):.0%})" for p in parts)
    algorithms = ", ".join(f"{k} {v:.2f}" for k, v in result.algorithm_ms.items())
    lines = [
        f"[bold]{result.scenario}[/], {result.level} level{lidar}, {result.duration_s:g} s "
        f"simulated, {result.frames} frames; medians of {result.repeats} passes",
        f"closed loop {result.wall_s:.3f} s = {rtf:.1f}x real time "
        f"{verdict(rtf >= result.target)} {result.target:g}x  (whole call with setup and close: "
        f"{result.total_s:.3f} s, process CPU {result.cpu_s:.3f} s)",
        "  split: " + ", ".join(split),
        f"  CPU: simulation {result.simulation_cpu_s:.3f} s, algorithms "
        f"{result.algorithms_cpu_s:.3f} s; the world alone {result.baseline_cpu_s:.3f} s",
        "  algorithms, mean ms per step: " + algorithms,
        f"baseline: the world alone {result.baseline_s:.3f} s = "
        f"{result.baseline_realtime_factor:.1f}x real time; closed loop / baseline = "
        f"{result.ratio:.2f}x the time; in CPU time (the loop's {result.loop_cpu_s:.3f} s) "
        f"{result.cpu_ratio:.2f}x",
    ]
    report_console().print("\n".join(lines))


def _run_closed_loop(args: argparse.Namespace) -> int:
    from redrive.benchmarks.closed_loop import bench_closed_loop

    with spinner() as progress:
        result = bench_closed_loop(
            scenario=args.scenario, duration_s=args.duration, level=args.level,
            repeats=args.repeat, lidar=args.lidar, progress=progress,
        )  # fmt: skip
    if args.json:
        print_json(result.to_json())
    else:
        _closed_loop_report(result)
    return 0


def _run_eval(args: argparse.Namespace) -> int:
    from redrive.benchmarks.eval import bench_eval
    from redrive.evaluation.evaluator import default_metrics
    from redrive.evaluation.registry import load_metric_class

    metrics = [load_metric_class(m)() for m in args.metric] if args.metric else default_metrics()
    with spinner():
        result = bench_eval(args.run, metrics)
    if args.json:
        print_json(result.to_json())
        return 0
    console = report_console()
    console.print(f"[bold]{result.run}[/]: reading the tables {result.load_cpu_s:.3f} CPU s")
    for c in result.costs:
        who = f" ({c.algorithm})" if c.algorithm else ""
        note = "" if c.outcome == "scored" else f"  [{c.outcome}]"
        console.print(f"  {c.metric}{who}: {c.cpu_s:.3f} CPU s{note}")
    console.print(f"metrics in all: {result.metrics_cpu_s:.3f} CPU s")
    return 0


def _run_group(args: argparse.Namespace) -> int:
    args.bench_parser.print_help()
    return 2


def register(sub: Any) -> None:
    parser = add_command(
        sub, "bench",
        "benchmarks of this machine and your logs against a baseline measured in the same run",
        "Benchmarks of redrive on this machine and your logs, each against a baseline measured in "
        "the same run: read, engine, closed-loop, transport; and the CPU cost of each metric on a "
        "run (eval). (Comparisons against peers, soak and whole-system benchmarks: benchmarks/ in "
        "a checkout, `make bench`.)",
        EPILOG,
    )  # fmt: skip
    parser.set_defaults(func=_run_group, bench_parser=parser)
    bench_sub = parser.add_subparsers(dest="bench_command", metavar="BENCHMARK")
    add_read_parser(bench_sub)

    engine = add_command(
        bench_sub, "engine", "engine throughput and cost per frame against a bare loop", _ENGINE,
        "examples:\n  redrive bench engine\n  redrive bench engine --repeat 5 --frames 2000\n"
        "  redrive bench engine --json",
    )  # fmt: skip
    option(engine, "--frames", 500, "N", "frames per pass (default 500)")
    option(engine, "--work-ms", 1.0, "MS", "work per stage (default 1)")
    option(engine, "--repeat", 5, "N", "interleaved passes per variant; medians, and "
           "min/median/max when N > 1 (default 5)")  # fmt: skip
    flag(engine, "--json", "print JSON instead of text")
    engine.set_defaults(func=_run_engine)

    loop = add_command(
        bench_sub, "closed-loop",
        "closed-loop real-time factor and its split, against the world stepping alone",
        _CLOSED_LOOP,
        "examples:\n  redrive bench closed-loop\n"
        "  redrive bench closed-loop --scenario cut_in --duration 10 --repeat 5 --json\n"
        "  redrive bench closed-loop --level sensor --repeat 1",
    )  # fmt: skip
    loop.add_argument("--scenario", default="urban", help="scenario name or TOML (default urban)")
    option(loop, "--duration", 20.0, "S", "seconds (default 20)")
    loop.add_argument(
        "--level", choices=LEVELS, default="object", help="closed-loop level (default object)"
    )
    loop.add_argument(
        "--lidar",
        metavar="PRESET",
        help="sensor level: the preset the scenario's first 3D LiDAR is swapped for (default "
        "HDL-64E; 'scenario' keeps the scenario's own)",
    )
    option(loop, "--repeat", 3, "N", "passes of each (default 3)")
    flag(loop, "--json", "print JSON instead of text")
    loop.set_defaults(func=_run_closed_loop)

    add_transport_parser(bench_sub)

    ev = add_command(
        bench_sub, "eval", "the CPU seconds of each metric on a run", _EVAL,
        "example:\n  redrive bench eval RUN --metric navsim_pdms --metric navsim_epdms\n",
    )  # fmt: skip
    ev.add_argument("run", metavar="RUN", help="a run directory")
    ev.add_argument(
        "--metric",
        action="append",
        metavar="NAME",
        help="an installed metric, package.module:Class or file.py:Class (repeat; default: all "
        "installed)",
    )
    flag(ev, "--json", "the result as JSON on stdout")
    ev.set_defaults(func=_run_eval)
