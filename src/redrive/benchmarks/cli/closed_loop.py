"""``redrive bench closed-loop`` — a closed-loop run against the world stepping alone."""

from __future__ import annotations

import argparse
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner

__all__ = ["LEVELS", "add_closed_loop_parser"]

#: redrive.benchmarks.closed_loop.LEVELS, kept here so building the parser imports no simulator
#: (tests/bench checks they agree)
LEVELS = ("object", "sensor")

_DESCRIPTION = """\
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


def _verdict(ok: bool) -> str:
    return "[green]meets[/]" if ok else "[red]misses[/]"


def _run_closed_loop(args: argparse.Namespace) -> int:
    from redrive.benchmarks.closed_loop import bench_closed_loop

    with spinner() as progress:
        result = bench_closed_loop(
            scenario=args.scenario,
            duration_s=args.duration,
            level=args.level,
            repeats=args.repeat,
            lidar=args.lidar,
            progress=progress,
        )
    if args.json:
        print_json(result.to_json())
        return 0
    console = report_console()
    lidar = f" ({result.lidar} LiDAR)" if result.lidar else ""
    console.print(
        f"[bold]{result.scenario}[/], {result.level} level{lidar}, {result.duration_s:g} s "
        f"simulated, {result.frames} frames; medians of {result.repeats} passes"
    )
    rtf = result.realtime_factor
    console.print(
        f"closed loop {result.wall_s:.3f} s = {rtf:.1f}x real time "
        f"{_verdict(rtf >= result.target)} {result.target:g}x  "
        f"(whole call with setup and close: {result.total_s:.3f} s, "
        f"process CPU {result.cpu_s:.3f} s)"
    )
    console.print(
        "  split: "
        + ", ".join(
            f"{part} {getattr(result, f'{part}_s'):.3f} s ({result.share(part):.0%})"
            for part in ("rendering", "simulation", "algorithms", "other")
            if part != "rendering" or result.level == "sensor"
        )
    )
    console.print(
        f"  CPU: simulation {result.simulation_cpu_s:.3f} s, algorithms "
        f"{result.algorithms_cpu_s:.3f} s; the world alone {result.baseline_cpu_s:.3f} s"
    )
    console.print(
        "  algorithms, mean ms per step: "
        + ", ".join(f"{k} {v:.2f}" for k, v in result.algorithm_ms.items())
    )
    console.print(
        f"baseline: the world alone {result.baseline_s:.3f} s = "
        f"{result.baseline_realtime_factor:.1f}x real time; closed loop / baseline = "
        f"{result.ratio:.2f}x the time; in CPU time (the loop's {result.loop_cpu_s:.3f} s) "
        f"{result.cpu_ratio:.2f}x"
    )
    return 0


def add_closed_loop_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "closed-loop",
        help="closed-loop real-time factor and its split, against the world stepping alone",
        description=_DESCRIPTION,
        epilog=(
            "examples:\n  redrive bench closed-loop\n"
            "  redrive bench closed-loop --scenario cut_in --duration 10 --repeat 5 --json\n"
            "  redrive bench closed-loop --level sensor --repeat 1"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--scenario", default="urban", help="scenario name or TOML (default urban)")
    parser.add_argument(
        "--duration", type=float, default=20.0, metavar="S", help="seconds (default 20)"
    )
    parser.add_argument(
        "--level", choices=LEVELS, default="object", help="closed-loop level (default object)"
    )
    parser.add_argument(
        "--lidar",
        metavar="PRESET",
        help="sensor level: the preset the scenario's first 3D LiDAR is swapped for (default "
        "HDL-64E; 'scenario' keeps the scenario's own)",
    )
    parser.add_argument(
        "--repeat", type=int, default=3, metavar="N", help="passes of each (default 3)"
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=_run_closed_loop)
