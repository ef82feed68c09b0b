"""``redrive batch LOG… --pipeline A.toml --pipeline B.toml`` — many logs × pipelines × loop
modes into one batch directory, on a local process pool or a Ray cluster."""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._batch_progress import BatchBar, batch_progress
from ._gates import add_gate_options
from ._map_options import add_map_options

if TYPE_CHECKING:
    from redrive.batch import CellRecord, CellTask
    from redrive.config import PipelineConfig
    from redrive.engine.stats import RunReport

__all__ = ["EXIT_CELLS_FAILED", "batch_cell", "register"]

#: the exit status of a batch in which some cell failed (every other cell still ran).
EXIT_CELLS_FAILED = 3

_EPILOG = """\
examples:
  redrive batch drives/*.mcap --out batches/ref          the reference pipeline on every log
  redrive batch drives/ fleet.txt --pipeline a.toml --pipeline b.toml --out batches/ab
  redrive batch urban cut_in --seeds 0-7 --duration 10 --loop both --planning my.py:Planner \\
      --out batches/synth                                 16 synthetic logs, open and closed loop
  redrive batch --spec nightly.toml                       the matrix of a spec file
  redrive batch --spec nightly.toml --executor ray --address auto   on an existing Ray cluster

LOG: a log (file or ROS 2 bag directory), a glob (quote it for `**`), a directory (the logs in
it), a .txt file listing them (one a line, # comments), or a synthetic scenario (`redrive synth
--list`, or a scenario .toml) with an optional @SEED: `urban@3`; --seeds A-B runs each scenario
named without a seed once per seed.  An open-loop cell of a scenario replays its log, simulated
once into BATCH/logs/; a closed-loop cell drives it (as `redrive run --closed-loop`).

Each cell (pipeline × loop × log) is an ordinary run directory, BATCH/runs/PIPELINE/LOOP/LOG_ID:
`redrive evaluate/report/export/compare/gui` take it.  BATCH/batch.json lists every cell with its
status and error.  Running the same command again skips the cells already complete for the same
log (sha256), pipeline (hash) and redrive version — an interrupted batch does only what is
missing; --force redoes them all.  A cell that fails (a corrupt log, a pipeline that does not fit
the log, a worker that dies) fails alone; a cell whose worker died is retried --retries times.

With --evaluate, --fail-under or --fail-over the batch is then evaluated as `redrive evaluate
BATCH` does (every complete cell, pooled per pipeline across the logs), and the gates are
checked on the pooled values: `--fail-under nuscenes_detection.mAP=0.40`.

Exit status: 0 every cell complete (and every gate passed), 3 some cell failed (the others ran)
or a metric raised, 4 a CI gate failed, 1 the batch could not start (bad spec, pipeline, Ray
missing), 2 bad usage, 130 interrupted (run again to continue).
See docs/batch.md.
"""


def batch_cell(task: CellTask) -> CellRecord:
    """The runner ``redrive batch`` gives its executors: a cell, open loop through the engine,
    closed loop through :func:`redrive.closedloop.run.run_closed_loop`."""
    from redrive.batch import run_cell

    return run_cell(task, closed_loop=_closed_loop)


def _closed_loop(
    *,
    target: str,
    pipeline: PipelineConfig,
    out: Path,
    seed: int | None,
    duration_s: float | None,
    agents: str,
    on_collision: str = "continue",
    road_map: Any = None,
) -> RunReport:
    from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop

    if agents not in ("replay", "reactive"):
        raise ValueError(f"agents {agents!r}: expected replay or reactive")
    request = ClosedLoopRequest(
        scenario=target,
        pipeline=pipeline,
        out=out,
        agents="reactive" if agents == "reactive" else "replay",
        seed=seed,
        duration_s=duration_s,
        on_collision=on_collision,
        road_map=road_map,
    )
    return run_closed_loop(request)


