"""A/B of the object-level closed loop's three reference algorithms, step by step, in one process.

    PYTHONPATH=src .venv/bin/python benchmarks/bench_objalg_ab.py --base OTHER/src [--passes 15]
        [--agents replay|reactive]

One closed loop (``urban``, 20 s, noisy-oracle → idm-planner → pure-pursuit-pid, this tree) is
run with every step's frame, upstream outputs and output kept.  Then each algorithm of this tree
and the same module of the ``--base`` tree (loaded from its file under another name, on this
tree's types) replays those inputs, alternating pass by pass (the order flipped every pass), in
the same process: thread CPU ms a step, min and median over the passes, and the ratio.  Every
output of both is compared with the recorded one, bit for bit (objects' arrays, waypoints,
commands); a difference is reported and the exit status is 1.  The inputs are replayed in a
tight loop, so the caches are warm: a step inside the closed loop costs more (the steps table's
``cpu_ns``); the ratio is the figure to read.  Used for BENCHMARKS.md's closed-loop section
(issue 15, branch h-objalg5).
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from redrive.benchmarks.closed_loop import closed_loop_pipeline
from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.types import ControlCommands, DetectedObject, PlannedPath

_MODULES = {
    "noisy-oracle": ("oracle", "NoisyOracle"),
    "idm-planner": ("planner", "IdmPlanner"),
    "pure-pursuit-pid": ("controller", "PurePursuitPid"),
}


def _bits(value: Any) -> bytes:
    return np.asarray(value, dtype=np.float64).tobytes()


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, DetectedObject):
        scalars = ("object_id", "object_class", "confidence", "bbox_2d", "num_lidar_points")
        return (
            all(getattr(a, f) == getattr(b, f) for f in (*scalars, "visible"))
            and all(
                _bits(getattr(a, f)) == _bits(getattr(b, f))
                for f in ("velocity", "acceleration", "orientation")
            )
            and _bits(a.box.center) == _bits(b.box.center)
            and _bits(a.box.size) == _bits(b.box.size)
            and _bits(a.box.yaw_rad) == _bits(b.box.yaw_rad)
        )
    if isinstance(a, PlannedPath):
        return a.stamp_ns == b.stamp_ns and _bits(a.waypoints) == _bits(b.waypoints)
    if isinstance(a, ControlCommands):
        fields = ("throttle", "brake", "steering_angle_rad")
        return all(_bits(getattr(a, f)) == _bits(getattr(b, f)) for f in fields)
    raise TypeError(type(a))


def _capture(agents: str) -> dict[str, list[tuple[Any, Any, Any]]]:
    recorded: dict[str, list[tuple[Any, Any, Any]]] = {name: [] for name in _MODULES}
    originals = []
    for name, (module, cls_name) in _MODULES.items():
        cls = getattr(importlib.import_module(f"redrive.algorithms.reference.{module}"), cls_name)
        original = cls.step
        originals.append((cls, original))

        def step(
            self: Any, frame: Any, upstream: Any, _orig: Any = original, _n: str = name
        ) -> Any:
            out = _orig(self, frame, upstream)
            recorded[_n].append((frame, upstream, out))
            return out

        cls.step = step
    try:
        with tempfile.TemporaryDirectory(prefix="redrive-objalg-ab-") as tmp:
            request = ClosedLoopRequest(
                scenario="urban",
                pipeline=closed_loop_pipeline("object"),
                out=Path(tmp) / "run",
                duration_s=20.0,
                agents=agents,  # type: ignore[arg-type]
            )
            run_closed_loop(request)
    finally:
        for cls, original in originals:
            cls.step = original
    return recorded


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, type=Path, help="the other tree's src")
    parser.add_argument("--passes", type=int, default=15)
    parser.add_argument("--agents", default="replay", choices=("replay", "reactive"))
    args = parser.parse_args()
    recorded = _capture(args.agents)
    status = 0
    for name, (module, cls_name) in _MODULES.items():
        path = args.base / "redrive" / "algorithms" / "reference" / f"{module}.py"
        spec = importlib.util.spec_from_file_location(f"_base_{module}", path)
        assert spec is not None
        assert spec.loader is not None
        base_module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(base_module)
        new_module = importlib.import_module(f"redrive.algorithms.reference.{module}")
        algs = {
            "base": getattr(base_module, cls_name)(name=name),
            "this": getattr(new_module, cls_name)(name=name),
        }
        items = recorded[name]
        for label, alg in algs.items():
            if name != "noisy-oracle":
                alg.bind({}, extras=("vehicle_state",))
            alg.reset()
            bad = [i for i, (f, u, o) in enumerate(items) if not _same(o, alg.step(f, u))]
            if bad:
                print(f"{name} ({label}): {len(bad)} outputs differ, first frame {bad[0]}")
                status = 1
        ms: dict[str, list[float]] = {"base": [], "this": []}
        for p in range(args.passes):
            for label in ("base", "this") if p % 2 else ("this", "base"):
                alg = algs[label]
                alg.reset()
                c0 = time.thread_time()
                for frame, upstream, _ in items:
                    alg.step(frame, upstream)
                ms[label].append((time.thread_time() - c0) / len(items) * 1e3)
        with open("/proc/loadavg") as f:
            load = f.read().split()[0]
        lo = {k: min(v) for k, v in ms.items()}
        med = {k: statistics.median(v) for k, v in ms.items()}
        print(
            f"{name:17s} base {lo['base']:.4f} / {med['base']:.4f}  this {lo['this']:.4f} / "
            f"{med['this']:.4f} ms a step (min / median of {args.passes})  this/base "
            f"{lo['this'] / lo['base']:.3f} / {med['this'] / med['base']:.3f}  load {load}"
        )
    return status


if __name__ == "__main__":
    sys.exit(main())
