"""Run the LiDAR / camera simulation benchmark recorded in BENCHMARKS.md, several times.

    PYTHONPATH=src .venv/bin/python -m benchmarks.bench_lidar [--runs 5] [--scans 100] [--json]

Runs ``benchmarks.lidar.bench_lidar`` (the code behind ``python -m benchmarks lidar``) ``--runs``
times, each in this process and pinned to one core, and prints one line per run plus the
median; the machine is shared, so single runs vary.  Open3D is the baseline when importable.
"""

from __future__ import annotations

import argparse
import json
import statistics

from benchmarks.lidar import LidarBenchResult, bench_lidar


def _line(i: int, r: LidarBenchResult) -> str:
    o3d = "n/a" if r.open3d_scans_per_s is None else f"{r.open3d_scans_per_s:6.1f}"
    ratio = "n/a" if r.ratio is None else f"{r.ratio:4.2f}"
    return (
        f"run {i}: {r.preset} redrive {r.scans_per_s:6.1f} sweeps/s "
        f"({r.real_time_factor:4.1f}x real time, {r.points_per_scan:,.0f} pts) | "
        f"Open3D {o3d} sweeps/s | ratio {ratio} | camera {r.camera_fps:5.1f} fps"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--scans", type=int, default=100)
    parser.add_argument("--frames", type=int, default=10)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    results = [bench_lidar(scans=args.scans, camera_frames=args.frames) for _ in range(args.runs)]
    if args.json:
        print(json.dumps([r.to_json() for r in results], indent=2))
        return 0
    for i, r in enumerate(results, start=1):
        print(_line(i, r))
    ratios = [r.ratio for r in results if r.ratio is not None]
    print(
        f"median: redrive {statistics.median(r.scans_per_s for r in results):.1f} sweeps/s, "
        + (f"ratio {statistics.median(ratios):.2f}, " if ratios else "")
        + f"camera {statistics.median(r.camera_fps for r in results):.1f} fps"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
