"""The road network painted into the ground raster the sensors see (road surface, sidewalks,
lane markings, stop lines)."""

from __future__ import annotations

import math

import numpy as np

from redrive.sim.roads import STOP_LINE_WIDTH_M, RoadNetwork
from redrive.sim.scene import GroundLabel, GroundMap

__all__ = ["network_bounds", "rasterize"]

_LINE_WIDTH_M = 0.15
_DASH_ON_M, _DASH_PERIOD_M = 3.0, 9.0


def network_bounds(
    network: RoadNetwork, *, margin_m: float = 5.0
) -> tuple[float, float, float, float]:
    """xmin, ymin, xmax, ymax (metres) of every segment including sidewalks, plus ``margin_m``."""
    xs: list[float] = []
    ys: list[float] = []
    for seg in network.segments:
        s = np.linspace(0.0, seg.length_m, 33)
        for d in (seg.right_edge_m - seg.sidewalk_width_m, seg.left_edge_m + seg.sidewalk_width_m):
            x, y, _ = seg.pose_at(s, d)
            xs += [float(x.min()), float(x.max())]
            ys += [float(y.min()), float(y.max())]
    return min(xs) - margin_m, min(ys) - margin_m, max(xs) + margin_m, max(ys) + margin_m


def rasterize(
    network: RoadNetwork, *, resolution_m: float = 0.1, margin_m: float = 5.0
) -> GroundMap:
    """Paint the network into a :class:`GroundMap` (vectorised; bounded to the network's extent).

    Painting order: sidewalks, road surface (and intersection square), lane markings (dashed between
    same-direction lanes, solid centre and edge lines), stop lines.
    """
    xmin, ymin, xmax, ymax = network_bounds(network, margin_m=margin_m)
    ox = math.floor(xmin / resolution_m) * resolution_m
    oy = math.floor(ymin / resolution_m) * resolution_m
    width = math.ceil((xmax - ox) / resolution_m)
    height = math.ceil((ymax - oy) / resolution_m)
    labels = np.zeros((height, width), dtype=np.uint8)
    windows = []
    for seg in network.segments:
        bx0, by0, bx1, by1 = network_bounds(
            RoadNetwork(segments=(seg,), lanes={}, routes={}), margin_m=1.0
        )
        c0 = max(int((bx0 - ox) / resolution_m), 0)
        c1 = min(math.ceil((bx1 - ox) / resolution_m), width)
        r0 = max(int((by0 - oy) / resolution_m), 0)
        r1 = min(math.ceil((by1 - oy) / resolution_m), height)
        xc = ox + (np.arange(c0, c1, dtype=np.float64) + 0.5) * resolution_m
        yc = oy + (np.arange(r0, r1, dtype=np.float64) + 0.5) * resolution_m
        s, d = seg.local_coords(xc[None, :], yc[:, None])
        inside = (s >= 0.0) & (s <= seg.length_m)
        windows.append((seg, labels[r0:r1, c0:c1], s, d, inside))
    for seg, view, _s, d, inside in windows:
        lo, hi = seg.right_edge_m, seg.left_edge_m
        walk = inside & (
            ((d >= lo - seg.sidewalk_width_m) & (d < lo))
            | ((d > hi) & (d <= hi + seg.sidewalk_width_m))
        )
        view[walk] = GroundLabel.SIDEWALK
    for seg, view, _s, d, inside in windows:
        view[inside & (d >= seg.right_edge_m) & (d <= seg.left_edge_m)] = GroundLabel.ROAD
    if network.intersection_half_m is not None:
        h = network.intersection_half_m
        xs = ox + (np.arange(width) + 0.5) * resolution_m
        ys = oy + (np.arange(height) + 0.5) * resolution_m
        cols = np.nonzero(np.abs(xs) <= h)[0]
        rows = np.nonzero(np.abs(ys) <= h)[0]
        labels[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1] = GroundLabel.ROAD
    half_line = _LINE_WIDTH_M / 2.0
    for seg, view, s, d, inside in windows:
        w = seg.lane_width_m
        solid = [-seg.lanes_forward * w, seg.lanes_backward * w]
        if seg.lanes_forward and seg.lanes_backward:
            solid.append(0.0)
        dashed = [-i * w for i in range(1, seg.lanes_forward)] + [
            i * w for i in range(1, seg.lanes_backward)
        ]
        mark = np.zeros(d.shape, dtype=bool)
        for off in solid:
            mark |= np.abs(d - off) <= half_line
        dash_on = np.mod(s, _DASH_PERIOD_M) < _DASH_ON_M
        for off in dashed:
            mark |= (np.abs(d - off) <= half_line) & dash_on
        view[inside & mark] = GroundLabel.LANE_MARKING
    if network.signals:
        for seg, view, s, d, inside in windows:
            stop = (s >= seg.length_m - 1.0 - STOP_LINE_WIDTH_M) & (s <= seg.length_m - 1.0)
            view[inside & stop & (d <= 0.0) & (d >= -seg.lanes_forward * seg.lane_width_m)] = (
                GroundLabel.STOP_LINE
            )
    return GroundMap(origin_xy=np.array([ox, oy]), resolution_m=resolution_m, labels=labels)
