"""Simulated spinning (3D) and scanning (2D) LiDARs, ray cast against a :class:`Scene`.

One sweep starts at ``scene.stamp_ns`` and lasts ``1 / rate_hz``.  The head turns clockwise seen
from above (as Velodyne and Ouster units do), starting at ``start_azimuth_rad`` (the rear, by
default: drivers cut the sweep behind the car); a 2D scanner sweeps its sector counter-clockwise
from ``−fov/2`` to ``+fov/2`` like a ROS ``LaserScan``.  The sweep is split into azimuth slices;
each slice is cast from the sensor pose at its own time (``map_from_base_at``), translation
interpolated column by column, so a moving sensor skews the cloud exactly as a real one does.
Points are expressed in the sensor frame *at their firing time* — what raw drivers output.

The boxes stand still during the sweep (they are where ``scene`` puts them); the ground z = 0
is intersected analytically.

Per point: Gaussian range noise, dropout, intensity = 255 · reflectivity · cos(incidence)
(objects' ``reflectivity``; the ground's from its :class:`~redrive.sim.scene.GroundLabel`),
``ring`` (uint16, lowest beam 0) and ``t_offset_ns`` (uint32 from the sweep start).  The rays
in the map frame, their ground distance and the ones that may meet a box are worked out in one
compiled loop, Embree casts those, and the kept returns are chosen and assembled in two more
(:mod:`redrive.sim.lidar_kernels`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import numpy.typing as npt

from redrive.errors import SimulationError
from redrive.sim import lidar_kernels
from redrive.sim.lidar_presets import LidarPreset, lidar_preset
from redrive.sim.mesh import TRIANGLES_PER_BOX, BoxMesh
from redrive.sim.rig import SensorSpec
from redrive.sim.scene import GroundLabel, GroundMap, Scene
from redrive.sim.scratch import Scratch
from redrive.types import ObjectColumns, PointCloud, SensorType
from redrive.types._arrays import frozen_array

__all__ = ["GROUND_REFLECTIVITY", "LidarModel", "LidarScan", "PoseAt"]

#: Callable giving ``map_from_base`` (4×4) at a time in ns.
PoseAt = Callable[[int], npt.ArrayLike]

#: Reflectivity of the ground by label: paint bright, asphalt dark, grass in between.
GROUND_REFLECTIVITY: Mapping[GroundLabel, float] = MappingProxyType(
    {
        GroundLabel.GRASS: 0.35,
        GroundLabel.ROAD: 0.08,
        GroundLabel.LANE_MARKING: 0.85,
        GroundLabel.SIDEWALK: 0.25,
        GroundLabel.STOP_LINE: 0.85,
    }
)
_GROUND_LUT = np.zeros(256, dtype=np.float32)
for _label, _refl in GROUND_REFLECTIVITY.items():
    _GROUND_LUT[int(_label)] = _refl


def _ground_labels(
    ground: GroundMap, x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]
) -> npt.NDArray[np.uint8]:
    """:meth:`GroundMap.label_at` for points given as two 1-D arrays (no (N, 2) temporaries)."""
    inv = 1.0 / ground.resolution_m
    h, w = ground.labels.shape
    col = np.floor((x - ground.origin_xy[0]) * inv).astype(np.int64)
    row = np.floor((y - ground.origin_xy[1]) * inv).astype(np.int64)
    inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    flat = np.where(inside, row * w + col, 0)
    labels = np.take(ground.labels.reshape(-1), flat)
    out: npt.NDArray[np.uint8] = np.where(inside, labels, np.uint8(GroundLabel.GRASS))
    return out


@dataclass(frozen=True, slots=True, kw_only=True)
class LidarScan:
    """One simulated sweep.

    Attributes:
        stamp_ns: start of the sweep (``t_offset_ns`` counts from here).
        frame_id: the sensor frame the points are in.
        cloud: xyz float32 (N, 3) metres in the sensor frame at each point's firing time;
            channels ``intensity`` float32 (0–255), ``ring`` uint16, ``t_offset_ns`` uint32.
        object_ids: (N,) int64: the object each point hit, −1 for the ground.
        hits_per_object: object id → number of returns, for every object of the scene.
    """

    stamp_ns: int
    frame_id: str
    cloud: PointCloud
    object_ids: npt.NDArray[np.int64]
    hits_per_object: Mapping[int, int]

    def __post_init__(self) -> None:
        ids = frozen_array(
            self.object_ids, name="LidarScan.object_ids", dtype=np.int64, shape=(len(self.cloud),)
        )
        object.__setattr__(self, "object_ids", ids)


class LidarModel:
    """A LiDAR of a given :class:`LidarPreset` mounted on the ego.

    Args:
        preset: the scan pattern (or its name).
        base_from_sensor: 4×4 extrinsics (identity by default).
        rate_hz: sweeps per second (rotation rate; a 2D scanner's scan rate).
        range_std_m: 1-σ Gaussian range noise (default: the preset's accuracy).
        dropout: probability that a return is lost.
        num_slices: azimuth slices with their own pose (default: one per 20 columns, 4° for an
            HDL-32E; translation is interpolated per column within a slice).
        start_azimuth_rad: azimuth of the first column of a spinning unit.
        frame_id: frame id of the clouds.
    """

    def __init__(
        self,
        preset: LidarPreset | str,
        *,
        base_from_sensor: npt.ArrayLike | None = None,
        rate_hz: float = 10.0,
        range_std_m: float | None = None,
        dropout: float = 0.0,
        num_slices: int | None = None,
        start_azimuth_rad: float = math.pi,
        frame_id: str = "lidar",
    ) -> None:
        self.preset = lidar_preset(preset) if isinstance(preset, str) else preset
        p = self.preset
        if not rate_hz > 0:
            msg = f"LidarModel({p.name}): rate_hz must be > 0, got {rate_hz}"
            raise SimulationError(msg)
        if not 0.0 <= dropout <= 1.0:
            msg = f"LidarModel({p.name}): dropout must lie in [0, 1], got {dropout}"
            raise SimulationError(msg)
        self.base_from_sensor = (
            np.eye(4) if base_from_sensor is None else np.asarray(base_from_sensor, np.float64)
        )
        self.rate_hz = float(rate_hz)
        self.range_std_m = p.range_accuracy_m if range_std_m is None else float(range_std_m)
        self.dropout = float(dropout)
        self.frame_id = frame_id
        self.period_ns = round(1e9 / rate_hz)
        cols = p.columns
        step = math.radians(p.azimuth_resolution_deg)
        idx = np.arange(cols, dtype=np.float64)
        if p.fov_deg >= 360.0:
            azimuths = start_azimuth_rad - idx * step  # clockwise from above
            col_t = idx * (self.period_ns / cols)
        else:
            azimuths = math.radians(-p.fov_deg / 2.0) + idx * step  # counter-clockwise sector
            col_t = idx * (self.period_ns * math.radians(p.azimuth_resolution_deg) / (2 * math.pi))
        self.col_offset_ns = np.round(col_t).astype(np.int64)
        elev = p.elevations_rad()
        ce, se = np.cos(elev), np.sin(elev)
        ca, sa = np.cos(azimuths), np.sin(azimuths)
        dirs = np.empty((cols, p.num_lasers, 3), dtype=np.float64)
        dirs[..., 0] = ca[:, None] * ce[None, :]
        dirs[..., 1] = sa[:, None] * ce[None, :]
        dirs[..., 2] = se[None, :]
        self._cos_elev32 = ce.astype(np.float32)
        self._tan_elev = np.tan(elev)
        #: (C, L, 3) unit ray directions in the sensor frame, firing order.
        self.directions = dirs
        self.rings = p.rings()
        self.num_slices = max(1, min(cols, num_slices if num_slices else max(1, cols // 20)))
        span = col_t[-1] + (col_t[1] - col_t[0] if cols > 1 else 1.0)
        self._slice_of_col = np.minimum(
            (col_t / span * self.num_slices).astype(np.int64), self.num_slices - 1
        )
        self._slice_t = np.linspace(0.0, span, self.num_slices + 1)
        frac = (col_t - self._slice_t[self._slice_of_col]) / (span / self.num_slices)
        self._frac_of_col = frac
        self._slice_starts = np.flatnonzero(np.r_[True, np.diff(self._slice_of_col) != 0])
        # azimuth span of each slice, relative to the sensor's x axis
        first = azimuths[self._slice_starts]
        last = azimuths[np.r_[self._slice_starts[1:] - 1, cols - 1]]
        self._slice_mid_az = 0.5 * (first + last)
        self._slice_half_az = 0.5 * np.abs(last - first) + step
        flat32 = dirs.reshape(-1, 3).astype(np.float32)
        self._dirs_flat = tuple(np.ascontiguousarray(flat32[:, a]) for a in range(3))
        local32 = dirs.astype(np.float32)
        self._local_x = np.ascontiguousarray(local32[..., 0])
        self._local_y = np.ascontiguousarray(local32[..., 1])
        self._local_z = np.ascontiguousarray(local32[..., 2])
        self._no_reach = np.zeros(cols)  # the cull's per-column figures when every ray is cast
        self._scratch = Scratch()  # the sweep's work arrays, kept between sweeps
        self._ring_flat = np.tile(self.rings, cols)
        self._t_off_flat = np.repeat(self.col_offset_ns, p.num_lasers).astype(np.uint32)

    @classmethod
    def from_spec(cls, spec: SensorSpec, *, num_slices: int | None = None) -> LidarModel:
        """The model of a rig sensor of kind ``lidar`` or ``lidar_2d``."""
        if spec.kind not in (SensorType.LIDAR, SensorType.LIDAR_2D) or spec.preset is None:
            msg = f"sensor {spec.name!r} is a {spec.kind.value}, not a LiDAR"
            raise SimulationError(msg)
        return cls(
            spec.preset,
            base_from_sensor=spec.base_from_sensor(),
            rate_hz=spec.rate_hz,
            range_std_m=spec.noise.get("range_std_m"),
            dropout=spec.noise.get("dropout", 0.0),
            num_slices=num_slices,
            frame_id=spec.name,
        )

    def _sensor_poses(
        self, scene: Scene, map_from_base_at: PoseAt | None
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Per slice the rotation (S, 3, 3) map_from_sensor; per column the position (C, 3)."""
        cols, slices = self.preset.columns, self.num_slices
        if map_from_base_at is None:
            pose = scene.map_from_base @ self.base_from_sensor
            return (
                np.broadcast_to(pose[:3, :3], (slices, 3, 3)),
                np.broadcast_to(pose[:3, 3], (cols, 3)),
            )
        poses = np.empty((slices + 1, 4, 4))
        for b, t in enumerate(self._slice_t):
            mat = np.asarray(map_from_base_at(scene.stamp_ns + round(t)), dtype=np.float64)
            if mat.shape != (4, 4):
                msg = f"map_from_base_at returned shape {mat.shape}, expected (4, 4)"
                raise SimulationError(msg)
            poses[b] = mat @ self.base_from_sensor
        pos = np.empty((cols, 3))
        slice_pos = np.ascontiguousarray(poses[:, :3, 3])
        lidar_kernels.columns(slice_pos, self._slice_of_col, self._frac_of_col, pos)
        return poses[:slices, :3, :3], pos

    def _boxes_in_range(
        self, objects: ObjectColumns, pos: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.int64]:
        """Indices of the boxes a ray of the sweep may reach: the others are not meshed.

        A ray goes no farther than 1.01 × the maximum range, and no farther along the ground
        than along itself, so a box whose footprint's circumscribed circle lies horizontally
        beyond that from the sweep's first position, less how far the sensor moves within the
        sweep (and 5 cm), cannot be hit.  The kept boxes are meshed in the scene's order.
        """
        xy0 = pos[0, :2]
        travel = float(np.max(np.hypot(pos[:, 0] - xy0[0], pos[:, 1] - xy0[1]), initial=0.0))
        half_diag = 0.5 * np.hypot(objects.size_m[:, 0], objects.size_m[:, 1])
        rel = objects.center_m[:, :2] - xy0
        gap = np.hypot(rel[:, 0], rel[:, 1]) - half_diag
        reach_m = self.preset.max_range_m * 1.01 + travel + 0.05
        return np.flatnonzero(gap <= reach_m)

    def _box_reach(
        self,
        centers: npt.NDArray[np.float64],
        sizes: npt.NDArray[np.float64],
        rot: npt.NDArray[np.float64],
        pos: npt.NDArray[np.float64],
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float] | None:
        """Per column, how near a box may come and how high it may reach — a conservative cull.

        Per slice, each box's azimuth interval (the angle its footprint's circumscribed circle
        subtends) and nearest horizontal distance are computed from the slice's first origin,
        grown by a margin covering the sensor's travel within the slice.  A ray needs Embree
        only if some box overlaps its slice, is nearer than where the ray meets the ground, and
        (for upward rays) is not already below the ray where the ray reaches it
        (:func:`~redrive.sim.lidar_kernels.rays` applies it).  Returns ``(r_col, top_col,
        margin)``: (C,) float64 nearest horizontal distance of a box overlapping the column's
        slice (+inf: none) and (C,) float64 highest top among them.  Only for an upright sensor
        (a ray's azimuth is its column's); ``None`` means cast every ray.
        """
        if len(centers) == 0 or np.any(rot[:, 2, 2] < 1.0 - 1e-9):
            return None
        cols = self.preset.columns
        r_col, top_col = np.empty(cols), np.empty(cols)
        margin = lidar_kernels.reach(
            self._slice_starts,
            pos,
            rot,
            centers,
            sizes,
            self._slice_mid_az,
            self._slice_half_az,
            self._slice_of_col,
            r_col,
            top_col,
        )
        return r_col, top_col, margin

    def scan(
        self,
        scene: Scene,
        rng: np.random.Generator,
        *,
        map_from_base_at: PoseAt | None = None,
    ) -> LidarScan:
        """Cast one sweep starting at ``scene.stamp_ns``.

        Args:
            scene: the world; its boxes within reach of the sweep are meshed anew for it.
            rng: the only source of randomness (noise, dropout).
            map_from_base_at: ego pose at a time in ns (default: ``scene.map_from_base`` for
                the whole sweep).
        """
        p = self.preset
        rot, pos = self._sensor_poses(scene, map_from_base_at)
        rot = np.ascontiguousarray(rot)
        pos = np.ascontiguousarray(pos, dtype=np.float64)
        origin = pos[0].copy()
        near = self._boxes_in_range(scene.objects, pos)
        objs = scene.objects
        centers, sizes = objs.center_m[near], objs.size_m[near]
        mesh = BoxMesh.from_boxes(centers, sizes, objs.yaw_rad[near], origin=origin)
        n_rays = p.columns * p.num_lasers
        # ray directions in the map frame, where they meet the ground, which Embree casts
        work = self._scratch
        dx, dy, dz = (work.array(name, (n_rays,), np.float32) for name in ("dx", "dy", "dz"))
        t_ground = work.array("t_ground", (n_rays,), np.float32)
        limit = work.array("limit", (n_rays,), np.float32)
        sel_all = work.array("sel", (n_rays,), np.int64)
        sel_orig = work.array("sel_orig", (n_rays, 3), np.float32)
        sel_dirs = work.array("sel_dirs", (n_rays, 3), np.float32)
        sel_limit = work.array("sel_limit", (n_rays,), np.float32)
        reach = self._box_reach(centers, sizes, rot, pos)
        r_col, top_col, margin = (self._no_reach, self._no_reach, 0.0) if reach is None else reach
        n_sel = lidar_kernels.rays(
            self._slice_of_col,
            rot,
            self._local_x,
            self._local_y,
            self._local_z,
            pos,
            origin,
            bool(np.all(rot[:, 2, :] == (0.0, 0.0, 1.0))),  # upright: heights need no rotation
            np.float32(p.max_range_m * 1.01),
            reach is not None,
            self._cos_elev32,
            self._tan_elev,
            np.ascontiguousarray(r_col, dtype=np.float64),
            np.ascontiguousarray(top_col, dtype=np.float64),
            margin,
            dx,
            dy,
            dz,
            t_ground,
            limit,
            sel_all,
            sel_orig,
            sel_dirs,
            sel_limit,
        )
        sel = sel_all[:n_sel]
        sel_dist, sel_prim, normal_sel = mesh.cast(
            sel_orig[:n_sel], sel_dirs[:n_sel], sel_limit[:n_sel]
        )
        dist = limit  # each ray's limit, then Embree's distance where it hit a box
        box = work.array("box", (n_rays,), np.int64)
        where_in_sel = work.array("where_in_sel", (n_rays,), np.int64)  # place in ``sel``
        keep = work.array("keep", (n_rays,), np.bool_)
        lidar_kernels.kept(
            sel,
            sel_dist,
            sel_prim,
            TRIANGLES_PER_BOX,
            near,
            t_ground,
            np.float32(p.min_range_m),
            np.float32(p.max_range_m),
            dist,
            box,
            where_in_sel,
            keep,
        )
        if self.dropout > 0:
            keep &= rng.random(keep.size) >= self.dropout
        idx = np.flatnonzero(keep)
        r = dist[idx]
        if self.range_std_m > 0:
            r = r + rng.standard_normal(idx.size, dtype=np.float32) * np.float32(self.range_std_m)
        normals = np.ascontiguousarray(normal_sel, dtype=np.float32)
        xyz = np.empty((idx.size, 3), dtype=np.float32)
        intensity = np.empty(idx.size, dtype=np.float32)
        ring = np.empty(idx.size, dtype=np.uint16)
        t_off = np.empty(idx.size, dtype=np.uint32)
        point_ids = np.empty(idx.size, dtype=np.int64)
        ids_all = scene.objects.object_id
        counts = np.zeros(len(ids_all), dtype=np.int64)
        ground = scene.ground
        lidar_kernels.returns(
            idx,
            np.ascontiguousarray(r, dtype=np.float32),
            p.num_lasers,
            self._dirs_flat[0],
            self._dirs_flat[1],
            self._dirs_flat[2],
            box,
            dist,
            dx,
            dy,
            dz,
            where_in_sel,
            normals,
            scene.looks.reflectivity,
            ids_all,
            pos,
            ground.labels,
            ground.origin_xy,
            1.0 / ground.resolution_m,
            int(GroundLabel.GRASS),
            _GROUND_LUT,
            self._ring_flat,
            self._t_off_flat,
            xyz,
            intensity,
            ring,
            t_off,
            point_ids,
            counts,
        )
        hits = MappingProxyType({int(i): int(c) for i, c in zip(ids_all, counts, strict=True)})
        cloud = PointCloud(
            xyz=xyz, channels={"intensity": intensity, "ring": ring, "t_offset_ns": t_off}
        )
        return LidarScan(
            stamp_ns=scene.stamp_ns,
            frame_id=self.frame_id,
            cloud=cloud,
            object_ids=point_ids,
            hits_per_object=hits,
        )
