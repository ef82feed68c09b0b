"""``--agents reactive`` on a recorded log with a road map: the logged vehicles drive along the
lane graph with IDM when something the log did not have holds them up, and hand back to their
logged track when nothing does.

Before the first frame every logged track of a vehicle (``vehicle``, ``truck``, ``motorcycle``
ground truth with a track id) is read whole (:meth:`FrameAssembler.ground_truth
<redrive.assembly.frames.FrameAssembler.ground_truth>`, moved into the map frame by the logged
ego pose at its stamp) and mapped onto the lane graph as the ego's route is
(:func:`redrive.maps.route.route_along_path`): its *lane line* is the centrelines of the lanes it
drives (its logged lane changes as blends), continued along successors past its last sample.
A track on no lane keeps its own logged path as its line.

Each track is in one of two modes:

- **log** — exactly where the log has it (the agent is *replayed*);
- **lane** — on its lane line at the arclength ``s`` IDM (Treiber et al. 2000, :mod:`redrive.motion`)
  moves it to, heading along the line, never ahead of its logged position projected on the line.

A track switches from *log* to *lane* when a leader the log did not have — the driven ego, or a
track in *lane* mode — is ahead of it on its lane line (within ``lane_half_width_m`` of it) closer
than IDM's desired gap ``s* = s0 + max(0, v·T + v·Δv / (2·√(a·b)))`` (bumper to bumper).  In
*lane* mode its leaders are every road user on its lane line ahead (the driven ego, the other
tracks where they are now) and the stop lines of its lanes: one a light controls while the light
shows red — or yellow while the agent can still stop at ``b`` (``v² / (2 b)`` within the gap) —
and a stop sign's until it has stood still within ``_STOP_SERVED_M`` of it once (a light without
a stop line holds its lanes where they meet the junction: an approach lane's end, an
intersection lane's start).  (The logged
tracks obey the logged lights by themselves: a track in *log* mode is the log.)  Its desired
speed is its lane's speed limit, else the highest speed of its logged track (at least 1 m/s).
It hands back to *log* once it has caught up with its logged position and nothing holds it
there (it then takes the logged pose: a lateral step of at most the lane line's distance from the
logged path, typically centimetres to a few decimetres).  Pedestrians, cyclists and objects
without a track id stay replayed; a track is shown only while the log has it.
"""

from __future__ import annotations

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
from redrive.motion import IdmParams, idm_acceleration
from redrive.types import LightState, Mission, ObjectClass, ObjectColumns, RoadMap

__all__ = ["LANE_CLASSES", "LaneAgents", "Track", "TrackSamples", "read_tracks"]

F64 = npt.NDArray[np.float64]
#: the ground-truth classes that drive along lanes
LANE_CLASSES = frozenset({ObjectClass.VEHICLE, ObjectClass.TRUCK, ObjectClass.MOTORCYCLE})
#: a stop sign is served once the agent stood (below this speed) within this distance of it
_STOP_SERVED_M = 3.0
_STOPPED_MPS = 0.2
#: the bounding boxes of the lane lines are grown by this much more than the half width (m)
_BOUNDS_MARGIN_M = 1e-6
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


#: one logged track: stamps (ns), centres (x, y, map), headings (rad), (length, width) m
TrackSamples = tuple[list[int], list[tuple[float, float]], list[float], tuple[float, float]]


