"""What every ``redrive bench …`` command does around its measurement: its options, a spinner on
stderr while it runs, then JSON or a report on stdout (verdicts, a table of spreads)."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.console import Console

__all__ = [
    "add_command", "flag", "num", "option", "print_json", "report_console", "spinner", "spread_table",
    "verdict",
]  # fmt: skip


def add_command(sub: Any, name: str, help: str, description: str, epilog: str) -> Any:
    """A subcommand whose description and epilog are printed as written."""
    return sub.add_parser(
        name,
        help=help,
        description=description,
        epilog=epilog,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def option(parser: Any, name: str, default: Any, metavar: str, help: str) -> None:
    """``name`` of the type of its ``default``."""
    parser.add_argument(name, type=type(default), default=default, metavar=metavar, help=help)


def flag(parser: Any, name: str, help: str) -> None:
    """``name``, an on/off switch."""
    parser.add_argument(name, action="store_true", help=help)


@contextlib.contextmanager
def spinner() -> Iterator[Callable[[str], None]]:
    """A "benchmarking" spinner on stderr; yields the ``progress`` callback benchmarks take."""
    from rich.console import Console

    with Console(stderr=True).status("benchmarking") as status:
        yield lambda text: status.update(f"benchmarking: {text}")


def print_json(data: Any) -> None:
    """``data`` as indented JSON on stdout."""
    json.dump(data, sys.stdout, indent=2)
    sys.stdout.write("\n")


def report_console(pipe_width: int = 120) -> Console:
    """The console a report is printed on: the terminal's width, or ``pipe_width`` columns in a
    pipe or a file."""
    from rich.console import Console

    return Console(width=None if sys.stdout.isatty() else pipe_width)


def verdict(met: bool | None) -> str:
    if met is None:
        return "[yellow]not measured[/]"
    return "[green]meets[/]" if met else "[red]misses[/]"


def num(x: float | None, fmt: str) -> str:
    return "—" if x is None or not math.isfinite(x) else format(x, fmt)


def spread_table(
    title: str, spreads: Iterable[Any], head: Iterable[str], row: Callable[[Any], list[str]]
) -> Any:
    """A table of :class:`~redrive.benchmarks._base.Spread` targets: ``row(target)`` gives the
    ``head`` columns, min / median / max, bound and verdict."""
    from rich.table import Table

    table = Table(title=title)
    for col in (*head, "min", "median", "max", "bound", "verdict"):
        table.add_column(col, justify="left" if col in ("target", "side", "verdict") else "right")
    for t in spreads:
        table.add_row(*row(t))
    return table
