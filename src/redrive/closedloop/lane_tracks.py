"""The logged tracks of ``--agents reactive`` (:mod:`redrive.closedloop.lane_agents`) and their
lane lines.

Before the first frame every logged track of a vehicle (``vehicle``, ``truck``, ``motorcycle``
ground truth with a track id) is read whole (:meth:`FrameAssembler.ground_truth
<redrive.assembly.frames.FrameAssembler.ground_truth>`, moved into the map frame by the logged
ego pose at its stamp) and mapped onto the lane graph as the ego's route is
(:func:`redrive.maps.route.route_along_path`): its *lane line* is the centrelines of the lanes it
drives (its logged lane changes as blends), continued along successors past its last sample.
A track on no lane keeps its own logged path as its line.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely

from redrive.assembly.frames import FrameAssembler
from redrive.maps.index import RoadMapIndex
from redrive.maps.polylines import packed, polyline_locate
from redrive.maps.route import routes_along_paths
from redrive.types import Mission, ObjectClass, ObjectColumns, RoadMap

__all__ = ["LANE_CLASSES", "Track", "TrackSamples", "lane_tracks", "on_line", "read_tracks"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
#: the ground-truth classes that drive along lanes
LANE_CLASSES = frozenset({ObjectClass.VEHICLE, ObjectClass.TRUCK, ObjectClass.MOTORCYCLE})
#: how far past its last sample a track's lane line goes on along successors, metres
_EXTEND_M = 40.0


@dataclass(slots=True, eq=False)
class Track:
    """One logged vehicle: its samples (map frame) and its lane line.

    Attributes:
        stamps_ns, xy, yaw_rad: the logged samples.
        length_m, width_m: its box (the first sample's).
        line: its lane line (shapely LineString); ``line_xy`` its vertices.
        s_log: (K,) each sample projected on the line, metres (non-decreasing).
        stops: (stop line id, light id or None, arclength on the line) of the stop lines of
            its lanes.
        desired_speed_mps: its IDM desired speed.
        lanes: the lanes of its line (() when it is on none).
    """

    object_id: int
    stamps_ns: npt.NDArray[np.int64]
    xy: F64
    yaw_rad: F64
    length_m: float
    width_m: float
    line: Any
    s_log: F64
    stops: list[tuple[str, str | None, float]]
    desired_speed_mps: float
    lanes: tuple[str, ...]
    line_length_m: float = 0.0
    bounds: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # the line's (x0, y0, x1, y1)
    first_ns: int = 0
    last_ns: int = 0
    #: its line's number in :class:`LaneAgents`' packed lines (the compiled projections)
    line_number: int = -1
    # -- the simulation state ---------------------------------------------------------------
    lane_mode: bool = False
    s_m: float = 0.0
    speed_mps: float = 0.0
    served: set[str] = field(default_factory=set)
    #: sample stamp → (x, y, yaw, s on the line, speed along it): what the interpolations below
    #: give at a sample's own stamp (np.interp there returns the sample), looked up; empty when
    #: two samples' stamps are one float (then every stamp is interpolated)
    _at_sample: dict[int, tuple[float, float, float, float, float]] = field(
        default_factory=dict, repr=False
    )
    #: the line's vertices and the arclength at each segment's end, summed as GEOS sums them
    #: (:func:`on_line`; made when it first asks)
    _line_x: list[float] = field(default_factory=list, repr=False)
    _line_y: list[float] = field(default_factory=list, repr=False)
    _seg_m: list[float] = field(default_factory=list, repr=False)
    _seg_end_m: list[float] = field(default_factory=list, repr=False)

    def __post_init__(self) -> None:
        stamps = self.stamps_ns
        if stamps.size and bool(np.all(np.diff(stamps.astype(np.float64)) > 0.0)):
            # _speed_interpolated at sample j reads the step from sample min(j, K−2) on (s_log
            # never decreases: the step is ≥ 0); one sample: 0
            if stamps.size >= 2:
                step = np.diff(self.s_log) / (np.diff(stamps) / 1e9)
                speeds = step[np.minimum(np.arange(stamps.size), stamps.size - 2)].tolist()
            else:
                speeds = [0.0]
            rows = zip(
                stamps.tolist(),
                self.xy.tolist(),
                self.yaw_rad.tolist(),
                self.s_log.tolist(),
                speeds,
                strict=True,
            )
            self._at_sample = {stamp: (x, y, yaw, s, v) for stamp, (x, y), yaw, s, v in rows}

    def s_logged(self, stamp_ns: int) -> float:
        """The logged position at ``stamp_ns`` on the line (linear between samples)."""
        at = self._at_sample.get(stamp_ns)
        if at is not None:
            return at[3]
        return float(np.interp(stamp_ns, self.stamps_ns, self.s_log))

    def speed_logged(self, stamp_ns: int) -> float:
        """The logged speed along the line at ``stamp_ns`` (difference of the samples)."""
        at = self._at_sample.get(stamp_ns)
        if at is not None:
            return at[4]
        return self._speed_interpolated(stamp_ns)

    def logged_xy_yaw(self, stamp_ns: int) -> tuple[float, float, float]:
        """The logged centre (linear between samples) and the heading of the sample at or after
        ``stamp_ns``."""
        at = self._at_sample.get(stamp_ns)
        if at is not None:
            return at[0], at[1], at[2]
        t = self.stamps_ns
        x = float(np.interp(stamp_ns, t, self.xy[:, 0]))
        y = float(np.interp(stamp_ns, t, self.xy[:, 1]))
        k = min(int(np.searchsorted(t, stamp_ns)), t.size - 1)
        return x, y, float(self.yaw_rad[k])

    def _speed_interpolated(self, stamp_ns: int) -> float:
        k = int(np.searchsorted(self.stamps_ns, stamp_ns, side="right"))
        k = min(max(k, 1), self.stamps_ns.size - 1)
        if self.stamps_ns.size < 2:
            return 0.0
        dt = (self.stamps_ns[k] - self.stamps_ns[k - 1]) / 1e9
        return max(0.0, float(self.s_log[k] - self.s_log[k - 1]) / dt) if dt > 0 else 0.0


def _logged_pose_at(mission: Mission, stamps_ns: npt.NDArray[np.int64]) -> tuple[F64, F64, F64]:
    rel = (mission.logged_stamps_ns - mission.logged_stamps_ns[0]).astype(np.float64)
    at = (stamps_ns - mission.logged_stamps_ns[0]).astype(np.float64)
    x = np.interp(at, rel, mission.logged_xy[:, 0])
    y = np.interp(at, rel, mission.logged_xy[:, 1])
    yaw = np.interp(at, rel, np.unwrap(mission.logged_yaw_rad))
    return x, y, yaw


#: one logged track: stamps (ns), centres (x, y, map), headings (rad), (length, width) m — as
#: sequences or arrays ((K,), (K, 2), (K,))
TrackSamples = tuple[
    Sequence[int] | I64,
    Sequence[tuple[float, float]] | F64,
    Sequence[float] | F64,
    tuple[float, float],
]


def read_tracks(
    assembler: FrameAssembler, mission: Mission, *, stop_ns: int | None
) -> dict[int, TrackSamples]:
    """Every lane-class track of the log's ground truth, in the map frame: id → (stamps, xy,
    yaw, (length, width)), in the order the tracks first appear; each track's samples in stamp
    order (of two at one stamp the first read), its box the first sample's."""
    read = [
        # the columns of each message (its objects are rows of one batch: none is built)
        (stamp_ns, ObjectColumns.from_objects(objects))
        for stamp_ns, objects in assembler.ground_truth(stop_ns=stop_ns)
    ]
    if not read:
        return {}
    # every message's rows one after the other, the lane-class rows with a track id kept
    all_ids = np.concatenate([cols.object_id for _, cols in read])
    classes = itertools.chain.from_iterable(cols.object_class for _, cols in read)
    keep = np.fromiter(map(LANE_CLASSES.__contains__, classes), dtype=bool, count=all_ids.size)
    keep &= all_ids >= 0
    if not keep.any():
        return {}
    counts = [len(cols) for _, cols in read]
    ids = all_ids[keep].astype(np.int64)
    stamps = np.repeat(np.array([stamp for stamp, _ in read], dtype=np.int64), counts)[keep]
    xy_all = np.concatenate([cols.center_m[:, :2] for _, cols in read])[keep]
    yaw_all = np.concatenate([cols.yaw_rad for _, cols in read])[keep]
    size_all = np.concatenate([cols.size_m[:, :2] for _, cols in read])[keep]
    # by track, then stamp (stable: one stamp's samples as read), each stamp's first kept
    order = np.lexsort((stamps, ids))
    ids, stamps = ids[order], stamps[order]
    keep = np.ones(ids.size, dtype=bool)
    keep[1:] = (ids[1:] != ids[:-1]) | (stamps[1:] > stamps[:-1])
    order, ids, stamps = order[keep], ids[keep], stamps[keep]
    xy = xy_all[order]
    ex, ey, eyaw = _logged_pose_at(mission, stamps)
    c, s = np.cos(eyaw), np.sin(eyaw)
    mxy = np.stack([ex + c * xy[:, 0] - s * xy[:, 1], ey + s * xy[:, 0] + c * xy[:, 1]], axis=1)
    yaw = yaw_all[order] + eyaw
    size = size_all[order].tolist()
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    ends = np.r_[starts[1:], ids.size]
    # the tracks in the order they first appear in the log
    first_read = np.minimum.reduceat(order, starts)
    out: dict[int, TrackSamples] = {}
    for g in np.argsort(first_read, kind="stable").tolist():
        lo, hi = int(starts[g]), int(ends[g])
        out[int(ids[lo])] = (stamps[lo:hi], mxy[lo:hi], yaw[lo:hi], (size[lo][0], size[lo][1]))
    return out


