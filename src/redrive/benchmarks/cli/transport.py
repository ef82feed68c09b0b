"""``redrive bench transport`` — redrive's shared-memory channel against pipe + pickle and against
memcpy, between two processes (``python -m benchmarks transport`` adds the peers)."""

from __future__ import annotations

import argparse
from typing import Any

from redrive.benchmarks.cli._console import (
    add_command,
    flag,
    num,
    option,
    print_json,
    report_console,
    spinner,
    spread_table,
    verdict,
)

__all__ = ["DESCRIPTION", "add_transport_parser"]

DESCRIPTION = """\
Move messages of each size between two fresh processes (multiprocessing spawn) with each transport
side: redrive's channel copy-out (Writer.publish -> Reader.read) and in place (Writer.loan ->
Reader.view), and pipe + pickle (the legacy path), each run flat out (throughput the subscriber
received, after a 10 % warm-up) and paced (one-way latency p50/p99 from a CLOCK_MONOTONIC stamp in
the payload). Every subscriber checks the header and sums one byte per 4 KiB page; copy sides do
it on the copy they were handed, in-place sides on the shared memory. Also single-thread
np.copyto, cache-hot and from memory (256 MiB pools): the ceiling of any copy on this machine.
Targets (issue 6): >= 10x pipe + pickle at 4 MiB; >= 50 % of the from-memory copy at 16 MiB; paced
4 MiB p99 <= 2 ms (issue 36: <= 1 ms copy-out), each latency shown against its floor: its copies
(copy-out 2, in place 1) at the from-memory memcpy rate of the same run. --repeat N runs the whole
set N times, interleaved (every side at every size once per repetition), and prints min / median /
max of each target's ratio over the repetitions, judged on the median. (Against ZeroMQ, eCAL and
iceoryx2: `PYTHONPATH=src python -m benchmarks transport` in a checkout, benchmarks/README.md.)
"""

_EPILOG = """\
examples:
  redrive bench transport                                   every side, 64K 1M 4M 16M, 2 s a run
  redrive bench transport --sizes 4M --sides redrive-inplace,pipe-pickle --seconds 5
  redrive bench transport --json > transport.json
  redrive bench transport --sizes 64K,1M,4M --repeat 3 --no-paced
"""


def _loss(sent: int, lost: int) -> str:
    if not sent:
        return "—"
    return "0" if lost == 0 else f"{lost} ({100 * lost / sent:.0f} %)"


def _print_report(result: Any, SIDES: Any) -> None:
    from rich.table import Table

    from redrive.benchmarks.transport import size_label

    console = report_console(140)
    m = result.machine
    console.print(
        f"[bold]machine[/]: {m.get('cpu', '?')}, {m.get('cpus', '?')} CPUs, "
        f"{m.get('memory', '?')}, {m.get('system', '?')}"
    )
    console.print("[bold]versions[/]: " + ", ".join(f"{k} {v}" for k, v in result.versions.items()))
    console.print(
        f"[bold]method[/]: {result.seconds:g} s per run, flat out and paced at "
        f"{result.paced_hz:g} Hz, {result.slots} slots / queue depth, first 10 % of each run "
        "is warm-up"
    )
    table = Table()
    paced = ("paced p50 ms", "paced p99 ms", "paced max ms", "paced lost")
    for col in ("size", "side", "msgs/s", "GB/s", "lost", *paced):
        table.add_column(col, justify="left" if col in ("size", "side") else "right")
    mem = {x.size_bytes: x for x in result.memcpy}
    for size in result.sizes:
        for c in (c for c in result.cells if c.size_bytes == size):
            label = SIDES[c.side].label
            if c.status != "ok" and c.flat is None:
                status = "[dim]not installed[/]" if c.status == "not installed" else "[red]error[/]"
                table.add_row(size_label(size), label, status, "", "", "", "", "", "")
                continue
            f, p = c.flat, c.paced
            table.add_row(
                size_label(size),
                label + ("" if c.status == "ok" else " [red](error)[/]"),
                num(f.msgs_per_s if f else None, ",.0f"),
                num(f.gb_per_s if f else None, ".2f"),
                _loss(f.sent, f.lost) if f else "—",
                *(
                    num(getattr(p, f"latency_{k}_ms") if p else None, ".2f")
                    for k in ("p50", "p99", "max")
                ),
                _loss(p.sent, p.lost) if p else "—",
            )
        if size in mem:
            x = mem[size]
            table.add_row(size_label(size), "memcpy cache-hot", "", num(x.hot_gb_per_s, ".2f"))
            gb = num(x.from_memory_gb_per_s, ".2f")
            table.add_row(size_label(size), "memcpy from memory", "", gb, end_section=True)
        else:
            table.rows[-1].end_section = True
    console.print(table)
    for c in result.cells:
        where = f"{SIDES[c.side].label} at {size_label(c.size_bytes)}"
        if c.status == "error":
            console.print(f"[red]{where}[/]: {c.error}")
        bad = sum(r.corrupt for r in (c.flat, c.paced) if r is not None)
        if bad:
            console.print(f"[red]{where}: {bad} messages arrived with a wrong payload[/]")
    if not result.targets:
        return
    targets = Table(title="targets (issues 6, 20)")
    for col in ("target", "side", "size", "value", "against", "ratio", "bound", "verdict"):
        targets.add_column(col, justify="left" if col in ("target", "side", "verdict") else "right")
    for t in result.targets:
        is_ms = t.target.endswith("ms")
        targets.add_row(
            t.name,
            SIDES[t.side].label,
            size_label(t.size_bytes),
            num(t.value, ".2f") + (" ms" if is_ms else " GB/s") if t.value is not None else "—",
            # a latency's reference is the floor of its copies at this run's memcpy rate
            num(t.reference, ".2f") + (" ms floor" if is_ms else " GB/s") if t.reference else "—",
            "" if t.ratio is None else f"{t.ratio:.2f}×",
            t.target,
            verdict(t.met),
        )
    console.print(targets)


