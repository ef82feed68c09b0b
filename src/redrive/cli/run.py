"""``redrive run LOG`` — replay a log through perception → planning → control into a run directory."""

from __future__ import annotations

import argparse
import re
import shlex
import sys
import time
from pathlib import Path
from typing import Any

from ._map_options import add_map_options, map_option
from .run_report import ProgressLines, print_deviation, print_run_report

__all__ = ["parse_frames", "pipeline_from_args", "register"]

_EPILOG = """\
examples:
  redrive run drive.mcap                                  the reference pipeline
  redrive run drive.bag --perception my_detector.py:MyDetector
  redrive run drive.bag --perception mypkg.det:Det --planning idm-planner --control pure-pursuit-pid
  redrive run drive.bag --pipeline pipeline.toml --frames 100:200 --out runs/try1
  redrive run autoware.bag --map lanelet2_map.osm         a Lanelet2 map (the log's `map` frame)
  redrive run drive.bag --map map.osm --map-origin 49.0,8.4   no `map` frame: the map's origin
  redrive run drive.bag --mode pipelined --step-timeout 2 --out runs/try2
  redrive run drive.bag --perception big.py:Det --max-rss 2048   each worker under 2 GiB
  redrive run drive.bag --out runs/try2 --resume           continue an interrupted run
  redrive run cut_in --closed-loop --planning my.py:Planner   closed loop: the planner drives
  redrive run cut_in --closed-loop --agents reactive --perception noisy-oracle \
      --planning idm-planner --control pure-pursuit-pid    followers react to the driven ego
  redrive run cut_in --closed-loop --sensors              the reference pipeline on sensors
                                                          rendered from the driven ego
  redrive run drive.bag --closed-loop --planning my.py:Planner --duration 30
                                                          closed loop on a recorded log

Plugins are entry-point names (`redrive algorithms` lists them), package.module:Class or
path/to/file.py:Class.  With no --pipeline and no plugin flag the reference pipeline runs:
cluster-detector → kalman-tracker → idm-planner → pure-pursuit-pid (on a log with ground truth
but no LiDAR — Waymo Open Motion, CommonRoad — noisy-oracle first instead of the detector).  A step that raises is
recorded for its frame and the run goes on (--fail-fast stops instead); Ctrl-C leaves a run
directory that --resume continues.  `redrive export RUN --format xlsx` exports the results.

Closed loop (--closed-loop): LOG is a scenario of the synthetic catalogue (`redrive synth
--list`) or a scenario TOML; the outputs move the ego (the last control stage's commands, else the
built-in tracker — nuPlan's LQR tracker — on the last planned path, else an emergency brake)
and the world goes on from where it puts the car, within the tyres' friction circle (--friction,
default μ = 0.9).  A collision is recorded (closed_loop table) and the run drives on, as
nuPlan's does; --on-collision stop ends it there.  Frames are object-level (the true ego state
and the ground-truth objects: use a perception that reads ground truth, e.g. noisy-oracle); with
--sensors they also carry the scenario's rig (LiDAR, camera, IMU, GNSS) rendered from the driven
ego, as a replay of its `redrive synth` log would, each LiDAR's last finished sweep in a frame (the first frame comes
one sweep after the start), and OUT/sensors.mcap records them (`redrive gui OUT` and Foxglove
open it).  --agents replay (default) keeps the other road users on their
scripted paths, --agents reactive lets them react to the ego.  --seed seeds the scenario too.

Closed loop on a recorded log (LOG with the ego's pose: odometry or poses): the ego starts at the
log's first pose and the bicycle model carries it; each frame is the log's, re-expressed from the
driven pose (point clouds and ground truth moved by the pose difference, images unchanged) — right
only for small deviations, so each frame past 2 m / 10° from the logged ego is flagged `deviated`
(closed_loop table; counted in the manifest summary).  An object-level run (no stage reads a
sensor) is paced by the log's ground truth; `redrive run` says which stream paces and why.  With
a road map (Argoverse 2, Waymo Open Motion, CommonRoad) the logged ego path mapped onto the lane
graph is the route idm-planner follows, and --planning log-future-planner drives the logged ego
(the expert); --agents reactive (needs objects in the log) lets the logged vehicles the driven ego
holds up drive their lanes under IDM (following, red lights, stop signs) until they catch up with
their log (without a map: slowed along their logged paths).  --sensor-map and --duration apply.
See docs/closed_loop.md.
"""

_FRAMES = re.compile(r"^(\d*):(\d*)$")


