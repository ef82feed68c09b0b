"""Where the one-way latency of a paced large message goes: the parts of each message, measured.

A publisher and a subscriber process (``spawn``), ``--count`` messages of ``--size`` at ``--hz``,
the benchmark's lossless 4-slot stream. Per message, on the wall clock (``time.time_ns`` on both
sides, the clock of the slot's ``publish_ns``):

* ``copy in``: the publisher's stamp → its publish (``Writer.publish``'s copy into the slot, or a
  loan's fill: ``--in-place``), from the ``publish_ns`` the writer stores at the commit;
* ``publish→wake``: the publish → the subscriber holding the message (its wake-up: the eventfd
  write, the scheduler, the re-check);
* ``copy out``: ``np.copyto`` into one reused destination (what ``Reader.read(out=…)`` does;
  none in place);
* ``touch``: one byte per 4 KiB page summed (the benchmark's subscriber work);

and the minor page faults of each part (``getrusage(RUSAGE_THREAD)``). Then the floor of the
same run: single-thread ``np.copyto`` of ``--size`` from memory (rotating over 256 MiB pools),
cache-hot, and cache-hot after a 10 ms sleep (what a 100-Hz stream's buffers are: the copies of
a paced message run at the from-memory rate even in one process)::

    PYTHONPATH=src python benchmarks/transport_paced_parts.py --size 4M --count 300
    PYTHONPATH=src python benchmarks/transport_paced_parts.py --size 4M --in-place

Wall-clock: run it on an idle machine, or read it as a breakdown, not as absolute figures.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import resource
import struct
import time
import uuid
from typing import Any

import numpy as np

_HEAD = struct.Struct("<qq")  # stamp_ns, seq (-1: the end)
_WARMUP = 10
_PARTS = ("copy in", "publish→wake", "copy out", "touch", "total")


def _faults() -> int:
    return resource.getrusage(resource.RUSAGE_THREAD).ru_minflt


def _publisher(name: str, args: argparse.Namespace, conn: Any) -> None:
    from redrive.transport import Policy, Writer

    src = np.random.default_rng(6).integers(0, 256, args.size, dtype=np.uint8)
    with Writer(name, capacity_bytes=args.size, slots=4, policy=Policy.LOSSLESS) as w:
        conn.send("up")
        conn.recv()  # the subscriber is attached
        faults = []
        period, next_s = 1.0 / args.hz, time.monotonic()
        for i in range(args.count + 1):
            wait = next_s - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            f0, stamp = _faults(), time.time_ns()
            _HEAD.pack_into(src, 0, stamp, i if i < args.count else -1)
            if args.in_place:
                with w.loan(args.size, stamp_ns=stamp) as out:
                    np.copyto(out, src)
            else:
                w.publish(src, stamp_ns=stamp)
            faults.append(_faults() - f0)
            next_s += period
        conn.send(faults)
        conn.recv()  # the subscriber has everything


def _subscriber(name: str, args: argparse.Namespace, conn: Any) -> None:
    from redrive.transport import Reader

    out = np.empty(args.size, np.uint8)
    out.fill(0)  # pre-touched, as a reused buffer is after its first message
    rows = []
    with Reader(name, timeout_s=20.0) as r:
        conn.send("ready")
        while True:
            f0 = _faults()
            with r.view(timeout_s=1.0) as msg:
                if msg is None:
                    continue
                woke, f1 = time.time_ns(), _faults()
                buf = msg.payload
                if not args.in_place:
                    np.copyto(out, buf)
                    buf = out
                copied, f2 = time.time_ns(), _faults()
                int(np.add.reduce(buf[4095::4096], dtype=np.uint64))
                touched, f3 = time.time_ns(), _faults()
                seq = _HEAD.unpack_from(buf, 0)[1]
                rows.append(
                    (msg.stamp_ns, msg.publish_ns, woke, copied, touched, f1 - f0, f2 - f1, f3 - f2)
                )
            if seq == -1:
                break
    conn.send(rows)


def _copy_ms(dst: np.ndarray, src: np.ndarray, *, sleep_s: float, n: int) -> float:
    got = []
    for _ in range(n):
        if sleep_s:
            time.sleep(sleep_s)
        t0 = time.perf_counter_ns()
        np.copyto(dst, src)
        got.append(time.perf_counter_ns() - t0)
    return float(np.median(got[2:])) / 1e6


def main() -> None:
    from redrive.benchmarks.transport import bench_memcpy, parse_size

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--size", default="4M")
    ap.add_argument("--count", type=int, default=300)
    ap.add_argument("--hz", type=float, default=100.0)
    ap.add_argument(
        "--in-place", action="store_true", help="Writer.loan + Reader.view, no copy out"
    )
    args = ap.parse_args()
    args.size = parse_size(args.size)
    name = f"parts.{os.getpid()}.{uuid.uuid4().hex[:8]}"
    ctx = multiprocessing.get_context("spawn")
    (pub_end, pub_child), (sub_end, sub_child) = ctx.Pipe(), ctx.Pipe()
    pub = ctx.Process(target=_publisher, args=(name, args, pub_child), daemon=True)
    sub = ctx.Process(target=_subscriber, args=(name, args, sub_child), daemon=True)
    pub.start()
    assert pub_end.recv() == "up"
    sub.start()
    assert sub_end.recv() == "ready"
    pub_end.send("go")
    pub_faults = pub_end.recv()
    rows = np.array(sub_end.recv()[_WARMUP:-1], dtype=np.int64)
    pub_end.send("done")
    pub.join(30.0)
    sub.join(30.0)
    stamp, published, woke, copied, touched = (rows[:, i] for i in range(5))
    parts = (published - stamp, woke - published, copied - woke, touched - copied, touched - stamp)
    mode = "in place" if args.in_place else "copy-out"
    load = os.getloadavg()[0]
    print(f"{mode}, {args.size} B at {args.hz:g} Hz, {len(rows)} messages, load {load:.1f}")
    for label, ns in zip(_PARTS, parts, strict=True):
        p50, p90, p99 = np.percentile(ns / 1e6, [50, 90, 99])
        top = ns.max() / 1e6
        print(f"  {label:14s} p50 {p50:6.3f}  p90 {p90:6.3f}  p99 {p99:6.3f}  max {top:6.3f} ms")
    wait_f, copy_f, touch_f = (rows[:, i].mean() for i in (5, 6, 7))
    print(
        f"  minor faults a message: subscriber wait {wait_f:.2f}, copy out {copy_f:.2f}, touch "
        f"{touch_f:.2f}; publisher {np.mean(pub_faults[_WARMUP:]):.2f}"
    )
    (mem,) = bench_memcpy([args.size], seconds=1.0)
    copies = 1 if args.in_place else 2
    from_memory_ms = args.size / (mem.from_memory_gb_per_s * 1e9) * 1e3
    a, b = np.ones(args.size, np.uint8), np.zeros(args.size, np.uint8)
    hot_ms = _copy_ms(b, a, sleep_s=0.0, n=50)
    idle_ms = _copy_ms(b, a, sleep_s=1.0 / args.hz, n=50)
    print(
        f"  memcpy of {args.size} B: from memory {from_memory_ms:.3f} ms "
        f"({mem.from_memory_gb_per_s:.2f} GB/s), cache-hot {hot_ms:.3f} ms, the same buffers "
        f"after {1e3 / args.hz:g} ms asleep {idle_ms:.3f} ms"
    )
    floor_ms = copies * from_memory_ms
    p50, p99 = np.percentile(parts[-1] / 1e6, [50, 99])
    print(
        f"  floor: {copies} cop{'y' if copies == 1 else 'ies'} from memory {floor_ms:.3f} ms; "
        f"total p50 ÷ floor {p50 / floor_ms:.2f}×, p99 ÷ floor {p99 / floor_ms:.2f}×"
    )


if __name__ == "__main__":
    main()
