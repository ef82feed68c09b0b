"""``redrive bench read``: redrive's ``open_log`` + ``decode`` against a raw third-party read.

Every repeat runs two passes, each in a fresh interpreter (:mod:`redrive.benchmarks.passes`):
*raw* iterates the PointCloud2 messages with ``rosbags`` or ``mcap``, no deserialisation (the
ceiling of any Python reader on those libraries); *redrive* decodes each into a
:class:`~redrive.types.PointCloud`.  Throughputs come from the message loop alone (opening is
reported apart), in messages/s and MB/s of payload (10⁶ bytes), with the page cache warmed by
one read of the whole log; the ratio is redrive's over raw's, on the median of the repeats.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from redrive.benchmarks.passes import PassResult
from redrive.errors import LogError
from redrive.io import detect_format, open_log

__all__ = [
    "POINTCLOUD2", "TUNED_MALLOC_ENV", "ReadBenchResult", "SideStats", "bench_read",
    "warm_page_cache",
]  # fmt: skip

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"

#: glibc settings that stop the allocator from returning every multi-MB message buffer to the
#: kernel (and page-faulting it back in for the next message).  With the defaults, copying
#: 3 MB messages out of a chunk — what ``rosbags`` does per message — is dominated by those page
#: faults; with these the passes measure CPU work, not allocator churn.
TUNED_MALLOC_ENV: Mapping[str, str] = {
    "MALLOC_MMAP_THRESHOLD_": str(64 << 20),
    "MALLOC_TRIM_THRESHOLD_": str(256 << 20),
}

#: the ratio redrive/raw we aim for (DESIGN: the decoder should come near the raw read).
TARGET_RATIO = 0.8


@dataclass(frozen=True, slots=True, kw_only=True)
class SideStats:
    """The repeats of one side (raw or redrive): loop seconds, median and best; open seconds
    (median); throughputs at the median and best loop times (MB = 10⁶ bytes of payload); the
    largest peak resident memory of any repeat and the median at a pass's start."""

    median_loop_s: float
    best_loop_s: float
    median_open_s: float
    msgs_per_s: float
    mb_per_s: float
    best_mb_per_s: float
    peak_rss_bytes: int
    rss_start_bytes: int


