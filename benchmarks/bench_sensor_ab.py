"""The sensor-level closed loop's renderers, this tree against another tree's ``src``: CPU per
1280×720 camera image and per 64-beam LiDAR sweep of ``urban``, and whether the outputs are equal.

    .venv/bin/python benchmarks/bench_sensor_ab.py --base /tmp/main/src [--rounds 3] [--frames 12]

Each round runs one fresh interpreter per tree (base first, then this one), interleaved.  Each
renders ``--frames`` scenes of ``urban`` (0.7 s apart, the HDL-64E swapped in) on one thread
after one warm-up call (numba's compiled code is loaded from its cache then), times them with
``time.thread_time`` (CPU of the rendering thread: robust to other load), and hashes every image,
depth map, cloud and channel.  The load average is printed with each round.  Outputs differing
between the trees are reported, not hidden.
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
from redrive.sim.camera import CameraModel
from redrive.sim.lidar import LidarModel
from redrive.sim.rig import rig_from_mapping
from redrive.sim.scenario import load_scenario
from redrive.sim.world import World
frames = int(sys.argv[1])
scenario = load_scenario(str(scenario_with_lidar("urban", "HDL-64E", Path(tempfile.mkdtemp()))))
rig = rig_from_mapping(scenario.rig, source=scenario.source)
camera = CameraModel.from_spec(next(s for s in rig if s.kind.value == "camera"))
camera.workers = 1
lidar = LidarModel.from_spec(next(s for s in rig if s.kind.value == "lidar"))
world = World(scenario)
camera.render(world.scene())
lidar.scan(world.scene(), np.random.default_rng(0))
digest = hashlib.sha256()
cam_s = lidar_s = 0.0
for k in range(frames):
    world.step_to(world.time_ns + 700_000_000)
    scene = world.scene()
    t0 = time.thread_time()
    image = camera.render(scene)
    t1 = time.thread_time()
    sweep = lidar.scan(scene, np.random.default_rng(k))
    t2 = time.thread_time()
    cam_s += t1 - t0
    lidar_s += t2 - t1
    digest.update(image.image.pixels.tobytes())
    digest.update(image.depth_m.tobytes())
    digest.update(repr(sorted(image.pixels_per_object.items())).encode())
    digest.update(sweep.cloud.xyz.tobytes())
    for name in sorted(sweep.cloud.channels):
        digest.update(np.asarray(sweep.cloud.channels[name]).tobytes())
    digest.update(sweep.object_ids.tobytes())
print(json.dumps({"camera_ms": cam_s / frames * 1e3, "lidar_ms": lidar_s / frames * 1e3,
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
    parser.add_argument("--frames", type=int, default=12)
    args = parser.parse_args()
    here = Path(__file__).resolve().parent.parent / "src"
    sides = {"base": args.base.resolve(), "this": here}
    cpu: dict[str, dict[str, list[float]]] = {s: {"camera": [], "lidar": []} for s in sides}
    hashes: dict[str, set[str]] = {s: set() for s in sides}
    for r in range(args.rounds):
        load = Path("/proc/loadavg").read_text().split()[:3]
        for side, src in sides.items():
            res = _run(src, args.frames)
            cpu[side]["camera"].append(float(res["camera_ms"]))
            cpu[side]["lidar"].append(float(res["lidar_ms"]))
            hashes[side].add(str(res["sha256"]))
            print(
                f"round {r + 1} (load {' '.join(load)}) {side}: camera {res['camera_ms']:.1f} ms, "
                f"64-beam sweep {res['lidar_ms']:.1f} ms CPU",
                flush=True,
            )
    for part in ("camera", "lidar"):
        base, this = (statistics.median(cpu[s][part]) for s in sides)
        print(f"{part}: median CPU base {base:.1f} ms, this {this:.1f} ms, {base / this:.2f}x")
    same = hashes["base"] == hashes["this"] and len(hashes["this"]) == 1
    print("outputs:", "identical" if same else f"DIFFERENT {hashes}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
