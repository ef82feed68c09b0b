"""The LiDAR work on a sensor-level closed loop's frame thread, this tree against another tree's
``src``: CPU per ``urban`` frame of the HDL-64E sweep and of the 2D scanner's two sweeps (20 Hz),
each cast with the ego-motion skew (``map_from_base_at``) as the closed loop casts them, and
whether the clouds are equal.

    .venv/bin/python benchmarks/bench_lidar_frame_ab.py --base /tmp/main/src [--rounds 3]
        [--frames 30]

Each round runs one fresh interpreter per tree (base first, then this one).  Each steps the
world 0.6 s a frame, casts the three sweeps of the frame after one warm-up frame (numba's code
is loaded from its cache then), times them with ``time.thread_time`` (the casting thread's CPU:
robust to other load) and hashes every cloud, intensity and object id.  The medians over the
frames are printed with the load average; outputs differing between the trees are reported.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

_CHILD = r"""
import hashlib, json, sys, tempfile, time
from pathlib import Path
import numpy as np
from redrive.benchmarks.closed_loop import scenario_with_lidar
from redrive.sim.lidar import LidarModel
from redrive.sim.rig import rig_from_mapping
from redrive.sim.scenario import load_scenario
from redrive.sim.world import World
frames = int(sys.argv[1])
scenario = load_scenario(str(scenario_with_lidar("urban", "HDL-64E", Path(tempfile.mkdtemp()))))
rig = rig_from_mapping(scenario.rig, source=scenario.source)
lidar = LidarModel.from_spec(next(s for s in rig if s.kind.value == "lidar"))
scanner = LidarModel.from_spec(next(s for s in rig if s.kind.value == "lidar_2d"))
world = World(scenario)
digest = hashlib.sha256()
t3d, t2d = [], []
for k in range(frames + 1):
    world.step_to(world.time_ns + 500_000_000)
    first = world.scene()
    world.step_to(world.time_ns + 50_000_000)
    second = world.scene()
    world.step_to(world.time_ns + 50_000_000)  # the poses of both sweeps are known
    t0 = time.thread_time()
    sweep = lidar.scan(first, np.random.default_rng(k), map_from_base_at=world.map_from_base_at)
    t1 = time.thread_time()
    scans = [
        scanner.scan(s, np.random.default_rng(k), map_from_base_at=world.map_from_base_at)
        for s in (first, second)
    ]
    t2 = time.thread_time()
    if k == 0:
        continue  # warm-up
    t3d.append(t1 - t0)
    t2d.append(t2 - t1)
    for out in (sweep, *scans):
        digest.update(out.cloud.xyz.tobytes())
        digest.update(out.cloud.channels["intensity"].tobytes())
        digest.update(out.object_ids.tobytes())
print(json.dumps({"sweep_ms": float(np.median(t3d)) * 1e3, "scans_ms": float(np.median(t2d)) * 1e3,
                  "sha256": digest.hexdigest()}))
"""


def _run(src: Path, frames: int) -> dict[str, float | str]:
    env = {**os.environ, "PYTHONPATH": str(src)}
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, str(frames)],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    )
    result: dict[str, float | str] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--base", type=Path, required=True, help="the other tree's src directory")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--frames", type=int, default=30)
    args = parser.parse_args()
    here = Path(__file__).resolve().parent.parent / "src"
    sides = {"base": args.base.resolve(), "this": here}
    cpu: dict[str, dict[str, list[float]]] = {s: {"sweep": [], "scans": []} for s in sides}
    hashes: dict[str, set[str]] = {s: set() for s in sides}
    for r in range(args.rounds):
        load = Path("/proc/loadavg").read_text().split()[:3]
        for side, src in sides.items():
            res = _run(src, args.frames)
            cpu[side]["sweep"].append(float(res["sweep_ms"]))
            cpu[side]["scans"].append(float(res["scans_ms"]))
            hashes[side].add(str(res["sha256"]))
            print(
                f"round {r + 1} (load {' '.join(load)}) {side}: HDL-64E sweep "
                f"{res['sweep_ms']:.1f} ms, two 2D scans {res['scans_ms']:.1f} ms CPU a frame",
                flush=True,
            )
    for part in ("sweep", "scans"):
        base, this = (statistics.median(cpu[s][part]) for s in sides)
        print(f"{part}: median CPU base {base:.1f} ms, this {this:.1f} ms, {base / this:.2f}x")
    same = hashes["base"] == hashes["this"] and len(hashes["this"]) == 1
    print("outputs:", "identical" if same else f"DIFFERENT {hashes}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
