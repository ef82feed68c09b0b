"""What every ``redrive bench …`` command does around its measurement: a spinner on stderr
while it runs, then JSON or a report on stdout."""

from __future__ import annotations

import contextlib
import json
import sys
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["print_json", "report_console", "spinner"]


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
