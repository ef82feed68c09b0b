"""Road-map queries for 100 agents at 10 Hz on the Argoverse 2 log map (issue 34's target:
lane of pose and distance to the road edge ≤ 1 ms a frame), against the linear scan they
replaced, in one process.

    PYTHONPATH=src python benchmarks/map_queries.py [--agents 100] [--frames 100] [--rounds 7]
    PYTHONPATH=src valgrind --tool=callgrind --instr-atstart=no --collect-atstart=no \\
        --toggle-collect=_operator_call --callgrind-out-file=cg.out \\
        python benchmarks/map_queries.py --callgrind      # instructions a frame (load-robust)

Agents drive along lanes of the map at 10 m/s, each frame 0.1 s later.  A frame is
``RoadMapIndex.lane_of_pose`` (all agents at once) plus ``distance_to_road_edge_m``.  The
baseline is what the closed-loop metrics did before the index: every lane polygon tested per
point (``shapely.intersects_xy`` lane by lane), the nearest centreline of the lanes holding it,
and the distance to the drivable area's boundary as one geometry.  Thread CPU a frame, median
over interleaved rounds, with the load average (the machine is shared: read the ratio, and the
index's figure as an upper bound).  ``--callgrind``: the index's frames only, counted through
``operator.call`` under callgrind.
"""

from __future__ import annotations

import argparse
import math
import operator
import os
import statistics
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from redrive.evaluation._kinematics import project_on_polyline
from redrive.maps.av2 import read_av2_map
from redrive.maps.index import DRIVABLE_LANE_KINDS, RoadMapIndex, lane_polygon
from redrive.types import RoadMap

_DATA = Path(os.environ.get("REDRIVE_SHARED_DATA", Path(__file__).parents[2] / "shared" / "data"))
_MAP = "av2_sensor_val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede/map"


def _map() -> RoadMap:
    for root in (_DATA, Path("/work/shared/data")):
        found = sorted((root / _MAP).glob("log_map_archive_*.json"))
        if found:
            return read_av2_map(found[0])
    msg = f"the AV2 map is not under {_DATA / _MAP} (set REDRIVE_SHARED_DATA)"
    raise SystemExit(msg)


def _agents(road: RoadMap, agents: int, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """(frames, agents, 2) positions and (frames, agents) headings along vehicle lanes."""
    rng = np.random.default_rng(34)
    lanes = [lane for lane in road.lanes if lane.kind == "vehicle"]
    xy = np.empty((frames, agents, 2))
    yaw = np.empty((frames, agents))
    for a in range(agents):
        lane = lanes[int(rng.integers(len(lanes)))]
        line = lane.centerline
        seg = np.diff(line, axis=0)
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
        s0 = rng.uniform(0.0, cum[-1])
        s = np.mod(s0 + 1.0 * np.arange(frames), max(cum[-1], 1e-6))  # 10 m/s at 10 Hz
        j = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
        t = (s - cum[j]) / np.maximum(cum[j + 1] - cum[j], 1e-9)
        xy[:, a] = line[j] + t[:, None] * seg[j] + rng.normal(0.0, 0.3, (frames, 2))
        yaw[:, a] = np.arctan2(seg[j, 1], seg[j, 0]) + rng.normal(0.0, 0.05, frames)
    return xy, yaw


class _LinearScan:
    """The queries as the metrics answered them before the index (every lane, every point)."""

    def __init__(self, road: RoadMap) -> None:
        self.lanes = road.lanes
        self.polys = [lane_polygon(lane) for lane in road.lanes]
        # the road edge: the boundary of the drivable area — the lanes cars drive (bike lanes
        # are lanes, not road) and the map's drivable areas, as RoadMapIndex.drivable
        areas = [shapely.make_valid(shapely.Polygon(a.polygon)) for a in road.areas]
        roads = [
            p
            for p, lane in zip(self.polys, road.lanes, strict=True)
            if lane.kind in DRIVABLE_LANE_KINDS
        ]
        self.edge = shapely.boundary(shapely.union_all([*roads, *areas]))
        for p in self.polys:
            shapely.prepare(p)

    def frame(self, xy: np.ndarray, yaw: np.ndarray) -> tuple[list[str | None], np.ndarray]:
        inside = np.array([shapely.intersects_xy(p, xy[:, 0], xy[:, 1]) for p in self.polys])
        out: list[str | None] = []
        for k in range(xy.shape[0]):
            best: tuple[float, str] | None = None
            for m in np.flatnonzero(inside[:, k]):
                _, d, h = project_on_polyline(xy[k : k + 1], self.lanes[m].centerline)
                diff = abs((float(h[0]) - yaw[k] + math.pi) % (2 * math.pi) - math.pi)
                if diff < math.pi / 2 and (best is None or abs(float(d[0])) < best[0]):
                    best = (abs(float(d[0])), self.lanes[m].lane_id)
            out.append(None if best is None else best[1])
        return out, np.asarray(shapely.distance(self.edge, shapely.points(xy)))


def _indexed(index: RoadMapIndex, xy: np.ndarray, yaw: np.ndarray) -> Any:
    return index.lane_of_pose(xy, yaw), index.distance_to_road_edge_m(xy)


def _cpu_per_frame(fn: Any, xy: np.ndarray, yaw: np.ndarray) -> float:
    t0 = time.thread_time()
    for f in range(xy.shape[0]):
        fn(xy[f], yaw[f])
    return (time.thread_time() - t0) / xy.shape[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=100)
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--callgrind", action="store_true", help="count the index's frames")
    args = parser.parse_args()
    road = _map()
    t0 = time.thread_time()
    index = RoadMapIndex(road)
    build_s = time.thread_time() - t0
    xy, yaw = _agents(road, args.agents, args.frames)
    if args.callgrind:
        _indexed(index, xy[0], yaw[0])  # warm
        subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=False)
        for f in range(args.frames):
            operator.call(_indexed, index, xy[f], yaw[f])  # type: ignore[attr-defined]
        print(f"{args.frames} frames of {args.agents} agents counted (divide by {args.frames})")
        return
    scan = _LinearScan(road)
    # both answer the same: the benchmark compares equal work
    for f in range(0, args.frames, 10):
        got, edge = _indexed(index, xy[f], yaw[f])
        want, want_edge = scan.frame(xy[f], yaw[f])
        assert got == want, (f, [(g, w) for g, w in zip(got, want, strict=True) if g != w])
        np.testing.assert_allclose(edge, want_edge, atol=1e-9)
    fast, slow = [], []
    for _ in range(args.rounds):
        fast.append(_cpu_per_frame(lambda p, h: _indexed(index, p, h), xy, yaw))
        slow.append(_cpu_per_frame(scan.frame, xy, yaw))
    load = Path("/proc/loadavg").read_text().split()[0]
    f_ms, s_ms = statistics.median(fast) * 1e3, statistics.median(slow) * 1e3
    print(
        f"AV2 map: {len(road.lanes)} lanes, {len(road.areas)} drivable areas; index built in "
        f"{build_s * 1e3:.1f} ms CPU"
    )
    print(
        f"{args.agents} agents, {args.frames} frames, {args.rounds} rounds (load {load}): "
        f"indexed {f_ms:.3f} ms a frame (min {min(fast) * 1e3:.3f}), linear scan {s_ms:.3f} ms "
        f"(min {min(slow) * 1e3:.3f}); {s_ms / f_ms:.1f}× faster; target ≤ 1 ms: "
        f"{'met' if f_ms <= 1.0 else 'NOT met'}"
    )


if __name__ == "__main__":
    main()