def parse_frames(text: str) -> tuple[int | None, int | None]:
    """``A:B`` → (A, B) frame indices, ``A:`` / ``:B`` open-ended; a single ``N`` is ``N:N+1``."""
    from redrive.errors import ConfigError

    if text.isdigit():
        return int(text), int(text) + 1
    match = _FRAMES.match(text.strip())
    if not match:
        msg = f"--frames {text!r}: expected START:STOP frame indices (e.g. 100:200, 100:, :50)"
        raise ConfigError(msg)
    first = int(match[1]) if match[1] else None
    stop = int(match[2]) if match[2] else None
    if first is not None and stop is not None and stop <= first:
        msg = f"--frames {text!r}: STOP must be greater than START"
        raise ConfigError(msg)
    return first, stop


def _default_out(log: Path) -> Path:
    stem = log.name.removesuffix(".bag").removesuffix(".mcap") or "run"
    return Path("runs") / f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}"


def resume_command(args: argparse.Namespace, out: Path) -> str:
    """The command that continues this interrupted run: the one given (``args.argv``), with
    ``--out`` where the run went (when it was chosen for the user) and ``--resume``."""
    argv = [a for a in getattr(args, "argv", []) if a != "--resume"]
    if not argv:  # called without main(): say what is known
        argv = ["run", str(args.log)]
    if args.out is None:
        argv += ["--out", str(out)]
    return shlex.join(["redrive", *argv, "--resume"])


def pipeline_from_args(args: argparse.Namespace) -> Any:
    """The pipeline of ``--pipeline FILE``, else of ``--perception/--planning/--control``
    plugins, else the reference pipeline (shared by ``redrive run`` and ``redrive live``)."""
    from redrive.config import load_pipeline, pipeline_from_plugins, reference_pipeline

    if args.pipeline is not None:
        return load_pipeline(args.pipeline)
    if args.perception or args.planning or args.control:
        return pipeline_from_plugins(
            perception=args.perception or (),
            planning=args.planning or (),
            control=args.control or (),
        )
    return reference_pipeline()


def _run(args: argparse.Namespace) -> int:
    from redrive.engine import RunRequest, run_log
    from redrive.output.progress import ProgressBar, is_terminal
    from redrive.results import RunStatus

    if args.pipeline is not None and (args.perception or args.planning or args.control):
        print("redrive run: give either --pipeline or --perception/--planning/--control")
        return 2
    default = args.pipeline is None and not (args.perception or args.planning or args.control)
    base = pipeline_from_args(args)
    if default and not args.closed_loop:
        base = _default_pipeline_for(args.log, base, sensor_map=args.sensor_map)
    pipeline = base.with_options(
        mode=args.mode,
        executor=args.executor,
        seed=args.seed,
        step_timeout_s=args.step_timeout,
        max_rss_mb=args.max_rss,
        fail_fast=True if args.fail_fast else None,
    )
    if args.closed_loop:
        return _run_closed_loop(args, pipeline)
    if args.sensors:
        print("redrive run: --sensors renders a closed loop's sensors; add --closed-loop")
        return 2
    first, stop = parse_frames(args.frames) if args.frames else (None, None)
    out = args.out or _default_out(args.log)
    request = RunRequest(
        log=args.log,
        pipeline=pipeline,
        out=out,
        first_frame=first,
        stop_frame=stop,
        sensor_map=args.sensor_map,
        rate=args.rate,
        resume=args.resume,
        strict=args.strict,
        skip_unfed=not args.strict,
        road_map=map_option(args),
    )
    progress_bar = ProgressBar(args.log.name, unit="frames", quiet=args.no_progress)
    lines = None if args.no_progress or is_terminal() else ProgressLines(args.log.name, sys.stderr)
    started = [0.0]
    with progress_bar:

        def on_start(total: int | None) -> None:
            started[0] = time.perf_counter()
            progress_bar.start(total)
            if lines is not None:
                lines.start(total)

        def on_progress(done: int) -> None:
            progress_bar.update(done)
            if lines is not None:
                lines.update(done, time.perf_counter() - started[0])

        report = run_log(request, on_start=on_start, progress=on_progress)
    print_run_report(report, out)
    if report.status is RunStatus.INTERRUPTED:
        print(f"interrupted: continue with `{resume_command(args, out)}`")
        return 130
    if report.status is RunStatus.FAILED and report.failure is not None:
        index, step = report.failure
        print(
            f"redrive: error: --fail-fast: {step.algorithm} {step.status} on frame {index}: "
            f"{step.error_type}: {step.error_message}"
        )
        return 1
    return nothing_succeeded_status(report, out)


