"""redrive.gui.map_layers.map_lines: what the planview's road-map layers draw (no Qt)."""

from __future__ import annotations

import numpy as np

from redrive.gui.map_layers import map_lines
from redrive.types import Crosswalk, MapLane, RoadMap, StopLine


def test_map_lines_draw_boundaries_crosswalks_and_stop_lines() -> None:
    lane = MapLane(
        lane_id="a",
        centerline=[[0.0, 0.0], [10.0, 0.0]],
        width_m=None,
        left_boundary=[[0.0, 1.5], [5.0, 2.0], [10.0, 1.5]],
        right_boundary=[[0.0, -1.5], [10.0, -1.5]],
    )
    plain = MapLane(lane_id="b", centerline=[[0.0, 5.0], [10.0, 5.0]], width_m=3.0)
    road = RoadMap(
        lanes=(lane, plain),
        crosswalks=(Crosswalk(crosswalk_id="c", polygon=[[12, -2], [14, -2], [14, 2], [12, 2]]),),
        stop_lines=(StopLine(stop_line_id="s", line=[[11.0, -1.5], [11.0, 1.5]], lane_ids=("a",)),),
    )
    groups = {k: v.reshape(-1, 2, 2) for k, v in map_lines(road).groups.items()}
    # lane a's own boundaries (2 + 1 segments) and lane b's derived ones (1 + 1): lane lines
    # (no boundary type says road edge); one centreline segment each
    bounds = groups["lane lines"]
    assert len(bounds) == 3 + 2
    assert np.array_equal(bounds[1], [[5.0, 2.0], [10.0, 1.5]])
    np.testing.assert_allclose(bounds[3], [[0.0, 6.5], [10.0, 6.5]])
    assert len(groups["centrelines"]) == 2
    assert len(groups["crosswalks"]) == 4  # the outline, closed
    assert np.array_equal(groups["stop lines"][0], [[11.0, -1.5], [11.0, 1.5]])
    assert len(groups["road edges"]) == len(groups["drivable areas"]) == 0