def read_tracks(
    assembler: FrameAssembler, mission: Mission, *, stop_ns: int | None
) -> dict[int, TrackSamples]:
    """Every lane-class track of the log's ground truth, in the map frame: id → (stamps, xy,
    yaw, (length, width)), in the order the tracks first appear; each track's samples in stamp
    order (of two at one stamp the first read), its box the first sample's."""
    stamps_l, ids_l, xy_l, yaw_l, size_l = [], [], [], [], []
    for stamp_ns, objects in assembler.ground_truth(stop_ns=stop_ns):
        # the columns of the message (its objects are rows of one batch: none is built)
        cols = ObjectColumns.from_objects(objects)
        keep = np.array([c in LANE_CLASSES for c in cols.object_class], dtype=bool)
        keep &= cols.object_id >= 0
        if keep.any():
            stamps_l.append(np.full(int(keep.sum()), stamp_ns, dtype=np.int64))
            ids_l.append(cols.object_id[keep])
            xy_l.append(cols.center_m[keep, :2])
            yaw_l.append(cols.yaw_rad[keep])
            size_l.append(cols.size_m[keep, :2])
    if not ids_l:
        return {}
    ids = np.concatenate(ids_l).astype(np.int64)
    stamps = np.concatenate(stamps_l)
    # by track, then stamp (stable: one stamp's samples as read), each stamp's first kept
    order = np.lexsort((stamps, ids))
    ids, stamps = ids[order], stamps[order]
    keep = np.ones(ids.size, dtype=bool)
    keep[1:] = (ids[1:] != ids[:-1]) | (stamps[1:] > stamps[:-1])
    order, ids, stamps = order[keep], ids[keep], stamps[keep]
    xy = np.concatenate(xy_l)[order]
    ex, ey, eyaw = _logged_pose_at(mission, stamps)
    c, s = np.cos(eyaw), np.sin(eyaw)
    mx = (ex + c * xy[:, 0] - s * xy[:, 1]).tolist()
    my = (ey + s * xy[:, 0] + c * xy[:, 1]).tolist()
    yaw = (np.concatenate(yaw_l)[order] + eyaw).tolist()
    size = np.concatenate(size_l)[order].tolist()
    stamp_list = stamps.tolist()
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    ends = np.r_[starts[1:], ids.size]
    # the tracks in the order they first appear in the log
    first_read = np.minimum.reduceat(order, starts)
    out: dict[int, TrackSamples] = {}
    for g in np.argsort(first_read, kind="stable").tolist():
        lo, hi = int(starts[g]), int(ends[g])
        out[int(ids[lo])] = (
            stamp_list[lo:hi],
            list(zip(mx[lo:hi], my[lo:hi], strict=True)),
            yaw[lo:hi],
            (size[lo][0], size[lo][1]),
        )
    return out


