"""``python -m benchmarks loss`` — the paper's loss experiment: legacy pipes + pickle against redrive."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner

__all__ = ["add_loss_parser"]

_DESCRIPTION = """\
Four sensor streams (3D LiDAR 60 Hz with VLP-16 sweeps of 28,800 points, 2D LiDAR 15 Hz,
1280x720 rgb camera 15 Hz, IMU 15 Hz), paced by the wall clock, go from a collector process to a
core process through (a) the legacy chain of the paper: a pipe with pickle to a bridge process,
then a multiprocessing queue to the core, and (b) redrive's shared-memory transport, one stream per
sensor (keep-latest; redrive-lossless: lossless). Every configuration runs SECONDS, one after the
other, at each rate factor (10 = ten times the rates). Per second and stream: the ID difference
(newest ID produced minus highest ID received, largest over the second's receipts); the
cumulative error is its sum. Also lost (never delivered) and late messages and latencies. Writes
loss.json (with the per-second series), loss.png (ID difference over time, as the paper's Figures
10/11) and loss_table.md (as its Table 5) to --out. Target: redrive's cumulative error 0 and
nothing lost, at 1x and 10x.
"""

_EPILOG = """\
examples:
  python -m benchmarks loss                                   30 minutes per configuration (2 hours)
  python -m benchmarks loss --seconds 300 --out /tmp/loss
  python -m benchmarks loss --seconds 20 --rates 1 --chains legacy,redrive,redrive-lossless --json
"""


def _floats(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        values = ()
    if not values or any(v <= 0 for v in values):
        msg = f"expected rate factors > 0 separated by commas, such as 1,10 (got {text!r})"
        raise argparse.ArgumentTypeError(msg)
    return values


def _chains(text: str) -> tuple[str, ...]:
    from benchmarks.loss import CHAINS

    values = tuple(x.strip() for x in text.split(",") if x.strip())
    bad = [v for v in values if v not in CHAINS]
    if not values or bad:
        msg = f"chains are a comma-separated list of {', '.join(CHAINS)} (got {text!r})"
        raise argparse.ArgumentTypeError(msg)
    return values


def _verdict(ok: bool | None) -> str:
    return "" if ok is None else "[green]meets[/]" if ok else "[red]misses[/]"


def _print_report(result: Any, paths: dict[str, Path]) -> None:
    from rich.table import Table

    console = report_console(140)
    m = result.machine
    console.print(
        f"[bold]machine[/] {m['cpu']}, {m['cpus']} CPUs, {m['system']}, Python {m['python']}; "
        f"load average at start {m['load_average_at_start']}"
    )
    console.print(f"[bold]run[/] {result.seconds:g} s per configuration, one after the other")
    if result.wakeup is not None:
        w = result.wakeup
        console.print(
            f"[bold]wake-up[/] time.sleep({w['period_ms']:.2f} ms) overshoots by p50 "
            f"{w['overshoot_p50_ms']:.2f} / p99 {w['overshoot_p99_ms']:.2f} / max "
            f"{w['overshoot_max_ms']:.2f} ms; {w['fraction_over_one_period']:.2%} by more than "
            "the period (the floor under 'late' at that rate, whatever the transport)"
        )
    table = Table()
    for col in (
        "configuration", "stream", "Hz", "due", "delivered", "lost", "late",
        "cumulative error", "max ID diff", "latency p50/p99/max ms",
    ):  # fmt: skip
        table.add_column(col, justify="left" if col in ("configuration", "stream") else "right")
    for c in result.configs:
        if c.error is not None:
            table.add_row(c.label, "[red]failed[/]", c.error.splitlines()[0])
            continue
        for s in c.streams:
            table.add_row(
                c.label, s.name, f"{s.rate_hz:g}", f"{s.due:,}", f"{s.delivered:,}",
                f"{s.lost:,}", f"{s.late:,}", f"{s.cumulative_error:,}", f"{s.max_id_diff:,}",
                f"{s.latency_p50_ms:.2f} / {s.latency_p99_ms:.2f} / {s.latency_max_ms:.1f}",
            )  # fmt: skip
        table.add_row(
            f"[bold]{c.label}[/]", "[bold]all[/]", "", "", "", f"[bold]{c.lost:,}[/]", "",
            f"[bold]{c.cumulative_error:,}[/]", "", "", end_section=True,
        )  # fmt: skip
    console.print(table)
    for c in result.configs:
        if c.meets_target is not None:
            console.print(
                f"{c.label}: cumulative error {c.cumulative_error:,}, lost {c.lost:,} — "
                f"{_verdict(c.meets_target)} the target (0 and 0)"
            )
    console.print(f"wrote {paths['json']}, {paths['png']}, {paths['table']}")


def _run_loss(args: argparse.Namespace) -> int:
    from benchmarks.loss import SLOTS, bench_loss, write_outputs

    with spinner() as progress:
        result = bench_loss(
            seconds=args.seconds,
            rate_factors=args.rates,
            chains=args.chains,
            slots=SLOTS if args.slots is None else args.slots,
            progress=progress,
        )
    paths = write_outputs(result, args.out)
    failed = any(c.error is not None for c in result.configs)
    if args.json:
        out = result.to_json(series=False)
        out["files"] = {kind: str(path) for kind, path in paths.items()}
        print_json(out)
    else:
        _print_report(result, paths)
    return 1 if failed else 0


def add_loss_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "loss",
        help="the paper's loss experiment: sensor streams through pipes + pickle vs redrive",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--seconds",
        type=float,
        default=1800.0,
        metavar="S",
        help="length of each configuration (default 1800 = 30 minutes, as the paper)",
    )
    parser.add_argument(
        "--rates",
        type=_floats,
        default=(1.0, 10.0),
        metavar="F,F",
        help="rate factors (default 1,10: the sensor rates and ten times them)",
    )
    parser.add_argument(
        "--chains",
        type=_chains,
        default=("legacy", "redrive"),
        metavar="C,C",
        help="legacy, redrive (keep-latest), redrive-lossless (default legacy,redrive)",
    )
    parser.add_argument(
        "--slots",
        type=int,
        default=None,
        metavar="N",
        help="slots per redrive stream (default 8, as redrive.live)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("bench-loss"),
        metavar="DIR",
        help="where loss.json, loss.png and loss_table.md go (default ./bench-loss)",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print JSON (without the per-second series; those are in DIR/loss.json)",
    )
    parser.set_defaults(func=_run_loss)
