"""`redrive bench read`'s two loops in thread CPU, alternating in one process (load-robust: no
wall clock, both loops see the same machine).

    python benchmarks/read_cpu.py BAG [--rounds 7]

* ``raw``: rosbags' ``messages()`` over every connection, no deserialisation;
* ``redrive``: ``open_log(...).messages()`` + ``decode`` of every message, each cloud's
  ``xyz.shape`` read (the bench's redrive pass).

Prints the medians (ms a pass), ratio = raw / redrive, and the load average.  For a before/after
comparison run it with ``PYTHONPATH=<tree>/src`` for each tree, in fresh processes, alternating;
set ``MALLOC_MMAP_THRESHOLD_=67108864 MALLOC_TRIM_THRESHOLD_=268435456`` (``--tune-malloc``).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from rosbags.rosbag1 import Reader

from redrive.io import open_log
from redrive.io.ros.decoders import decode
from redrive.io.ros.decoders.registry import active_decoders
from redrive.types import PointCloud


def _raw(bag: Path) -> float:
    with Reader(bag) as reader:
        start = time.thread_time()
        for _, _, _data in reader.messages(connections=reader.connections):
            pass
        return time.thread_time() - start


def _redrive(bag: Path) -> float:
    points = 0
    with open_log(bag) as log:
        deserialize = log.deserialize
        start = time.thread_time()
        for message in log.messages():
            cloud = decode(message, deserialize).value
            assert isinstance(cloud, PointCloud)
            points += cloud.xyz.shape[0]
        return time.thread_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bag", type=Path)
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    active_decoders()  # the entry-point scan, once a process (as the bench's pass does)
    raw: list[float] = []
    ours: list[float] = []
    _raw(args.bag), _redrive(args.bag)  # warm-up: imports, page cache, compiled paths
    for _ in range(args.rounds):
        raw.append(_raw(args.bag))
        ours.append(_redrive(args.bag))
    r, o = statistics.median(raw), statistics.median(ours)
    with open("/proc/loadavg", encoding="ascii") as fh:
        load = fh.read().split()[0]
    print(
        f"{args.bag.name}: raw {r * 1e3:.1f} ms, redrive {o * 1e3:.1f} ms, ratio {r / o:.2f}, load {load}"
    )


if __name__ == "__main__":
    main()
