"""Where `redrive bench read`'s time goes on a ROS 1 bag of PointCloud2: thread CPU of one
process, the loops alternating so that every one sees the same machine (load-robust: no wall
clock).

    python benchmarks/read_gap.py BAG [--rounds 8]

Loops (medians over the rounds, ms a pass over the bag):

* ``raw``: rosbags' ``messages()``, no deserialisation (the bench's baseline);
* ``read``: ``open_log(...).messages()`` alone (each message's bytes are a view: nothing copied);
* ``read + xyz copy``: the same, and per chunk batch the one ``V12`` copy of every cloud's
  x, y, z that the decoder makes (the source pages are touched here first);
* ``read + decode``: ``decode`` of every message, as the bench's redrive pass.

``read + xyz copy`` − ``read`` is what the copy costs in the loop (cold source), to compare with
the same copy repeated on one hot chunk (printed last).

The ``V12`` gather is what the decoder did until branch h-read5; it now copies each cloud's
whole point bytes (in groups of at most 256 KiB) and views xyz in them, strided: the ``read +
decode`` loop measures that, and ``benchmarks/read_cpu.py`` compares two trees.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag1 import Reader

from redrive.io import open_log
from redrive.io.ros.decoders import decode
from redrive.io.ros.decoders.pointcloud2 import read_cloud_layout


def _xyz_view(message: Any) -> np.ndarray[Any, Any] | None:
    """The x, y, z of every cloud of the message's batch as one strided V12 view (None when
    the batch is not at a fixed distance or x, y, z are not 12 adjacent bytes)."""
    if message.batch is None:
        return None
    batch, _ = message.batch
    layout = read_cloud_layout(message.raw, "ros1")
    names = {f.name: f.offset for f in layout.fields}
    x = names.get("x")
    if x is None or names.get("y") != x + 4 or names.get("z") != x + 8:
        return None
    starts = np.asarray(batch.starts)
    gaps = np.diff(starts)
    stride = int(gaps[0]) if len(gaps) else 0
    if len(gaps) and not (gaps == stride).all():
        return None
    n = layout.width * layout.height
    first = int(starts[0]) + layout.data_offset + x
    return np.ndarray((len(starts), n), "V12", batch.buffer, first, (stride, layout.point_step))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bag", type=Path)
    parser.add_argument("--rounds", type=int, default=8)
    args = parser.parse_args()
    log = open_log(args.bag)
    deserialize = log.deserialize

    def raw() -> None:
        with Reader(args.bag) as reader:
            for _, _, data in reader.messages():
                len(data)

    def read() -> None:
        for message in log.messages():
            len(message.raw)

    def read_copy() -> None:
        seen = None
        for message in log.messages():
            batch = message.batch[0] if message.batch is not None else None
            if batch is None or batch is not seen:
                seen = batch
                view = _xyz_view(message)
                if view is not None:
                    view.copy()

    def read_decode() -> None:
        for message in log.messages():
            decode(message, deserialize).value.xyz.shape  # noqa: B018

    loops: dict[str, Callable[[], None]] = {
        "raw": raw,
        "read": read,
        "read + xyz copy": read_copy,
        "read + decode": read_decode,
    }
    spent: dict[str, list[float]] = {name: [] for name in loops}
    for _ in range(args.rounds):
        for name, loop in loops.items():
            start = time.thread_time()
            loop()
            spent[name].append(time.thread_time() - start)
    with open("/proc/loadavg", encoding="ascii") as fh:
        load = fh.read().split()[0]
    print(f"{args.bag}: thread CPU ms a pass, median (min) of {args.rounds}; load {load}")
    for name, values in spent.items():
        print(f"  {name:16s} {statistics.median(values) * 1e3:8.1f} ({min(values) * 1e3:.1f})")
    # The same copy on one chunk whose pages are resident and in cache.
    for message in log.messages():
        view = _xyz_view(message)
        if view is not None and len(view) > 1:
            break
    else:
        return
    view.copy()
    best = float("inf")
    for _ in range(5):
        start = time.thread_time()
        for _ in range(50):
            view.copy()
        best = min(best, (time.thread_time() - start) / 50)
    points = view.size
    print(
        f"  hot copy of one chunk's {points} points: {best * 1e6:.1f} us ({best / points * 1e9:.2f} ns a point)"
    )


if __name__ == "__main__":
    main()