def _default_pipeline_for(log_path: Path, reference: Any, *, sensor_map: Path | None) -> Any:
    """The reference pipeline, or — for a log with ground truth but no LiDAR (recorded traffic:
    Waymo Open Motion, CommonRoad) — the object-level one (noisy oracle first)."""
    from redrive.assembly.sensor_map import infer_sensor_map, load_sensor_map_overrides
    from redrive.config import object_level_pipeline
    from redrive.errors import RedriveError
    from redrive.io import open_log
    from redrive.types import SensorType

    try:
        with open_log(log_path) as log:
            overrides = load_sensor_map_overrides(sensor_map) if sensor_map else None
            smap = infer_sensor_map(
                log.topics, duration_ns=log.end_ns - log.start_ns, overrides=overrides
            )
            state = log.topics.get(smap.vehicle_state_topic or "")
    except (RedriveError, OSError):
        return reference  # the run itself reports what is wrong with the log
    if smap.ground_truth_topic is None or any(
        s.sensor_type is SensorType.LIDAR for s in smap.sensors
    ):
        return reference
    if state is None or state.count < 2:
        print(
            "redrive run: the log has ground truth but no LiDAR and records no ego motion (a "
            "CommonRoad scenario gives the ego's start only: `--closed-loop` drives it): the "
            "object-level perception stages run (noisy-oracle → kalman-tracker)",
            file=sys.stderr,
        )
        return object_level_pipeline(planning=False)
    print(
        "redrive run: the log has no LiDAR but ground truth: the object-level reference "
        "pipeline runs (noisy-oracle → kalman-tracker → idm-planner → pure-pursuit-pid)",
        file=sys.stderr,
    )
    return object_level_pipeline()


def nothing_succeeded_status(report: Any, out: Path | None = None) -> int:
    """3 (and why, on stderr) when no step of any algorithm succeeded in any frame, or when
    the run directory ``out`` holds no frame at all (none in this invocation, none before it),
    else 0."""
    if report.frames == 0 and out is not None:
        from redrive.results import read_manifest

        if read_manifest(out).frames_done == 0:
            damaged = " (the log is damaged: see the warnings above)" if report.damage else ""
            print(
                f"redrive: error: no frame was processed{damaged}: the log gave no frame in the "
                "range asked for (`redrive info LOG` shows its topics and time range; "
                "--frames START:STOP counts frames from 0)",
                file=sys.stderr,
            )
            return 3
    if not report.nothing_succeeded:
        return 0
    print(
        f"redrive: error: no algorithm step succeeded in any of the {report.frames} frames; "
        "the run's results hold only the failures (`redrive export RUN --format csv` lists them in "
        "steps.csv; the first failure of each algorithm is printed above)",
        file=sys.stderr,
    )
    return 3


def _run_closed_loop(args: argparse.Namespace, pipeline: Any) -> int:
    from redrive.closedloop.run import ClosedLoopRequest, is_scenario, run_closed_loop
    from redrive.errors import ConfigError
    from redrive.results import RunStatus

    name = str(args.log)
    scenario = is_scenario(name)
    if not scenario and not args.log.exists():
        msg = (
            f"{name}: no such scenario, scenario TOML or log (`redrive synth --list` lists the "
            "scenarios)"
        )
        raise ConfigError(msg)
    unsupported = [
        flag
        for flag, given in (
            ("--frames", args.frames),
            ("--rate", args.rate),
            ("--resume", args.resume),
            ("--sensor-map", args.sensor_map if scenario else None),
        )
        if given
    ]
    if args.sensors and not scenario:
        msg = (
            f"{name}: --sensors re-renders a synthetic scenario's rig; a recorded log's sensors "
            "are re-expressed from the driven pose without it (drop --sensors)"
        )
        raise ConfigError(msg)
    if unsupported:
        msg = f"--closed-loop: {', '.join(unsupported)} apply to open-loop replay; drop them"
        raise ConfigError(msg)
    out = args.out or Path("runs") / f"{Path(name).stem}-closed-{time.strftime('%Y%m%d-%H%M%S')}"
    request = ClosedLoopRequest(
        scenario=name,
        pipeline=pipeline,
        out=out,
        agents=args.agents,
        seed=args.seed,
        duration_s=args.duration,
        level="sensor" if args.sensors else "object",
        sensor_map=None if scenario else args.sensor_map,
        on_collision=args.on_collision,
        friction_coefficient=args.friction,
        road_map=_closed_loop_map(args, scenario=scenario),
    )
    report = run_closed_loop(request)
    print_run_report(report, out)
    print_deviation(out)
    if report.status is RunStatus.INTERRUPTED:
        print("interrupted: closed-loop runs do not resume; run it again into a new --out")
        return 130
    return nothing_succeeded_status(report, request.out)


