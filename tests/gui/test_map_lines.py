"""redrive.gui.closedloop.map_polylines: what the planview's road-map layer draws (no Qt)."""

from __future__ import annotations

import numpy as np

from redrive.gui.closedloop import map_polylines
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
    seg = map_polylines(road).reshape(-1, 2, 2)
    # lane a's own boundaries (2 + 1 segments), lane b's derived ones (1 + 1), the crosswalk's
    # outline (4) and the stop line (1)
    assert len(seg) == 3 + 2 + 4 + 1
    assert np.array_equal(seg[1], [[5.0, 2.0], [10.0, 1.5]])
    np.testing.assert_allclose(seg[3], [[0.0, 6.5], [10.0, 6.5]])
    assert np.array_equal(seg[-1], [[11.0, -1.5], [11.0, 1.5]])
