"""Recovery scan speed: reading an MCAP whose summary is missing against reading it intact.

    .venv/bin/python benchmarks/bench_recover.py [LOG.mcap | --synth-mb N] [--repeat 3] [--scratch /tmp]

The intact file is read through its summary (chunk indexes); the copy cut at the end of its data
section (no summary, the commonest damage: a recorder killed before it closed the file) is read
with the forward scan.  Both are opened and read to the end with ``open_log(strict=False)``,
alternating, after one warm-up read each so the page cache holds both files; the ratio is
throughput(scan) / throughput(intact) on the medians (issue 19 asks for >= 0.5 on 1 GB).  With
``--synth-mb`` a chunked zstd MCAP of about N MB of 64 KiB messages (half random, half
compressible bytes) is written first and deleted afterwards.
"""

from __future__ import annotations

import argparse
import logging
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from redrive.io import open_log


def _write_synth(path: Path, megabytes: int) -> None:
    with path.open("wb") as fh:
        writer = Writer(fh, compression=CompressionType.ZSTD, chunk_size=4 * 1024 * 1024)
        writer.start(profile="ros2", library="bench_recover")
        schema = writer.register_schema("std_msgs/msg/UInt8MultiArray", "ros2msg", b"uint8[] data")
        channel = writer.register_channel("/blob", "cdr", schema)
        for i in range(megabytes * 16):
            payload = os.urandom(32 * 1024) + bytes(32 * 1024)
            t = 1_700_000_000_000_000_000 + i * 10_000_000
            writer.add_message(channel, t, payload, t, sequence=i)
        writer.finish()


def _cut_summary(src: Path, dst: Path) -> int:
    with src.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    if summary is None or not summary.chunk_indexes:
        msg = f"{src}: no chunk indexes to cut after (give a chunked MCAP with a summary)"
        raise SystemExit(msg)
    end = max(
        c.chunk_start_offset + c.chunk_length + c.message_index_length
        for c in summary.chunk_indexes
    )
    with src.open("rb") as fin, dst.open("wb") as fout:
        left = end
        while left:
            block = fin.read(min(left, 1 << 24))
            fout.write(block)
            left -= len(block)
    return end


def _read(path: Path) -> tuple[float, int, int]:
    """Seconds to open and read everything, messages, message bytes."""
    started = time.perf_counter()
    count = size = 0
    with open_log(path, strict=False) as log:
        for message in log.messages():
            count += 1
            size += message.size_bytes
    return time.perf_counter() - started, count, size


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", nargs="?", type=Path, help="a chunked MCAP with a summary")
    parser.add_argument("--synth-mb", type=int, help="write a synthetic MCAP of about N MB first")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scratch", type=Path, default=Path(tempfile.gettempdir()))
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    with tempfile.TemporaryDirectory(dir=args.scratch) as tmp:
        src = args.log
        if src is None:
            src = Path(tmp) / "synth.mcap"
            _write_synth(src, args.synth_mb or 256)
        cut = Path(tmp) / "no-summary.mcap"
        file_size = _cut_summary(src, cut)
        _read(src), _read(cut)  # warm the page cache
        intact, scanned = [], []
        for _ in range(args.repeat):
            t, n_intact, size = _read(src)
            intact.append(t)
            t, n_scan, _ = _read(cut)
            scanned.append(t)
        if n_scan != n_intact:
            print(f"the scan read {n_scan} messages, the intact read {n_intact}", file=sys.stderr)
            return 1
        mb = size / 1e6
        ti, ts = statistics.median(intact), statistics.median(scanned)
        print(
            f"{src.name}: {file_size / 1e6:.0f} MB file, {n_intact} messages of {mb:.0f} MB "
            f"(MB/s below: message bytes); intact (summary) {mb / ti:.0f} MB/s "
            f"(median of {args.repeat}, best {mb / min(intact):.0f}); no summary (forward scan) "
            f"{mb / ts:.0f} MB/s (best {mb / min(scanned):.0f}); ratio scan/intact {ti / ts:.2f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
