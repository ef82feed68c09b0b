"""``redrive synth SCENARIO -o OUT.mcap`` — simulate a scenario into an MCAP log."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive synth urban -o urban.mcap                 the default scenario (its own duration)
  redrive synth cut_in --duration 10 --seed 3 -o cut_in.mcap
  redrive synth my_scenario.toml -o mine.mcap       a copied and edited scenario file
  redrive synth --list                              the built-in scenarios

The log holds LiDAR (PointCloud2), 2D LiDAR (LaserScan), camera (Image), IMU, GNSS, wheel
odometry, tf and ground truth (objects in base_link with LiDAR point counts and visibility, the
true ego state); it opens in redrive, Foxglove and Lichtblick.  The same scenario and seed give a
byte-identical file.
"""


def _run(args: argparse.Namespace) -> int:
    from redrive.output.progress import ProgressBar
    from redrive.sim.scenario import list_scenarios, load_scenario
    from redrive.sim.synth import synthesize

    if args.list:
        for name in list_scenarios():
            scenario = load_scenario(name)
            print(f"{name:28s} {scenario.duration_s:5.0f} s  {scenario.description}")
        return 0
    if args.scenario is None or args.output is None:
        print("redrive synth: give a SCENARIO and -o OUT.mcap (or --list)")
        return 2
    if args.output.suffix.lower() != ".mcap":
        print(
            f"redrive synth: {args.output}: synth writes an MCAP log, so OUT must end in .mcap "
            f"(e.g. -o {args.output.with_suffix('.mcap')}); to get a ROS 1 bag, "
            f"`redrive convert` the MCAP file to a .bag",
            file=sys.stderr,
        )
        return 2
    scenario = load_scenario(args.scenario)
    total_s = args.duration or scenario.duration_s
    with ProgressBar(
        f"simulating {scenario.name}", total=total_s, unit="s", decimals=1, show_rate=False
    ) as bar:

        def progress(done_s: float, total_s: float) -> None:
            bar.update(done_s, total=total_s)

        summary = synthesize(
            scenario, args.output, duration_s=args.duration, seed=args.seed, progress=progress
        )
    print(
        f"wrote {summary.path}: scenario {summary.scenario}, seed {summary.seed}, "
        f"{summary.duration_s:g} s, {summary.messages} messages on {len(summary.topics)} topics"
    )
    return 0


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "synth",
        help="simulate a driving scenario into an MCAP log",
        description=(
            "Simulate a scenario of the built-in catalogue (or a scenario TOML file): a "
            "deterministic world with traffic, pedestrians and lights, sensed by a rig of "
            "ray-cast LiDARs, a camera, IMU, GNSS and odometry, written as an MCAP log with "
            "ground truth (objects, the ego state, the lights' states) and the road map."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("scenario", nargs="?", metavar="SCENARIO", help="a name or a .toml path")
    parser.add_argument("-o", "--output", type=Path, metavar="OUT.mcap", help="the log to write")
    parser.add_argument(
        "--duration", type=float, metavar="S", help="seconds (default: the scenario's)"
    )
    parser.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    parser.add_argument("--list", action="store_true", help="list the built-in scenarios")
    parser.set_defaults(func=_run)