def _closed_loop_map(args: argparse.Namespace, *, scenario: bool) -> Any:
    """The closed loop's --map option; a scenario brings its own map."""
    option = map_option(args)
    if option is not None and scenario:
        from redrive.errors import ConfigError

        msg = f"{args.log}: a synthetic scenario drives on its own road map; drop --map/--no-map"
        raise ConfigError(msg)
    return option


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "run",
        help="replay a log through perception → planning → control",
        description=(
            "Replay a log (ROS 1/2 bag, MCAP, KITTI, nuScenes, Argoverse 2, Waymo Open Motion, CommonRoad) frame by frame through a pipeline of "
            "algorithms and store every output, latency and error in a run directory "
            "(manifest.json + Parquet)."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "log",
        type=Path,
        metavar="LOG",
        help="the log to replay (with --closed-loop also a scenario name or scenario TOML)",
    )
    parser.add_argument("--pipeline", type=Path, metavar="TOML", help="a pipeline file")
    for role in ("perception", "planning", "control"):
        parser.add_argument(
            f"--{role}",
            action="append",
            metavar="PLUGIN",
            help=f"a {role} algorithm (repeat for consecutive stages)",
        )
    parser.add_argument(
        "--frames", metavar="A:B", help="frame indices to run, START:STOP (STOP excluded)"
    )
    parser.add_argument(
        "-o", "--out", type=Path, metavar="DIR", help="run directory (default runs/LOG-TIME)"
    )
    parser.add_argument(
        "--mode",
        choices=("sequential", "pipelined"),
        help="default sequential; pipelined runs each stage on a thread of its own, frames "
        "overlapping — faster only with cores to spare (on two cores the reference pipeline "
        "runs at 0.8–0.9x its sequential speed: docs/algorithms.md)",
    )
    parser.add_argument(
        "--executor",
        choices=("threads", "processes"),
        help="run algorithms in this process (threads, default) or in worker processes",
    )
    parser.add_argument(
        "--step-timeout",
        type=float,
        metavar="S",
        help="record steps longer than S seconds as timed out (runs algorithms in workers)",
    )
    parser.add_argument(
        "--max-rss",
        type=float,
        metavar="MB",
        help="bound each algorithm's worker process to MB MiB resident (interpreter and "
        "libraries included, about 60-100 MiB); a step past it is killed and recorded as a "
        "MemoryLimit error on its frame, a fresh worker takes the next (runs algorithms in "
        "workers: an algorithm in this process cannot be bounded); a stage's own max_rss_mb in "
        "--pipeline wins over it",
    )
    parser.add_argument("--fail-fast", action="store_true", help="stop at the first failed step")
    parser.add_argument(
        "--rate", type=float, metavar="X", help="pace at X times real time (default: flat out)"
    )
    parser.add_argument("--seed", type=int, help="seed for algorithms that take one")
    parser.add_argument(
        "--resume", action="store_true", help="continue the interrupted run in --out"
    )
    parser.add_argument(
        "--sensor-map", type=Path, metavar="TOML", help="which topic is which sensor"
    )
    parser.add_argument(
        "--closed-loop",
        action="store_true",
        help="the outputs drive the ego (LOG: a scenario, or a log with the ego's pose)",
    )
    parser.add_argument(
        "--agents",
        choices=("replay", "reactive"),
        default="replay",
        help="closed loop: other road users replay their script (default) or react to the ego",
    )
    parser.add_argument(
        "--sensors",
        action="store_true",
        help=(
            "closed loop: render the scenario's sensors from the driven ego (sensor level); "
            "they are recorded in OUT/sensors.mcap"
        ),
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="closed loop: seconds (default: the scenario's, or the whole log)",
    )
    parser.add_argument(
        "--on-collision",
        choices=("continue", "stop"),
        default="continue",
        help=(
            "closed loop: when the ego touches an object, drive on and count it (default, as "
            "nuPlan) or end the run there (the reason is in the manifest's summary)"
        ),
    )
    parser.add_argument(
        "--friction",
        type=float,
        metavar="MU",
        default=0.9,
        help=(
            "closed loop: tyre-road friction coefficient; the ego's combined acceleration stays "
            "within MU·g (default 0.9: dry asphalt; about 0.5 wet, 0.1-0.2 snow and ice)"
        ),
    )
    parser.add_argument(
        "--strict",
        action="store_true",
        help=(
            "refuse a damaged log (stop at its first damage, exit status 1) and a pipeline the "
            "log cannot feed whole; by default the damaged parts are skipped with a warning and "
            "the run covers the intact part, and the algorithms whose inputs the log lacks (a "
            "planner on a log without ego state) are skipped with the reason, shown and stored "
            "in the manifest (pipeline.skipped)"
        ),
    )
    add_map_options(parser, stored=True)
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=_run)