def _spec_from_args(args: argparse.Namespace) -> tuple[Any, dict[str, Any]]:
    """The batch spec of ``--spec`` with the command line's logs, pipelines and options over it."""
    from redrive.batch import (
        LOOP_MODES,
        BatchSpec,
        expand_logs,
        load_batch_spec,
        make_pipeline_item,
        parse_seeds,
        unique_pipelines,
    )
    from redrive.errors import ConfigError

    base = load_batch_spec(args.spec) if args.spec else {}
    logs = base.get("logs", ())
    if args.logs:
        seeds = parse_seeds(args.seeds) if args.seeds else ()
        logs = expand_logs(args.logs, seeds=seeds)
    elif args.seeds:
        raise ConfigError("--seeds applies to the scenarios given on the command line")
    if not logs:
        raise ConfigError("no logs: give LOG… or a --spec with `logs`")
    pipelines = list(base.get("pipelines", ()))
    if args.pipeline or args.perception or args.planning or args.control:
        pipelines = [make_pipeline_item(name=None, file=str(p)) for p in args.pipeline or ()]
        if args.perception or args.planning or args.control:
            pipelines.append(
                make_pipeline_item(
                    name=None,
                    perception=args.perception or (),
                    planning=args.planning or (),
                    control=args.control or (),
                )
            )
    loop = args.loop or base.get("loop", "open")
    if loop not in LOOP_MODES:
        raise ConfigError(f"loop {loop!r}: expected open, closed or both")
    agents = args.agents or base.get("agents", "replay")
    if agents not in ("replay", "reactive"):
        raise ConfigError(f"agents {agents!r}: expected replay or reactive")
    on_collision = args.on_collision or base.get("on_collision", "continue")
    if on_collision not in ("continue", "stop"):
        raise ConfigError(f"on_collision {on_collision!r}: expected continue or stop")
    spec = BatchSpec(
        logs=tuple(logs),
        pipelines=unique_pipelines(pipelines),
        loops=LOOP_MODES[loop],
        duration_s=args.duration if args.duration is not None else base.get("duration_s"),
        agents=agents,
        on_collision=on_collision,
        fail_fast=bool(args.fail_fast or base.get("fail_fast", False)),
        **_map_fields(args, base),
    )
    options = {
        "out": args.out or base.get("out"),
        "executor": args.executor or base.get("executor", "local"),
        "workers": args.workers or base.get("workers"),
        "retries": args.retries if args.retries is not None else base.get("retries", 1),
        "address": args.address or base.get("address"),
    }
    if options["out"] is None:
        raise ConfigError("give the batch directory: --out DIR (or `out` in the --spec file)")
    return spec, options


def _map_fields(args: argparse.Namespace, base: dict[str, Any]) -> dict[str, Any]:
    """--map / --map-origin / --no-map over the spec's ``map`` / ``map_origin`` / ``no_map``."""
    from redrive.errors import ConfigError

    fields: dict[str, Any]
    if args.map_file is not None or args.no_map:  # the command line replaces the spec's choice
        fields = {"map_file": None if args.map_file is None else str(args.map_file.resolve())}
        fields |= {"no_map": bool(args.no_map), "map_origin": args.map_origin}
    else:
        fields = {"map_file": base.get("map"), "no_map": bool(base.get("no_map", False))}
        fields["map_origin"] = args.map_origin or base.get("map_origin")
    if fields["no_map"] and fields["map_file"] is not None:
        raise ConfigError("the batch gives both a map and no_map: give one")
    if fields["map_origin"] is not None and fields["map_file"] is None:
        raise ConfigError("map_origin is the origin of the batch's map: give `map` / --map too")
    return fields


def _run(args: argparse.Namespace) -> int:
    import os

    from redrive.batch import CellStatus, run_batch

    spec, options = _spec_from_args(args)
    out = Path(options["out"])
    workers = int(options["workers"] or os.cpu_count() or 1)
    cells = len(spec.logs) * len(spec.pipelines) * len(spec.loops)
    progress = batch_progress(workers, cells, quiet=args.no_progress)
    print(
        f"batch {out}: {len(spec.logs)} logs × {len(spec.pipelines)} pipelines × "
        f"{len(spec.loops)} loop modes = {cells} cells on {options['executor']} "
        f"({workers} workers)",
        file=sys.stderr,
    )
    started = time.perf_counter()
    bar = progress if isinstance(progress, BatchBar) else contextlib.nullcontext()
    try:
        with bar:
            manifest = run_batch(
                spec,
                out,
                runner=batch_cell,
                executor=options["executor"],
                workers=workers,
                retries=int(options["retries"]),
                address=options["address"],
                cpus_per_cell=args.cpus_per_cell,
                force=args.force,
                progress=progress,
            )
    except KeyboardInterrupt:
        print(
            f"interrupted: the same command continues the batch (only missing cells run); "
            f"{out}/batch.json says where each cell stands",
            file=sys.stderr,
        )
        return 130
    by_status = {s: [c for c in manifest.cells if c.status is s] for s in CellStatus}
    print(
        f"batch {out}: {len(by_status[CellStatus.COMPLETE])} complete, "
        f"{len(by_status[CellStatus.SKIPPED])} skipped (already complete), "
        f"{len(by_status[CellStatus.FAILED])} failed in {time.perf_counter() - started:.1f} s"
    )
    for cell in by_status[CellStatus.FAILED]:
        print(f"  failed {cell.cell_id}: {cell.error}")
    print(f"manifest: {out / 'batch.json'}; runs: {out / 'runs'}")
    status = EXIT_CELLS_FAILED if manifest.status != "complete" else 0
    gates = [*args.fail_under, *args.fail_over]
    if gates or args.evaluate:
        gated = _evaluate(out, gates)
        return status or gated
    return status