def lane_tracks(
    tracks: Mapping[int, TrackSamples], index: RoadMapIndex
) -> tuple[dict[int, Track], F64, I64]:
    """Each logged track (:func:`read_tracks`) with its lane line on ``index``'s map, by id (a
    track that never moves is left out: it stays replayed), and every line packed
    (:func:`~redrive.maps.polylines.packed`; ``Track.line_number`` is its line's number)."""
    road = index.road_map
    controlled = {t.stop_line_id: t.light_id for t in road.traffic_lights if t.stop_line_id}
    samples = [
        (np.array(xy, dtype=np.float64), np.array(yaw, dtype=np.float64))
        for _, xy, yaw, _ in tracks.values()
    ]
    routes = routes_along_paths(index, samples, extend_m=_EXTEND_M)
    kept: list[tuple[int, tuple[str, ...], F64]] = []  # (position in tracks, lanes, line)
    for k, ((pts, _), route) in enumerate(zip(samples, routes, strict=True)):
        lanes, line_xy = route
        if line_xy.shape[0] < 2:
            lanes, line_xy = (), _dedup(pts)
        if line_xy.shape[0] >= 2:  # (a track that never moves stays replayed)
            kept.append((k, lanes, line_xy))
    lines = [line_xy for _, _, line_xy in kept]
    coords, offsets = packed(lines)
    if not kept:
        return {}, coords, offsets
    # the lines made, measured and bounded in one call each; shapely.line_locate_point of each
    # kept track's samples on its line in one compiled pass (the same doubles)
    geoms = shapely.linestrings(coords, indices=np.repeat(np.arange(len(lines)), np.diff(offsets)))
    bounds = shapely.bounds(geoms).tolist()
    line_lengths = shapely.length(geoms).tolist()
    kept_pts = [samples[k][0] for k, _, _ in kept]
    counts = [p.shape[0] for p in kept_pts]
    located, _ = polyline_locate(
        np.concatenate(kept_pts), np.repeat(np.arange(len(kept)), counts), coords, offsets
    )
    starts = np.cumsum([0, *counts]).tolist()
    entries = list(tracks.items())
    out: dict[int, Track] = {}
    for n, (k, lanes, _) in enumerate(kept):
        oid, (stamps, _, _, (length, width)) = entries[k]
        pts, yaws = samples[k]
        line = geoms[n]
        s_log = np.maximum.accumulate(located[starts[n] : starts[n + 1]])
        limit = [road.lane(i).speed_limit_mps for i in lanes]
        known = [v for v in limit if v]
        steps = np.hypot(*np.diff(pts, axis=0).T) if pts.shape[0] > 1 else np.zeros(0)
        dts = np.diff(np.array(stamps, dtype=np.int64)).astype(np.float64) / 1e9
        top = float(np.max(steps / dts)) if steps.size else 0.0
        desired = max(known) if known else max(top, 1.0)
        x0, y0, x1, y1 = bounds[n]
        out[oid] = Track(
            object_id=oid,
            stamps_ns=np.array(stamps, dtype=np.int64),
            xy=pts,
            yaw_rad=yaws,
            length_m=length,
            width_m=width,
            line=line,
            s_log=s_log,
            stops=_stops(road, lanes, line, controlled),
            desired_speed_mps=desired,
            lanes=lanes,
            line_length_m=line_lengths[n],
            bounds=(x0, y0, x1, y1),
            first_ns=int(stamps[0]),
            last_ns=int(stamps[-1]),
            line_number=n,
        )
    return out, coords, offsets