def _stats(passes: Sequence[PassResult]) -> SideStats:
    loops = [p.loop_s for p in passes]
    median = statistics.median(loops)
    best = min(loops)
    messages = passes[0].messages
    mb = passes[0].payload_bytes / 1e6
    return SideStats(
        median_loop_s=median,
        best_loop_s=best,
        median_open_s=statistics.median(p.open_s for p in passes),
        msgs_per_s=messages / median if median > 0 else float("inf"),
        mb_per_s=mb / median if median > 0 else float("inf"),
        best_mb_per_s=mb / best if best > 0 else float("inf"),
        peak_rss_bytes=max(p.peak_rss_bytes for p in passes),
        rss_start_bytes=int(statistics.median(p.rss_start_bytes for p in passes)),
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadBenchResult:
    """Every pass of one ``bench_read`` run (in the order run) and their summary; ``messages``,
    ``payload_bytes`` and ``points`` are what one pass reads (every pass reads the same),
    ``file_bytes`` the log on disk (all files of a ROS 2 bag), ``pass_env`` the environment
    variables set for the passes."""

    path: Path
    log_format: str
    file_bytes: int
    topics: tuple[str, ...]
    messages: int
    payload_bytes: int
    points: int
    warmed: bool
    pass_env: Mapping[str, str]
    raw_passes: tuple[PassResult, ...]
    redrive_passes: tuple[PassResult, ...]

    @property
    def raw(self) -> SideStats:
        return _stats(self.raw_passes)

    @property
    def redrive(self) -> SideStats:
        return _stats(self.redrive_passes)

    @property
    def ratio(self) -> float:
        """redrive throughput / raw throughput, on the median loop times."""
        return self.raw.median_loop_s / self.redrive.median_loop_s

    @property
    def best_ratio(self) -> float:
        """redrive throughput / raw throughput, on the best loop times."""
        return self.raw.best_loop_s / self.redrive.best_loop_s

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict: inputs, summary of both sides, ratio, and every pass."""
        return {
            "path": str(self.path),
            "format": self.log_format,
            "file_bytes": self.file_bytes,
            "topics": list(self.topics),
            "messages": self.messages,
            "payload_bytes": self.payload_bytes,
            "points": self.points,
            "repeats": len(self.redrive_passes),
            "page_cache_warmed": self.warmed,
            "pass_env": dict(self.pass_env),
            "raw": asdict(self.raw),
            "redrive": asdict(self.redrive),
            "ratio": self.ratio,
            "best_ratio": self.best_ratio,
            "target_ratio": TARGET_RATIO,
            "passes": [asdict(p) for p in (*self.raw_passes, *self.redrive_passes)],
        }


def _log_files(path: Path) -> list[Path]:
    if path.is_dir():
        return sorted(p for p in path.iterdir() if p.is_file())
    return [path]


def warm_page_cache(path: Path, *, block_bytes: int = 8 << 20) -> int:
    """Read every byte of the log once so the passes find it in the page cache; returns bytes."""
    total = 0
    buf = bytearray(block_bytes)
    view = memoryview(buf)
    for file in _log_files(path):
        with file.open("rb", buffering=0) as fh:
            while n := fh.readinto(view):
                total += n
    return total


def _pointcloud_topics(path: Path, topics: Iterable[str] | None) -> tuple[str, ...]:
    with open_log(path) as reader:
        available = reader.topics
        if topics is None:
            found = tuple(t for t, info in available.items() if info.msgtype == POINTCLOUD2)
            if not found:
                listed = ", ".join(f"{t} ({i.msgtype})" for t, i in available.items()) or "none"
                msg = f"{path}: no sensor_msgs/PointCloud2 topic to benchmark (topics: {listed})"
                raise LogError(msg)
            return found
        chosen = tuple(topics)
        for topic in chosen:
            info = available.get(topic)
            if info is None or info.msgtype != POINTCLOUD2:
                have = "missing" if info is None else info.msgtype
                msg = (
                    f"{path}: topic {topic!r} is not a PointCloud2 topic ({have}); "
                    "`redrive info` lists the topics"
                )
                raise LogError(msg)
        return chosen


def _spawn(spec: dict[str, Any], env: Mapping[str, str]) -> PassResult:
    cmd = [sys.executable, "-m", "redrive.benchmarks.passes", json.dumps(spec)]
    full_env = {**os.environ, **env}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=full_env, check=False)
    if proc.returncode != 0:
        tail = proc.stderr.strip().splitlines()[-5:]
        msg = f"the {spec['kind']} pass over {spec['path']} failed: " + " | ".join(tail)
        raise LogError(msg)
    return PassResult.from_json(json.loads(proc.stdout.strip().splitlines()[-1]))


def bench_read(
    path: str | Path,
    *,
    topics: Iterable[str] | None = None,
    repeats: int = 3,
    warm: bool = True,
    pass_env: Mapping[str, str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> ReadBenchResult:
    """Benchmark reading + decoding the PointCloud2 ``topics`` (None: all) of ``path`` (a ROS 1
    bag, a ROS 2 bag directory or an MCAP file) against a raw read: ``repeats`` passes per side,
    each in a fresh process with ``pass_env`` added to its environment (e.g.
    :data:`TUNED_MALLOC_ENV`), raw and redrive alternating, after one read of the whole log when
    ``warm``; ``progress`` is called with a short text before each step.

    Raises:
        LogError: the log cannot be opened, has no PointCloud2 topic, or a pass failed or read
            different messages than the other side.
    """
    path = Path(path)
    log_format = detect_format(path)
    if log_format not in ("ros1", "ros2", "mcap"):
        msg = f"{path}: {log_format} logs have no raw baseline; bench ROS 1/2 bags or MCAP files"
        raise LogError(msg)
    if repeats < 1:
        msg = f"repeats must be at least 1, not {repeats}"
        raise LogError(msg)
    chosen = _pointcloud_topics(path, topics)
    note = progress or (lambda _text: None)
    env = dict(pass_env or {})
    if warm:
        note("warming the page cache")
        warm_page_cache(path)
    spec: dict[str, Any] = {"path": str(path), "topics": list(chosen), "format": log_format}
    raw: list[PassResult] = []
    ours: list[PassResult] = []
    for i in range(repeats):
        note(f"repeat {i + 1}/{repeats}: raw")
        raw.append(_spawn({**spec, "kind": "raw"}, env))
        note(f"repeat {i + 1}/{repeats}: redrive")
        ours.append(_spawn({**spec, "kind": "redrive"}, env))
    seen = {(p.messages, p.payload_bytes) for p in (*raw, *ours)}
    if len(seen) != 1:
        msg = (
            f"{path}: the passes read different messages (messages, bytes): {sorted(seen)}; "
            "the comparison would be meaningless"
        )
        raise LogError(msg)
    return ReadBenchResult(
        path=path, log_format=log_format, file_bytes=sum(f.stat().st_size for f in _log_files(path)),
        topics=chosen, messages=raw[0].messages, payload_bytes=raw[0].payload_bytes,
        points=ours[0].points, warmed=warm, pass_env=env, raw_passes=tuple(raw),
        redrive_passes=tuple(ours),
    )  # fmt: skip