def _evaluate(out: Path, gates: list[Any]) -> int:
    """``redrive evaluate BATCH`` after the batch, with its gates; 3 a metric raised, 4 a gate
    failed, else 0."""
    from rich.console import Console

    from redrive.batch.evaluate import evaluate_batch

    from ._gates import gate_batch, print_gates
    from .evaluate import EXIT_METRIC_FAILED, print_batch_evaluation

    console = Console(width=None if sys.stdout.isatty() else 120)
    evaluation = evaluate_batch(out)
    print_batch_evaluation(evaluation, console)
    gated = print_gates(gate_batch(gates, evaluation), console)
    return EXIT_METRIC_FAILED if evaluation.failed_metrics else gated


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "batch",
        help="many logs × pipelines × loop modes on a process pool or Ray",
        description=(
            "Run every pipeline over every log (open loop, closed loop or both) into one batch "
            "directory: a batch manifest and one ordinary run directory per cell.  Resumable, "
            "and a failing cell fails alone."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "logs", nargs="*", metavar="LOG", help="logs, globs, directories, .txt lists, scenarios"
    )
    parser.add_argument("--spec", type=Path, metavar="TOML", help="a batch spec file")
    parser.add_argument(
        "--pipeline",
        type=Path,
        action="append",
        metavar="TOML",
        help="a pipeline file (repeat for several pipelines)",
    )
    for role in ("perception", "planning", "control"):
        parser.add_argument(
            f"--{role}",
            action="append",
            metavar="PLUGIN",
            help=f"a {role} algorithm of the pipeline named 'flags' (repeat for stages)",
        )
    parser.add_argument(
        "--loop", choices=("open", "closed", "both"), help="loop mode(s) (default open)"
    )
    parser.add_argument("--seeds", metavar="A-B", help="seeds of the scenarios without @SEED")
    parser.add_argument(
        "--duration", type=float, metavar="S", help="seconds of each synthetic scenario"
    )
    parser.add_argument(
        "--agents", choices=("replay", "reactive"), help="closed loop: other road users"
    )
    parser.add_argument(
        "--on-collision",
        choices=("continue", "stop"),
        help="closed loop: drive on after a collision (default, as nuPlan) or end the run there",
    )
    parser.add_argument(
        "--fail-fast", action="store_true", help="a failed algorithm step fails its cell"
    )
    parser.add_argument("-o", "--out", type=Path, metavar="DIR", help="the batch directory")
    parser.add_argument(
        "--executor", choices=("local", "ray"), help="local process pool (default) or Ray"
    )
    parser.add_argument(
        "--workers", type=int, metavar="N", help="cells at a time (default: the cores)"
    )
    parser.add_argument(
        "--retries",
        type=int,
        metavar="N",
        help="run a cell whose worker died again up to N times (default 1)",
    )
    parser.add_argument(
        "--address", metavar="ADDR", help="ray: an existing cluster (default: start a local one)"
    )
    parser.add_argument(
        "--cpus-per-cell",
        type=float,
        default=1.0,
        metavar="N",
        help="ray: num_cpus per task; local: the OpenMP/BLAS threads of each cell (default 1)",
    )
    parser.add_argument("--force", action="store_true", help="redo the cells already complete")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar or lines")
    parser.add_argument(
        "--evaluate",
        action="store_true",
        help="then evaluate the batch (as `redrive evaluate BATCH`; implied by a gate)",
    )
    add_gate_options(parser, on="the pooled value (the batch is evaluated after it ran)")
    add_map_options(parser, stored=True)
    parser.set_defaults(func=_run)