def _print_floors(console: Any, spreads: Any, SIDES: Any) -> None:
    """Each latency target's floor (its copies at the from-memory memcpy rate of each
    repetition) and its value ÷ that floor, min / median / max over the repetitions."""
    from redrive.benchmarks._base import Spread

    for t in spreads:
        if t.floor_median is None:
            continue
        ratio = Spread(name=t.name, bound=1.0, at_most=True, values=t.floor_ratios)
        spread = "/".join(num(v, ".2f") for v in (ratio.min, ratio.median, ratio.max))
        console.print(
            f"{t.name}, {SIDES[t.side].label}: floor {t.floor_median:.2f} ms (median), p99 ÷ "
            f"floor {spread}× (min/median/max)" + (
                f" — the bound {t.target} is below the floor" if t.floor_median > t.bound else ""
            )
        )  # fmt: skip


def _run_transport(args: argparse.Namespace) -> int:
    from redrive.benchmarks.transport import (
        bench_transport,
        catalogue_sides,
        parse_size,
        size_label,
        target_spreads,
    )
    from redrive.errors import ConfigError

    SIDES = catalogue_sides(args.catalogue)
    sizes = [parse_size(s) for s in args.sizes.split(",") if s.strip()]
    sides = [s.strip() for s in args.sides.split(",") if s.strip()] if args.sides else list(SIDES)
    unknown = [s for s in sides if s not in SIDES]
    if unknown:
        msg = f"--sides: unknown {', '.join(unknown)} (choose from {', '.join(SIDES)})"
        raise ConfigError(msg)
    if args.seconds <= 0 or args.paced_hz <= 0:
        msg = "--seconds and --paced-hz must be greater than 0"
        raise ConfigError(msg)
    if args.repeat < 1:
        msg = "--repeat must be at least 1"
        raise ConfigError(msg)
    results = []
    with spinner() as say:
        for rep in range(args.repeat):
            prefix = f"repetition {rep + 1}/{args.repeat}: " if args.repeat > 1 else ""

            def progress(text: str, prefix: str = prefix) -> None:
                say(f"{prefix}{text}")

            results.append(
                bench_transport(
                    sizes, sides=sides, catalogue=args.catalogue, seconds=args.seconds,
                    paced_hz=args.paced_hz, paced=not args.no_paced, memcpy=not args.no_memcpy,
                    verify=args.verify, progress=progress,
                )
            )  # fmt: skip
    runs = (r for res in results for c in res.cells for r in (c.flat, c.paced) if r is not None)
    corrupt = sum(r.corrupt for r in runs)
    spreads = target_spreads(results)
    if args.json:
        print_json(
            results[0].to_json()
            if args.repeat == 1
            else {
                "repetitions": [r.to_json() for r in results],
                "spread": [t.to_json() for t in spreads],
            }
        )
    else:
        _print_report(results[-1], SIDES)
        if args.repeat > 1:

            def row(t: Any) -> list[str]:
                unit = " ms" if t.at_most else "×"
                values = (
                    num(v, ".2f") + unit if v is not None else "—" for v in (t.min, t.median, t.max)
                )
                return [
                    t.name,
                    SIDES[t.side].label,
                    size_label(t.size_bytes),
                    *values,
                    t.target,
                    verdict(t.met),
                ]

            title = f"targets over {len(results)} interleaved repetitions (verdict on the median)"
            console = report_console(140)
            console.print(spread_table(title, spreads, ("target", "side", "size"), row))
            _print_floors(console, spreads, SIDES)
    return 1 if corrupt else 0


def add_transport_parser(
    bench_sub: Any,
    *,
    catalogue: str = "redrive.benchmarks.transport.sides",
    help: str = "two-process throughput and latency: redrive's channel, pipe+pickle, memcpy",
    description: str = DESCRIPTION,
    epilog: str = _EPILOG,
) -> None:
    """``transport`` with the sides of ``catalogue`` (a module with ``SIDES``)."""
    from redrive.benchmarks.transport.sides import catalogue_sides

    sides = ", ".join(catalogue_sides(catalogue))
    parser = add_command(bench_sub, "transport", help, description, f"{epilog}\nsides: {sides}\n")
    parser.add_argument(
        "--sizes",
        default="64K,1M,4M,16M",
        metavar="LIST",
        help="message sizes, comma-separated, binary units (default 64K,1M,4M,16M; at least 4K)",
    )
    option(parser, "--seconds", 2.0, "S", "seconds per run (default 2)")
    parser.add_argument(
        "--sides",
        default=None,
        metavar="LIST",
        help="transport sides, comma-separated (default: all; see below)",
    )
    option(parser, "--paced-hz", 100.0, "HZ", "publishing rate of the latency runs (default 100)")
    flag(parser, "--no-paced", "skip the paced latency runs")
    flag(parser, "--no-memcpy", "skip the memcpy ceiling")
    flag(parser, "--verify", "subscribers compare every byte of every message (slower; numbers "
         "not comparable)")  # fmt: skip
    option(parser, "--repeat", 1, "N", "run everything N times, interleaved; print "
           "min/median/max per target ratio (default 1)")  # fmt: skip
    flag(parser, "--json", "print JSON instead of tables")
    parser.set_defaults(func=_run_transport, catalogue=catalogue)
