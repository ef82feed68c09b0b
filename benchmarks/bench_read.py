"""Run the read benchmarks recorded in BENCHMARKS.md and print one summary line per case.

    PYTHONPATH=src .venv/bin/python -m benchmarks.bench_read [--big] [--scratch /tmp] [--json-dir DIR]

Runs ``redrive.benchmarks.read.bench_read`` (the code behind ``redrive bench read``) on the real bags
in ../shared/data (when present) and on synthetic bags written to ``--scratch`` and deleted
afterwards: 0.32 GB of 100k-point clouds in both point layouts, and with ``--big`` 2 GB.  Every
case runs twice: with glibc's default allocator settings and with ``--tune-malloc``'s.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from benchmarks.synth_log import Layout, write_synthetic_bag
from redrive.benchmarks.read import TUNED_MALLOC_ENV, ReadBenchResult, bench_read

_SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
_REAL = (
    _SHARED / "rosbag1_real" / "embag_luminar_test.bag",
    _SHARED / "rosbag1_recorded_here" / "kitti_3frames_rosbag_record_lz4.bag",
)


def _line(name: str, malloc: str, r: ReadBenchResult) -> str:
    raw, ours = r.raw, r.redrive
    return (
        f"{name:28s} {malloc:7s} {r.messages:4d} msgs {r.payload_bytes / 1e6:8.1f} MB | "
        f"raw {raw.mb_per_s:7.0f} MB/s {raw.msgs_per_s:8.1f} msg/s | "
        f"redrive {ours.mb_per_s:7.0f} MB/s {ours.msgs_per_s:8.1f} msg/s | "
        f"ratio {r.ratio:4.2f} (best {r.best_ratio:4.2f}) | "
        f"open {ours.median_open_s:.3f}s vs {raw.median_open_s:.3f}s | "
        f"peak RSS redrive {ours.peak_rss_bytes / 1e6:5.1f} MB raw {raw.peak_rss_bytes / 1e6:5.1f} MB"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--big", action="store_true", help="also write and read a 2 GB bag")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--scratch", type=Path, default=Path(tempfile.gettempdir()))
    parser.add_argument("--json-dir", type=Path, default=None)
    args = parser.parse_args()
    cases: list[tuple[str, Path, bool]] = [(p.name, p, False) for p in _REAL if p.is_file()]
    synth: list[tuple[str, float, Layout]] = [
        ("synth-0.32GB-xyzi", 0.32, "xyzi"),
        ("synth-0.32GB-velodyne", 0.32, "velodyne"),
    ]
    if args.big:
        synth.append(("synth-2GB-velodyne", 2.0, "velodyne"))
    for name, size_gb, layout in synth:
        out = args.scratch / f"redrive-{name}.bag"
        out.unlink(missing_ok=True)
        write_synthetic_bag(out, size_bytes=round(size_gb * 1e9), layout=layout)
        cases.append((name, out, True))
    try:
        for name, path, _ in cases:
            repeat = 3 if path.stat().st_size > 1e9 else args.repeat
            for malloc, env in (("default", None), ("tuned", TUNED_MALLOC_ENV)):
                result = bench_read(path, repeats=repeat, pass_env=env)
                print(_line(name, malloc, result), flush=True)
                if args.json_dir is not None:
                    args.json_dir.mkdir(parents=True, exist_ok=True)
                    target = args.json_dir / f"{name}-{malloc}.json"
                    target.write_text(json.dumps(result.to_json(), indent=2))
    finally:
        for _, path, made in cases:
            if made:
                path.unlink(missing_ok=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