def _dedup(pts: F64) -> F64:
    if pts.shape[0] < 2:
        return pts
    keep = np.ones(pts.shape[0], dtype=bool)
    keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-3
    return pts[keep]


def on_line(track: Track, s_m: float) -> tuple[float, float, float]:
    """The point of the track's line at arclength ``s_m`` (clamped to the line) and the line's
    heading there (the chord from 0.5 m before it to 0.5 m after it)."""
    length = track.line_length_m
    s = min(max(s_m, 0.0), length)
    x, y = _interpolated(track, s)
    qx, qy = _interpolated(track, min(s + 0.5, length))
    ox, oy = _interpolated(track, max(s - 0.5, 0.0))
    return x, y, math.atan2(qy - oy, qx - ox)


def _interpolated(track: Track, s_m: float) -> tuple[float, float]:
    """``shapely.line_interpolate_point(track.line, s_m)`` for ``s_m`` ≥ 0, the same doubles:
    GEOS's ``LengthLocationMap::getLocationForward`` (the first segment whose end lies beyond
    ``s_m``, the fraction ``(s_m − its start) / its length``) and
    ``LinearLocation::pointAlongSegmentByFraction`` (``(p1 − p0) · fraction + p0``)."""
    if not track._line_x:  # the line's vertices and lengths, when first asked
        xy = shapely.get_coordinates(track.line)
        d = np.diff(xy, axis=0)
        # GEOS: each segment's length sqrt(dx² + dy²), added one after the other
        seg = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
        track._seg_m, track._seg_end_m = seg.tolist(), np.cumsum(seg).tolist()
        track._line_x, track._line_y = xy[:, 0].tolist(), xy[:, 1].tolist()
    xs, ys, ends = track._line_x, track._line_y, track._seg_end_m
    if s_m <= 0.0:
        return xs[0], ys[0]
    k = bisect.bisect_right(ends, s_m)
    if k == len(ends):
        return xs[-1], ys[-1]
    frac = (s_m - (ends[k - 1] if k else 0.0)) / track._seg_m[k]
    if frac <= 0.0:
        return xs[k], ys[k]
    if frac >= 1.0:
        return xs[k + 1], ys[k + 1]
    return (xs[k + 1] - xs[k]) * frac + xs[k], (ys[k + 1] - ys[k]) * frac + ys[k]


