"""``--agents reactive`` on a recorded log with a road map: the logged vehicles drive along the
lane graph with IDM when something the log did not have holds them up, and hand back to their
logged track when nothing does.

Before the first frame every logged vehicle's track is read whole and mapped onto the lane graph
(:mod:`redrive.closedloop.lane_tracks`): its *lane line* is the centrelines of the lanes it drives,
continued along successors past its last sample (its logged path when it is on no lane).

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

import numpy as np
import numpy.typing as npt

from redrive.assembly.frames import FrameAssembler
from redrive.closedloop.lane_tracks import (
    LANE_CLASSES,
    Track,
    TrackSamples,
    lane_tracks,
    on_line,
    read_tracks,
)
from redrive.maps.index import RoadMapIndex
from redrive.maps.polylines import polyline_locate
from redrive.motion import IdmParams, idm_acceleration
from redrive.types import LightState, Mission

__all__ = ["LANE_CLASSES", "LaneAgents", "Track", "TrackSamples", "read_tracks"]

F64 = npt.NDArray[np.float64]
#: a stop sign is served once the agent stood (below this speed) within this distance of it
_STOP_SERVED_M = 3.0
_STOPPED_MPS = 0.2
#: the bounding boxes of the lane lines are grown by this much more than the half width (m)
_BOUNDS_MARGIN_M = 1e-6


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
        self.tracks: dict[int, Track]
        #: every track's line, packed (the per-frame projections of :meth:`_hold_up`,
        #: :meth:`_leader`)
        self._coords: F64
        self._offsets: npt.NDArray[np.int64]
        self.tracks, self._coords, self._offsets = lane_tracks(tracks, index)
        #: each line's bounding box grown by the half width (x0, y0, x1, y1; by line number):
        #: a road user outside it is not on the line (:meth:`_hold_up`)
        reach = self.lane_half_width_m + _BOUNDS_MARGIN_M
        bounds = np.zeros((len(self.tracks), 4))
        for t in self.tracks.values():
            bounds[t.line_number] = t.bounds
        self._reach_bounds = bounds + np.array([-reach, -reach, reach, reach])

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
        x, y, yaw = on_line(track, track.s_m)
        return x, y, yaw, track.speed_mps

    def poses(self) -> dict[int, tuple[float, float, float, float]]:
        """Object id → (x, y, yaw, speed) of every track in *lane* mode (:meth:`pose`)."""
        out: dict[int, tuple[float, float, float, float]] = {}
        for oid, track in self.tracks.items():
            if track.lane_mode:
                x, y, yaw = on_line(track, track.s_m)
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
            x, y, yaw = on_line(track, track.s_m)
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
        grown = self._reach_bounds[[t.line_number for t in replayed]]
        lo_x, lo_y, hi_x, hi_y = grown[:, 0], grown[:, 1], grown[:, 2], grown[:, 3]
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
                    _, _, line_yaw = on_line(track, s_k)
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
                _, _, line_yaw = on_line(track, float(s[k]))
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
