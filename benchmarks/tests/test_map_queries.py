"""``benchmarks/map_queries.py`` compares equal work: on the Argoverse 2 map its linear scan (the
queries as the metrics answered them before the index) and :class:`RoadMapIndex` give the same
lane of every pose and the same distance to the road edge — the check the script makes before it
times them (it failed on every tree once the drivable area left out bike lanes and the scan did
not)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.map_queries import _agents, _indexed, _LinearScan
from redrive.maps.av2 import read_av2_map
from redrive.maps.index import RoadMapIndex

_MAP = "av2_sensor_val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede/map"


def test_the_linear_scan_and_the_index_answer_the_same(shared_data: Path) -> None:
    road = read_av2_map(sorted((shared_data / _MAP).glob("log_map_archive_*.json"))[0])
    index, scan = RoadMapIndex(road), _LinearScan(road)
    xy, yaw = _agents(road, 100, 30)
    on_a_lane = 0
    for f in range(0, 30, 3):
        got, edge = _indexed(index, xy[f], yaw[f])
        want, want_edge = scan.frame(xy[f], yaw[f])
        assert got == want
        np.testing.assert_allclose(edge, want_edge, atol=1e-9)
        on_a_lane += sum(lane is not None for lane in got)
    assert on_a_lane > 500  # most agents drive on a lane: the lane answers are compared
