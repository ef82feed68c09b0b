"""A reference multi-object tracker: constant-velocity Kalman filters + Hungarian assignment."""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar, NoReturn

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from redrive.algorithms.base import Algorithm, Role, StageOutputs
from redrive.algorithms.reference._kalman import (
    initial_state,
    mahalanobis_sq_all,
    predict_all,
    update_all,
)
from redrive.errors import AlgorithmError, ConfigError
from redrive.geometry.se3 import normalize_angle
from redrive.types import DetectedObject, Frame, ObjectClass

__all__ = ["KalmanTracker"]

logger = logging.getLogger(__name__)

Array = npt.NDArray[np.float64]

#: cost of a detection–track pair outside the gate (never accepted).
_INFEASIBLE = 1e9
#: the frame tracks live in when the frame carries no ego state.
_BASE_LINK = "base_link"


@dataclass(slots=True)
class _Track:
    """A track's values besides its Kalman state (row ``i`` of the tracker's ``_x``, ``_p`` for
    ``_tracks[i]``)."""

    track_id: int
    z_m: float  # box-centre height in the tracking frame, smoothed
    size_m: Array  # (3,) l, w, h, smoothed
    yaw_rad: float  # heading in the tracking frame, from the last matched detection
    pitch_roll_rad: tuple[float, float]
    confidence: float
    votes: dict[ObjectClass, tuple[int, int]] = field(default_factory=dict)  # count, last hit
    hits: int = 1
    misses: int = 0  # consecutive frames without a match
    confirmed: bool = False

    def vote(self, cls: ObjectClass, when: int) -> None:
        count, _ = self.votes.get(cls, (0, when))
        self.votes[cls] = (count + 1, when)

    @property
    def object_class(self) -> ObjectClass:
        # most votes; a tie goes to the class seen most recently
        return max(self.votes.items(), key=lambda kv: kv[1])[0]


@dataclass(frozen=True, slots=True)
class _Pose2D:
    """``track_from_base`` as a planar pose: heading (rad) and translation (m)."""

    heading_rad: float
    xyz_m: Array

    @property
    def rotation(self) -> Array:
        c, s = math.cos(self.heading_rad), math.sin(self.heading_rad)
        return np.array([[c, -s], [s, c]])


