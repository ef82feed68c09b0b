"""One pass of `redrive bench read`'s loops for an instruction count under callgrind
(load-robust: the count does not depend on what else runs on the machine).

    valgrind --tool=callgrind --collect-atstart=no --toggle-collect=functools_reduce \\
        python benchmarks/read_instructions.py BAG raw|read|decode

The log is opened and read once (imports, decoder lookup, page cache, compiled paths), then
opened again and read once inside ``functools.reduce``, which is all callgrind counts:

* ``raw``: rosbags' ``messages()`` over every connection, no deserialisation;
* ``read``: ``open_log(...).messages()`` alone;
* ``decode``: ``decode`` of every message, each cloud's ``xyz.shape`` read (the bench's pass).

Note: callgrind counts a ``rep movsb`` copy once per byte moved, so the raw loop's (and the
decoder's) memcpy weighs far more in instructions than in time; compare a tree with another
on the same loop, not the loops with each other.
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rosbags.rosbag1 import Reader

from redrive.io import open_log
from redrive.io.ros.decoders import decode
from redrive.io.ros.decoders.registry import active_decoders


def _raw(log: Any) -> None:
    for _ in log.messages(connections=log.connections):
        pass


def _read(log: Any) -> None:
    for _ in log.messages():
        pass


def _decode(log: Any) -> None:
    deserialize = log.deserialize
    for message in log.messages():
        decode(message, deserialize).value.xyz.shape  # noqa: B018


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bag", type=Path)
    parser.add_argument("loop", choices=("raw", "read", "decode"))
    args = parser.parse_args()
    active_decoders()  # the entry-point scan, once a process (as the bench's pass does)
    loop: Callable[[Any], None] = {"raw": _raw, "read": _read, "decode": _decode}[args.loop]

    def opened() -> Any:
        return Reader(args.bag) if args.loop == "raw" else open_log(args.bag)

    with opened() as log:
        loop(log)
    with opened() as log:
        functools.reduce(lambda _a, _b: loop(log), [0, 1])


if __name__ == "__main__":
    main()
