"""One measured pass over a log, run in a fresh interpreter.

``python -m redrive.benchmarks.passes '{"kind": ..., "path": ..., "topics": [...]}'`` runs one pass and
prints its :class:`PassResult` as JSON on stdout.  Running every pass in its own process keeps the
peak-memory figures per pass and independent (nothing allocated by one pass lingers in the next).

Passes: ``raw``, the baseline (the messages of ``topics`` through ``rosbags``' ``messages`` or
``mcap``'s ``iter_messages``, no deserialisation); ``redrive``, ``open_log`` + ``decode`` of every
message to a ``PointCloud`` (each cloud's point count read; the decoder builds xyz and every
channel eagerly).  The imports and decoder lookup come before the clock starts.
"""

from __future__ import annotations

import json
import os
import resource
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

__all__ = ["PassResult", "peak_rss_bytes", "raw_pass", "redrive_pass", "run_pass"]


@dataclass(frozen=True, slots=True, kw_only=True)
class PassResult:
    """What one pass read and what it cost (seconds; resident memory at its start, after the
    interpreter and imports, and its peak)."""

    kind: str  # "raw" or "redrive"
    messages: int
    payload_bytes: int  # serialised bytes of those messages
    points: int  # points decoded (0 for the raw pass)
    open_s: float  # opening the log (index, connections, type definitions)
    loop_s: float  # the message loop (what the throughputs are computed from)
    rss_start_bytes: int
    peak_rss_bytes: int

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> PassResult:
        return cls(**data)


def peak_rss_bytes() -> int:
    """Peak resident memory of this process (``VmHWM``; ``ru_maxrss`` where /proc is absent).

    ``VmHWM`` belongs to the process's address space, which ``exec`` replaces, so it does not
    inherit the parent's peak the way ``ru_maxrss`` can.
    """
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def _rss_bytes() -> int:
    try:
        with open("/proc/self/statm", encoding="ascii") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except OSError:
        return peak_rss_bytes()


def _result(
    kind: str, counts: tuple[int, int, int], t: tuple[float, float, float], rss: int
) -> PassResult:
    messages, payload_bytes, points = counts
    return PassResult(
        kind=kind, messages=messages, payload_bytes=payload_bytes, points=points,
        open_s=t[1] - t[0], loop_s=t[2] - t[1], rss_start_bytes=rss, peak_rss_bytes=peak_rss_bytes(),
    )  # fmt: skip


def raw_pass(path: Path, topics: Sequence[str], log_format: str) -> PassResult:
    """Iterate ``topics`` with the third-party reader, no deserialisation."""
    from mcap.reader import make_reader
    from rosbags.rosbag1 import Reader as Ros1Reader
    from rosbags.rosbag2 import Reader as Ros2Reader

    rss_start = _rss_bytes()
    t0 = time.perf_counter()
    count = size = 0
    wanted = set(topics)
    if log_format in ("ros1", "ros2"):
        ros1 = log_format == "ros1"
        with (Ros1Reader if ros1 else Ros2Reader)(
            path if ros1 or path.is_dir() else path.parent
        ) as reader:
            conns = [c for c in reader.connections if c.topic in wanted]
            t1 = time.perf_counter()
            for _, _, data in reader.messages(connections=conns):
                count += 1
                size += len(data)
    elif log_format == "mcap":
        with path.open("rb") as fh:
            mreader = make_reader(fh)
            t1 = time.perf_counter()
            for _, _, message in mreader.iter_messages(topics=list(topics)):
                count += 1
                size += len(message.data)
    else:
        msg = f"no raw baseline for {log_format!r} logs (ros1, ros2, mcap only)"
        raise ValueError(msg)
    return _result("raw", (count, size, 0), (t0, t1, time.perf_counter()), rss_start)


def redrive_pass(path: Path, topics: Sequence[str]) -> PassResult:
    """``open_log`` + ``decode`` every message of ``topics`` to a PointCloud."""
    import redrive.io.mcap.reader
    import redrive.io.rosbag1.reader
    import redrive.io.rosbag2.reader  # noqa: F401  (imported here so open_s is work, not imports)
    from redrive.io import open_log
    from redrive.io.ros.decoders import decode
    from redrive.io.ros.decoders.registry import active_decoders
    from redrive.types import PointCloud

    # The decoders (redrive's and the installed plugins', an entry-point scan) are found once a
    # process, like the imports above: ≈ 20 ms that would otherwise land in the first decode of
    # the measured loop.  A fleet worker pays it once for all its logs.
    active_decoders()
    rss_start = _rss_bytes()
    t0 = time.perf_counter()
    count = size = points = 0
    with open_log(path) as reader:
        t1 = time.perf_counter()
        deserialize = reader.deserialize
        for message in reader.messages(topics=topics):
            cloud = decode(message, deserialize).value
            if not isinstance(cloud, PointCloud):
                msg = f"{message.topic}: decoded to {type(cloud).__name__}, not a PointCloud"
                raise TypeError(msg)
            points += cloud.xyz.shape[0]
            count += 1
            size += len(message.raw)
    return _result("redrive", (count, size, points), (t0, t1, time.perf_counter()), rss_start)


def run_pass(spec: dict[str, Any]) -> PassResult:
    """Run the pass described by ``spec`` (``kind``, ``path``, ``topics``, ``format``)."""
    path = Path(spec["path"])
    topics = list(spec["topics"])
    if spec["kind"] == "raw":
        return raw_pass(path, topics, str(spec["format"]))
    if spec["kind"] == "redrive":
        return redrive_pass(path, topics)
    msg = f"unknown pass kind {spec['kind']!r}"
    raise ValueError(msg)


def main(argv: Sequence[str]) -> int:
    if len(argv) != 1:
        print("usage: python -m redrive.benchmarks.passes SPEC_JSON", file=sys.stderr)
        return 2
    result = run_pass(json.loads(argv[0]))
    print(json.dumps(asdict(result)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