class KalmanTracker(Algorithm):
    """Tracks the detections of an upstream perception algorithm: stable ids and velocities.

    Each track is a planar constant-velocity Kalman filter (state x, y, vx, vy; white
    acceleration noise ``accel_std_mps2``; position measurements with ``measurement_std_m``).
    Detections are assigned to predicted tracks by the Hungarian method
    (:func:`scipy.optimize.linear_sum_assignment`) on the squared Mahalanobis distance of the
    detection centre from the predicted position (innovation covariance ``HPHᵀ + R``).  The gate:
    a pair is admissible only when that distance² is ≤ ``gate_chi2`` (default 9.21, the 99 %
    point of χ² with 2 degrees of freedom) *and* the plain centre distance is ≤
    ``max_distance_m``.  Box height ``z``, and the size (l, w, h) are smoothed exponentially
    (``box_smoothing`` is the weight of the new detection); yaw, pitch and roll are carried
    from the last matched detection (no smoothing: detectors flip headings by π).  Class is the
    vote over all detections of the track (ties: the most recent).  Confidence is that of the
    last matched detection.

    Life cycle: an unmatched detection starts a tentative track; it is confirmed after
    ``min_hits`` matched frames (counting the first) and dropped at its first miss while
    tentative.  A confirmed track survives up to ``max_misses`` consecutive missed frames
    (predicted, output while ``output_coasting``) and keeps its id when matched again; after
    more misses it is deleted.  Only confirmed tracks are returned, sorted by id.  Ids count up
    from 1 and are never reused within a run.

    Frames and velocity convention: detections are read in ``base_link`` of the current frame.
    When ``frame.vehicle_state`` is present, tracking happens in its fixed frame (``map`` or
    ``odom``): each detection is moved there with the ego pose (position, ``heading_rad``; the
    ego reference point, the rear axle, is the base_link origin; pitch and roll are ignored).
    The outputs are then expressed back in base_link of the current frame and their
    ``velocity`` is the **over-ground** velocity rotated into base_link axes — the convention
    of the synthetic logs' ground truth (``redrive.sim.synth`` rotates world velocities with
    ``base_from_map``; the ego's own motion is not subtracted), so a parked car reads ~0 m/s
    from a moving ego.  Without a vehicle state, tracking happens in base_link itself and the
    velocities are *relative* to the ego (apparent motion in its moving, turning frame).  When
    the tracking frame changes between frames (ego state appears or disappears, or its frame
    id changes) all tracks are dropped, since positions cannot be compared.

    ``dt`` is the difference of ``frame.stamp_ns`` between successive calls (ns → s); a
    stamp earlier than the previous one raises :class:`AlgorithmError` (call :meth:`reset`
    between runs).  Deterministic: the same frames in the same order give the same outputs.

    Config:
        source: name of the upstream perception algorithm; None = the last one that ran.
        min_hits, max_misses: track confirmation and deletion (frames).
        gate_chi2, max_distance_m: the assignment gate (see above).
        measurement_std_m, accel_std_mps2, initial_velocity_std_mps: filter noise.
        box_smoothing: weight in (0, 1] of a new detection in the smoothed z and size.
        output_coasting: also return confirmed tracks not matched this frame.
    """

    role = Role.PERCEPTION
    inputs = ()  # reads frame.vehicle_state when present; the detections come from upstream
    upstream = Role.PERCEPTION
    version = "1"
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {
            "source": None,
            "min_hits": 3,
            "max_misses": 3,
            "gate_chi2": 9.21,
            "max_distance_m": 5.0,
            "measurement_std_m": 0.3,
            "accel_std_mps2": 2.0,
            "initial_velocity_std_mps": 10.0,
            "box_smoothing": 0.3,
            "output_coasting": True,
        }
    )

    def __init__(self, *, name: str | None = None) -> None:
        super().__init__(name=name)
        self._tracks: list[_Track] = []
        self._x: Array = _NO_X
        self._p: Array = _NO_P
        self._next_id = 1
        self._last_stamp_ns: int | None = None
        self._frame_id: str | None = None
        self.setup(self.config)

    # -- configuration ------------------------------------------------------------------------

    def setup(self, config: Mapping[str, Any]) -> None:
        source = config["source"]
        if source is not None and not isinstance(source, str):
            self._bad("source", source, "a perception algorithm's name or None")
        self._source: str | None = source
        self._min_hits = self._int(config, "min_hits", minimum=1)
        self._max_misses = self._int(config, "max_misses", minimum=0)
        self._gate_chi2 = self._positive(config, "gate_chi2")
        self._max_distance_m = self._positive(config, "max_distance_m")
        self._meas_std_m = self._positive(config, "measurement_std_m")
        self._accel_std = self._positive(config, "accel_std_mps2")
        self._vel0_std = self._positive(config, "initial_velocity_std_mps")
        self._alpha = self._positive(config, "box_smoothing")
        if self._alpha > 1.0:
            self._bad("box_smoothing", self._alpha, "a weight in (0, 1]")
        self._coasting = bool(config["output_coasting"])
        self.reset()

    def _bad(self, key: str, value: object, wanted: str) -> NoReturn:
        msg = f"algorithm {self.name!r}: config {key} = {value!r}; expected {wanted}"
        raise ConfigError(msg)

    def _int(self, config: Mapping[str, Any], key: str, *, minimum: int) -> int:
        value = config[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            self._bad(key, value, f"an integer ≥ {minimum}")
        return int(value)

    def _positive(self, config: Mapping[str, Any], key: str) -> float:
        value = config[key]
        if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
            self._bad(key, value, "a number > 0")
        return float(value)

    def reset(self) -> None:
        """Forget every track and restart ids at 1."""
        self._drop_tracks()
        self._next_id = 1
        self._last_stamp_ns = None
        self._frame_id = None

    # -- one frame ----------------------------------------------------------------------------

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        detections = upstream.objects(self._source)
        if detections is None:
            which = f"algorithm {self._source!r}" if self._source else "any perception algorithm"
            msg = (
                f"{self.name}: frame {frame.index} (stamp {frame.stamp_ns} ns) has no output of "
                f"{which} to track (its step failed or it did not run); put a detector before "
                "the tracker in the pipeline or set its 'source'"
            )
            raise AlgorithmError(msg)
        dt_s = self._advance_clock(frame)
        pose = self._pose(frame)
        centers, yaws = self._to_tracking_frame(detections, pose)

        if self._tracks:
            self._x, self._p = predict_all(self._x, self._p, dt_s, accel_std_mps2=self._accel_std)
        matches, unmatched_tracks, unmatched_dets = self._associate(centers)

        if matches:
            ti = np.array([t for t, _ in matches], dtype=np.intp)
            di = np.array([d for _, d in matches], dtype=np.intp)
            self._x[ti], self._p[ti] = update_all(
                self._x[ti], self._p[ti], centers[di, :2], meas_std_m=self._meas_std_m
            )
        for t, d in matches:
            self._absorb(self._tracks[t], detections[d], centers[d], yaws[d], frame.index)
        for t in unmatched_tracks:
            self._tracks[t].misses += 1
        keep = [
            (t.confirmed and t.misses <= self._max_misses) or (not t.confirmed and t.misses == 0)
            for t in self._tracks
        ]
        if not all(keep):
            self._tracks = [t for t, k in zip(self._tracks, keep, strict=True) if k]
            self._x, self._p = self._x[keep], self._p[keep]
        if unmatched_dets:
            self._births(
                [detections[d] for d in unmatched_dets],
                centers[unmatched_dets],
                yaws[unmatched_dets],
                frame.index,
            )

        out = self._outputs(
            [
                i
                for i, t in enumerate(self._tracks)
                if t.confirmed and (t.misses == 0 or self._coasting)
            ],
            pose,
        )
        logger.debug(
            "%s frame %d: %d detections, %d tracks, %d returned",
            self.name,
            frame.index,
            len(detections),
            len(self._tracks),
            len(out),
        )
        return out

    def _advance_clock(self, frame: Frame) -> float:
        last = self._last_stamp_ns
        if last is not None and frame.stamp_ns < last:
            msg = (
                f"{self.name}: frame {frame.index} stamp {frame.stamp_ns} ns is earlier than the "
                f"previous frame's {last} ns; frames must come in time order (reset() between "
                "runs)"
            )
            raise AlgorithmError(msg)
        self._last_stamp_ns = frame.stamp_ns
        return 0.0 if last is None else (frame.stamp_ns - last) * 1e-9

    def _pose(self, frame: Frame) -> _Pose2D | None:
        """track_from_base, or None when tracking in base_link; drops tracks on a frame change."""
        state = frame.vehicle_state
        frame_id = _BASE_LINK if state is None else f"{state.frame_id}"
        if self._frame_id is not None and frame_id != self._frame_id:
            logger.warning(
                "%s frame %d: tracking frame changed from %s to %s; dropping %d tracks",
                self.name,
                frame.index,
                self._frame_id,
                frame_id,
                len(self._tracks),
            )
            self._drop_tracks()
        self._frame_id = frame_id
        if state is None:
            return None
        return _Pose2D(heading_rad=state.heading_rad, xyz_m=state.position.copy())

    @staticmethod
    def _to_tracking_frame(
        detections: tuple[DetectedObject, ...], pose: _Pose2D | None
    ) -> tuple[Array, Array]:
        """(M, 3) centres and (M,) yaws of the detections in the tracking frame."""
        centers = np.array([d.box.center for d in detections], dtype=np.float64).reshape(-1, 3)
        yaws = np.array([d.box.yaw_rad for d in detections], dtype=np.float64)
        if pose is not None:
            centers[:, :2] = centers[:, :2] @ pose.rotation.T
            centers += pose.xyz_m
            yaws = yaws + pose.heading_rad
        return centers, yaws

    def _associate(self, centers: Array) -> tuple[list[tuple[int, int]], list[int], list[int]]:
        n_t, n_d = len(self._tracks), len(centers)
        if n_t == 0 or n_d == 0:
            return [], list(range(n_t)), list(range(n_d))
        xy = np.ascontiguousarray(centers[:, :2])
        d2 = mahalanobis_sq_all(self._x, self._p, xy, meas_std_m=self._meas_std_m)
        d = xy[None, :, :] - self._x[:, None, :2]
        dist = np.hypot(d[:, :, 0], d[:, :, 1])
        cost = np.where((d2 <= self._gate_chi2) & (dist <= self._max_distance_m), d2, _INFEASIBLE)
        rows, cols = linear_sum_assignment(cost)
        matches = [
            (int(r), int(c)) for r, c in zip(rows, cols, strict=True) if cost[r, c] < _INFEASIBLE
        ]
        matched_t = {r for r, _ in matches}
        matched_d = {c for _, c in matches}
        return (
            matches,
            [i for i in range(n_t) if i not in matched_t],
            [j for j in range(n_d) if j not in matched_d],
        )

    def _absorb(
        self, track: _Track, det: DetectedObject, center: Array, yaw_rad: float, index: int
    ) -> None:
        a = self._alpha
        track.z_m = (1.0 - a) * track.z_m + a * float(center[2])
        track.size_m = (1.0 - a) * track.size_m + a * det.box.size
        track.yaw_rad = normalize_angle(float(yaw_rad))
        track.pitch_roll_rad = (float(det.orientation[1]), float(det.orientation[2]))
        track.confidence = det.confidence
        track.vote(det.object_class, index)
        track.hits += 1
        track.misses = 0
        if track.hits >= self._min_hits:
            track.confirmed = True

    def _births(self, dets: list[DetectedObject], centers: Array, yaws: Array, index: int) -> None:
        """New tentative tracks, one per detection (ids in their order)."""
        xs, ps = [], []
        for det, center, yaw_rad in zip(dets, centers, yaws, strict=True):
            kf = initial_state(
                center[:2], position_std_m=self._meas_std_m, velocity_std_mps=self._vel0_std
            )
            xs.append(kf.x)
            ps.append(kf.p)
            track = _Track(
                track_id=self._next_id,
                z_m=float(center[2]),
                size_m=det.box.size.astype(np.float64),
                yaw_rad=normalize_angle(float(yaw_rad)),
                pitch_roll_rad=(float(det.orientation[1]), float(det.orientation[2])),
                confidence=det.confidence,
                confirmed=self._min_hits <= 1,
            )
            track.vote(det.object_class, index)
            self._next_id += 1
            self._tracks.append(track)
        self._x = np.concatenate([self._x, np.array(xs)])
        self._p = np.concatenate([self._p, np.array(ps)])

    def _drop_tracks(self) -> None:
        self._tracks = []
        self._x, self._p = _NO_X, _NO_P

    def _outputs(self, which: list[int], pose: _Pose2D | None) -> list[DetectedObject]:
        """Tracks ``which`` as DetectedObjects in base_link of this frame."""
        if not which:
            return []
        tracks = [self._tracks[i] for i in which]
        xy, v_xy = to_base_link(self._x[which], pose)
        zs = [t.z_m for t in tracks]
        yaws = [t.yaw_rad for t in tracks]
        if pose is not None:
            dz = float(pose.xyz_m[2])
            zs = [z - dz for z in zs]
            yaws = [normalize_angle(yaw - pose.heading_rad) for yaw in yaws]
        return DetectedObject.many(
            object_id=[t.track_id for t in tracks],
            object_class=[t.object_class for t in tracks],
            confidence=[t.confidence for t in tracks],
            center_m=np.column_stack((xy, zs)),
            size_m=[t.size_m for t in tracks],
            yaw_rad=yaws,
            velocity_mps=np.column_stack((v_xy, np.zeros(len(tracks)))),
            orientation_rad=[(yaw, *t.pitch_roll_rad) for yaw, t in zip(yaws, tracks, strict=True)],
        )


def to_base_link(x: Array, pose: _Pose2D | None) -> tuple[Array, Array]:
    """Positions (T, 2) and velocities (T, 2) of stacked Kalman states ``x`` (T, 4) in base_link
    of the frame whose ``track_from_base`` is ``pose`` (as they are when ``pose`` is None);
    each row bit-equal to ``rotation.T @ (x[:2] - xyz[:2])`` and ``rotation.T @ x[2:]``."""
    xy, v_xy = x[:, :2].copy(), x[:, 2:].copy()
    if pose is None:
        return xy, v_xy
    rot_t = pose.rotation.T
    xy = (rot_t @ (xy - pose.xyz_m[:2])[:, :, None])[:, :, 0]
    v_xy = (rot_t @ v_xy[:, :, None])[:, :, 0]
    return xy, v_xy


_NO_X: Array = np.empty((0, 4))
_NO_P: Array = np.empty((0, 4, 4))