def _stops(
    road: RoadMap, lanes: tuple[str, ...], line: Any, controlled: Mapping[str, str]
) -> list[tuple[str, str | None, float]]:
    """The stop lines of ``lanes`` as (id, light id or None, arclength on ``line``), and the
    stop positions of the lights of ``lanes`` that have no stop line."""
    mine = set(lanes)
    out: list[tuple[str, str | None, float]] = []
    for stop in road.stop_lines:
        if not mine.intersection(stop.lane_ids):
            continue
        geom = shapely.LineString(stop.line) if stop.line.shape[0] >= 2 else None
        hit = shapely.intersection(line, geom) if geom is not None else None
        if hit is not None and not shapely.is_empty(hit):
            s = float(
                np.min(
                    shapely.line_locate_point(line, shapely.points(shapely.get_coordinates(hit)))
                )
            )
        else:
            s = float(shapely.line_locate_point(line, shapely.Point(*stop.line.mean(axis=0))))
        out.append((stop.stop_line_id, controlled.get(stop.stop_line_id), s))
    # a light without a stop line holds its lanes where they meet the junction (the reference
    # planner's gate, redrive.algorithms.reference._lights): the end of an approach lane, the
    # start of a lane in the intersection
    for light in road.traffic_lights:
        if light.stop_line_id is not None:
            continue
        for lane_id in mine.intersection(light.lane_ids):
            lane = road.lane(lane_id)
            point = lane.centerline[0] if lane.intersection_id is not None else lane.centerline[-1]
            s = float(shapely.line_locate_point(line, shapely.Point(*point)))
            out.append((f"light:{light.light_id}:{lane_id}", light.light_id, s))
    return out