class LaneAgents:
    """The logged vehicles of a log under IDM along the lane graph (see the module text).

    Args:
        tracks: the logged tracks, map frame (:func:`read_tracks`; :meth:`from_log`).
        index: the road map's index (its lane queries: the lanes of
            :data:`~redrive.maps.index.DRIVABLE_LANE_KINDS`).
        lane_half_width_m: a leader farther off an agent's lane line does not hold it up.
        params: IDM's parameters but the desired speed (per track).
    """

    def __init__(
        self,
        tracks: Mapping[int, TrackSamples],
        *,
        index: RoadMapIndex,
        lane_half_width_m: float = 1.75,
        params: IdmParams | None = None,
    ) -> None:
        self.index = index
        self.lane_half_width_m = float(lane_half_width_m)
        self.params = params or IdmParams()
        road = index.road_map
        controlled = {t.stop_line_id: t.light_id for t in road.traffic_lights if t.stop_line_id}
        self.tracks: dict[int, Track] = {}
        lines: list[F64] = []
        samples = [
            (np.array(xy, dtype=np.float64), np.array(yaw, dtype=np.float64))
            for _, xy, yaw, _ in tracks.values()
        ]
        routes = routes_along_paths(index, samples, extend_m=_EXTEND_M)
        for (oid, (stamps, _, _, (length, width))), (pts, yaws), route in zip(
            tracks.items(), samples, routes, strict=True
        ):
            lanes, line_xy = route
            if line_xy.shape[0] < 2:
                lanes, line_xy = (), _dedup(pts)
            if line_xy.shape[0] < 2:  # a track that never moves: stays replayed
                continue
            line = shapely.LineString(line_xy)
            x0, y0, x1, y1 = line.bounds
            # shapely.line_locate_point of each sample on the line (the same doubles)
            on_line, _ = polyline_locate(pts, np.zeros(pts.shape[0], np.int64), *packed([line_xy]))
            s_log = np.maximum.accumulate(on_line)
            limit = [road.lane(i).speed_limit_mps for i in lanes]
            known = [v for v in limit if v]
            steps = np.hypot(*np.diff(pts, axis=0).T) if pts.shape[0] > 1 else np.zeros(0)
            dts = np.diff(np.array(stamps, dtype=np.int64)).astype(np.float64) / 1e9
            top = float(np.max(steps / dts)) if steps.size else 0.0
            desired = max(known) if known else max(top, 1.0)
            self.tracks[oid] = Track(
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
                line_length_m=float(line.length),
                bounds=(float(x0), float(y0), float(x1), float(y1)),
                first_ns=int(stamps[0]),
                last_ns=int(stamps[-1]),
                line_number=len(lines),
            )
            lines.append(line_xy)
        #: every track's line, packed (the per-frame projections of :meth:`_hold_up`,
        #: :meth:`_leader`)
        self._coords, self._offsets = packed(lines)

    @classmethod
    def from_log(
        cls,
        assembler: FrameAssembler,
        *,
        mission: Mission,
        index: RoadMapIndex,
        lane_half_width_m: float = 1.75,
        stop_ns: int | None = None,
    ) -> LaneAgents:
        """The lane agents of a log's ground truth (read whole, :func:`read_tracks`)."""
        tracks = read_tracks(assembler, mission, stop_ns=stop_ns)
        return cls(tracks, index=index, lane_half_width_m=lane_half_width_m)

    # -- per frame ---------------------------------------------------------------------------

    def reset(self) -> None:
        for track in self.tracks.values():
            track.lane_mode = False
            track.served = set()

    def pose(self, object_id: int, stamp_ns: int) -> tuple[float, float, float, float] | None:
        """(x, y, yaw, speed) of a track in *lane* mode at ``stamp_ns``; None when it is
        replayed (or not a lane agent)."""
        track = self.tracks.get(object_id)
        if track is None or not track.lane_mode:
            return None
        x, y, yaw = _on_line(track, track.s_m)
        return x, y, yaw, track.speed_mps

    def poses(self) -> dict[int, tuple[float, float, float, float]]:
        """Object id → (x, y, yaw, speed) of every track in *lane* mode (:meth:`pose`)."""
        out: dict[int, tuple[float, float, float, float]] = {}
        for oid, track in self.tracks.items():
            if track.lane_mode:
                x, y, yaw = _on_line(track, track.s_m)
                out[oid] = (x, y, yaw, track.speed_mps)
        return out

    def lane_mode_count(self) -> int:
        return sum(1 for t in self.tracks.values() if t.lane_mode)

    def step(
        self,
        stamp_ns: int,
        *,
        dt_s: float,
        ego: tuple[float, float, float, float, float],
        lights: Mapping[str, LightState],
    ) -> None:
        """Advance every track present at ``stamp_ns`` by ``dt_s``; ``ego`` is the driven
        ego's (centre x, y, yaw, speed, length)."""
        live: list[Track] = []
        for track in self.tracks.values():
            if track.first_ns <= stamp_ns <= track.last_ns:
                live.append(track)
            else:
                track.lane_mode = False  # shown only while the log has it
        if not live:
            return
        # where everyone is now (before this step): the leaders' positions
        ex, ey, eyaw, ev, elen = ego
        driven = (-1, ex, ey, eyaw, ev, elen)
        unlogged = [driven, *(self._now(t, stamp_ns) for t in live if t.lane_mode)]
        self._hold_up(stamp_ns, [t for t in live if not t.lane_mode], unlogged)
        if not any(t.lane_mode for t in live):
            return  # everyone as logged (the common case: nothing more to compute)
        leaders_all = [driven, *(self._now(t, stamp_ns) for t in live)]
        for track in live:
            if not track.lane_mode:
                continue
            gap, lead_v = self._leader(track, track.s_m, leaders_all)
            stop = self._stop_gap(track, lights)
            if stop is not None and (gap is None or stop < gap):
                gap, lead_v = stop, 0.0
            params = IdmParams(
                desired_speed_mps=track.desired_speed_mps,
                time_headway_s=self.params.time_headway_s,
                min_gap_m=self.params.min_gap_m,
                max_accel_mps2=self.params.max_accel_mps2,
                comfort_decel_mps2=self.params.comfort_decel_mps2,
                delta=self.params.delta,
                max_decel_mps2=self.params.max_decel_mps2,
            )
            if gap is None:
                accel = idm_acceleration(params, track.speed_mps)
            else:
                accel = idm_acceleration(
                    params, track.speed_mps, gap_m=gap, leader_speed_mps=lead_v
                )
            accel = max(accel, -params.max_decel_mps2)
            track.speed_mps = max(0.0, track.speed_mps + accel * dt_s)
            track.s_m += track.speed_mps * dt_s
            self._serve_stop_signs(track)
            s_next = track.s_logged(stamp_ns + round(dt_s * 1e9))
            if track.s_m >= s_next - 1e-6:
                track.s_m = s_next
                held, _ = self._leader(track, s_next, unlogged)
                if held is None or held >= _desired_gap(self.params, track.speed_mps, 0.0):
                    track.lane_mode = False  # caught up, nothing holds it: the log again

    # -- helpers -----------------------------------------------------------------------------

    @staticmethod
    def _now(track: Track, stamp_ns: int) -> tuple[int, float, float, float, float, float]:
        """(id, x, y, yaw, speed, length) of a track where it is at ``stamp_ns``."""
        if track.lane_mode:
            x, y, yaw = _on_line(track, track.s_m)
            v = track.speed_mps
        else:
            x, y, yaw = track.logged_xy_yaw(stamp_ns)
            v = track.speed_logged(stamp_ns)
        return track.object_id, x, y, yaw, v, track.length_m

    def _hold_up(
        self,
        stamp_ns: int,
        replayed: Sequence[Track],
        unlogged: Sequence[tuple[int, float, float, float, float, float]],
    ) -> None:
        """Switch to *lane* mode each replayed track that a road user the log did not have
        (``unlogged``) is ahead of on its line, closer than IDM's desired gap: each such road
        user projected onto the lines of the replayed tracks it can be on — those whose bounding
        box, grown by ``lane_half_width_m``, holds it (a line farther than that cannot have it
        within the half width: the others are not looked at)."""
        if not replayed or not unlogged:
            return
        bounds = np.array([t.bounds for t in replayed])
        reach = self.lane_half_width_m + _BOUNDS_MARGIN_M
        lo_x, lo_y = bounds[:, 0] - reach, bounds[:, 1] - reach
        hi_x, hi_y = bounds[:, 2] + reach, bounds[:, 3] + reach
        s_log: dict[int, float] = {}
        best: dict[int, tuple[float, float]] = {}  # track index → (gap, leader speed on line)
        for oid, x, y, yaw, v, length in unlogged:
            near = np.flatnonzero((lo_x <= x) & (x <= hi_x) & (lo_y <= y) & (y <= hi_y))
            near_list = [k for k in near.tolist() if replayed[k].object_id != oid]
            if not near_list:
                continue
            s_arr, d_arr = polyline_locate(
                np.broadcast_to(np.array([x, y]), (len(near_list), 2)),
                [replayed[k].line_number for k in near_list],
                self._coords,
                self._offsets,
            )
            s, d = s_arr.tolist(), d_arr.tolist()
            for k, s_k, d_k in zip(near_list, s, d, strict=True):
                track = replayed[k]
                if k not in s_log:
                    s_log[k] = track.s_logged(stamp_ns)
                ahead = s_k - s_log[k]
                if not (ahead > 0.0 and d_k <= self.lane_half_width_m):
                    continue
                if not s_k < track.line_length_m - 1e-6:
                    continue
                gap = max(ahead - track.length_m / 2.0 - length / 2.0, 0.0)
                if gap < best.get(k, (math.inf, 0.0))[0]:
                    _, _, line_yaw = _on_line(track, s_k)
                    best[k] = (gap, v * math.cos(math.remainder(yaw - line_yaw, math.tau)))
        for k in sorted(best):
            track = replayed[k]
            gap, lead_v = best[k]
            v_log = track.speed_logged(stamp_ns)
            if gap < _desired_gap(self.params, v_log, v_log - lead_v):
                track.lane_mode, track.s_m, track.speed_mps = True, s_log[k], float(v_log)

    def _leader(
        self,
        track: Track,
        s_m: float,
        leaders: Sequence[tuple[int, float, float, float, float, float]],
    ) -> tuple[float | None, float]:
        """The bumper-to-bumper gap to the nearest road user ahead of ``s_m`` on the track's
        line (within the lane half width), and its speed along the line."""
        # a road user outside the line's bounding box grown by the half width is not on it
        x0, y0, x1, y1 = track.bounds
        r = self.lane_half_width_m + _BOUNDS_MARGIN_M
        cand = [
            ldr
            for ldr in leaders
            if ldr[0] != track.object_id
            and x0 - r <= ldr[1] <= x1 + r
            and y0 - r <= ldr[2] <= y1 + r
        ]
        if not cand:
            return None, 0.0
        s, d = polyline_locate(
            np.array([[c[1], c[2]] for c in cand]),
            np.full(len(cand), track.line_number, np.int64),
            self._coords,
            self._offsets,
        )
        best: tuple[float | None, float] = (None, 0.0)
        for k, (_, _, _, yaw, v, length) in enumerate(cand):
            ahead = float(s[k]) - s_m
            if ahead <= 0.0 or float(d[k]) > self.lane_half_width_m:
                continue
            if float(s[k]) >= track.line_length_m - 1e-6 and ahead > 0.0:
                continue  # projected onto the line's end: beyond it, not on it
            gap = ahead - track.length_m / 2.0 - length / 2.0
            if best[0] is None or gap < best[0]:
                _, _, line_yaw = _on_line(track, float(s[k]))
                best = (max(gap, 0.0), v * math.cos(math.remainder(yaw - line_yaw, math.tau)))
        return best

    def _stop_gap(self, track: Track, lights: Mapping[str, LightState]) -> float | None:
        front = track.s_m + track.length_m / 2.0
        best: float | None = None
        for stop_id, light_id, s_stop in track.stops:
            gap = s_stop - front
            if gap < -0.5:
                continue  # passed
            if light_id is None:
                if stop_id in track.served:
                    continue
            else:
                state = lights.get(light_id)
                if state is LightState.YELLOW:
                    if track.speed_mps**2 / (2.0 * self.params.comfort_decel_mps2) > gap:
                        continue
                elif state is not LightState.RED:
                    continue
            gap = max(gap, 0.0)
            if best is None or gap < best:
                best = gap
        return best

    def _serve_stop_signs(self, track: Track) -> None:
        if track.speed_mps > _STOPPED_MPS:
            return
        front = track.s_m + track.length_m / 2.0
        for stop_id, light_id, s_stop in track.stops:
            if light_id is None and -0.5 <= s_stop - front <= _STOP_SERVED_M:
                track.served.add(stop_id)


def _desired_gap(p: IdmParams, speed_mps: float, approach_mps: float) -> float:
    """IDM's desired gap s* (m) at ``speed_mps`` closing at ``approach_mps``."""
    v = max(speed_mps, 0.0)
    return p.min_gap_m + max(
        0.0,
        v * p.time_headway_s
        + v * approach_mps / (2.0 * math.sqrt(p.max_accel_mps2 * p.comfort_decel_mps2)),
    )


def _dedup(pts: F64) -> F64:
    if pts.shape[0] < 2:
        return pts
    keep = np.ones(pts.shape[0], dtype=bool)
    keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-3
    return pts[keep]


def _on_line(track: Track, s_m: float) -> tuple[float, float, float]:
    line = track.line
    s = min(max(s_m, 0.0), track.line_length_m)
    at = [s, min(s + 0.5, track.line_length_m), max(s - 0.5, 0.0)]
    (x, y), (qx, qy), (ox, oy) = shapely.get_coordinates(
        shapely.line_interpolate_point(line, at)
    ).tolist()
    return x, y, math.atan2(qy - oy, qx - ox)


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
