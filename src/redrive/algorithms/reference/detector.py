"""The reference LiDAR detector: ground removal, BEV clustering, L-shape boxes, size classes.

Pipeline (numpy/scipy over clusters; the passes over points and grid cells — crop, ground,
obstacle split, clustering — are numba kernels in :mod:`._kernels` that release the GIL, no
Python loop over points or clusters):

1. **Frame.**  Points are moved from the sensor frame to base_link by the translation
   ``SensorData.sensor_location`` (the data model has no mount rotation, so the sensor's axes are
   taken as parallel to base_link's).  Boxes come out in that frame, which is the frame ground
   truth uses: on synthetic logs ``sensor_location`` is the rig mount (``lidar_top`` at
   (1.2, 0, 1.9)) and ground truth is in base_link; on KITTI ``iter_frames`` gives
   ``sensor_location = (0, 0, 0)`` and the labels in the ``velodyne`` frame, so detections are in
   the velodyne frame too (the KITTI log's base_link *is* the velodyne frame).
2. **Crop.**  x, y within ±``range_m`` of base_link, beyond ``min_range_m`` of the sensor (the ego
   roof and body).
3. **Ground** (:mod:`._ground`).  Lowest z per ``ground_cell_m`` cell; ``"grid"`` takes the 3 × 3
   local minimum, falling back to a RANSAC plane where that is empty or more than
   ``ground_max_step_m`` above the plane; ``"plane"`` uses the plane alone.  A point is an obstacle
   point when ``ground_threshold_m`` < z - ground < ``max_height_m``.
4. **Clusters** (:mod:`._clusters`).  8-connected components of a ``cluster_tolerance_m`` BEV
   grid: Euclidean clustering in x-y with a tolerance between 1× and 2.83× that value (see
   there).  Clusters outside [``min_points``, ``max_points``] are dropped.
5. **Boxes** (:mod:`._box_fit`).  Search-based rectangle fit (Zhang et al. 2017) with the
   ``"closeness"`` criterion, or ``"area"`` (minimum-area rectangle), on at most
   ``fit_max_points`` points per cluster (an even subsample).  z spans ground → highest point.
6. **Classes** from the box size (``class_rules``, first match in order); clusters matching none
   are ``UNKNOWN``, except scenery, which is dropped: clusters with points in the
   ``tall_band_m`` above ``max_height_m`` (façades, trees, lamp posts; dropped before fitting),
   longer than ``max_length_m`` (walls, hedges), taller than ``drop_rules.max_height_m``
   (buildings whose top the LiDAR cannot see), thinner than ``pole_max_width_m`` and taller than
   ``pole_min_height_m`` (poles, posts, trunks), and thin (< ``wall_max_width_m``) tall
   (> ``wall_min_height_m``) boxes lying on one line with another such box (pieces of one wall).
7. **Completion** (``size_priors``).  A LiDAR sees an object's near faces only; a VEHICLE or
   TRUCK box seen from its end, or narrower than the prior, is grown away from the sensor to the
   class's prior size (:func:`._box_fit.complete_boxes`), so that its centre is the object's.
8. **Confidence** = ``(1 - exp(-n / 40)) × edge_fraction``, halved for ``UNKNOWN``: more points
   and points lying on the box outline (a solid object seen from outside) score higher.  It is a
   ranking score in [0, 1], not a calibrated probability.  ``object_id`` is -1 (a tracker assigns
   ids); velocity and acceleration are zero (one sweep cannot measure them); yaw is the direction
   of the long side in (-π/2, π/2] (the direction of travel cannot be seen in one sweep).

What it finds on the three real KITTI frames (``/work/shared/data/kitti_object``, asserted in
``tests/algorithms/test_detector.py``; labels cover only the camera's field of view, so the
~44 detections per sweep elsewhere — parked cars, walls, vegetation — cannot be scored there):

* 000000: the pedestrian at 8.7 m (376 points) — found, PEDESTRIAN.
* 000001: the truck at 69.7 m (70 points, rear face only) — found, TRUCK, centre 1.2 m off after
  completion to the 10 m prior (the truck is 12.3 m long); the car at 58.8 m (**9 points**, all
  0.3-0.6 m above the ground) — **missed** (below ``min_points``; with ``min_points = 3`` its
  nearest cluster is 1.7 m off); the cyclist at 46.1 m (18 points) — found, but as PEDESTRIAN
  (its seen extent is 0.7 m × 0.4 m).
* 000002: the car at 34.7 m — found, VEHICLE; the ``Misc`` trailer (class OTHER) is not scored.

Ground method, tried on those frames: ``"grid"`` keeps 1820 of the 1889 points in labelled boxes
as obstacle points and yields 133 detections; ``"plane"`` keeps 1802 and yields 157 (ground
leaking into obstacles far out), with the same four finds.  ``"grid"`` is the default.

Synthetic logs (``redrive.sim``, 2.5 s; objects with ≥ 50 LiDAR points within 40 m): urban
recall 74/75, 107 of 125 detections have ground truth within 2 m; cut_in (highway) recall
25/25, 26/33 — the rest are pieces of the highway's noise walls that look like a truck's flank.

Speed: on the demo log (``redrive synth urban --duration 20``, 200 sweeps of ~54k points) the
numba kernels brought a step from ≈ 8.5 to ≈ 4.8 ms of thread CPU, interleaved on the shared
build machine at load ≈ 22 (BENCHMARKS.md, "Open loop, 2026-11-26 07:45–08:35 (branch
h-openloop3)"); the outputs are bit for bit those of the former
numpy/scipy steps (``tests/algorithms/test_kernels.py`` keeps them as the reference).  What is
left is mostly the plane's least squares, building the ``DetectedObject`` values and the box
search's numpy parts.  The kernels compile once after an install and are cached on disk
(``__pycache__``); a process loads them when the detector is bound to a log (:meth:`bind` runs a
small made-up sweep), not in its first frame.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from redrive.algorithms.base import Algorithm, Input, Role, StageOutputs
from redrive.algorithms.reference._box_fit import collinear_walls, complete_boxes, fit_boxes
from redrive.algorithms.reference._clusters import Clusters, cluster_points
from redrive.algorithms.reference._ground import GroundGrid, ground_heights
from redrive.algorithms.reference._kernels import (
    crop_cell_minima,
    split_obstacles,
    subsample_clusters,
)
from redrive.errors import AlgorithmError, ConfigError
from redrive.types import DetectedObject, Frame, ObjectClass, PointCloud, SensorType

__all__ = ["ClusterDetector"]

logger = logging.getLogger(__name__)

_F32 = npt.NDArray[np.float32]

#: Size rules per class: [length min, max, width min, max, height min, max] in metres, where
#: length ≥ width are the fitted box's sides and height is ground → highest point.  Checked in
#: this order; the first match wins.  Observed sizes are often smaller than the object (one side
#: seen, sparse rings far away), hence the low minima.
_CLASS_RULES: Mapping[str, tuple[float, ...]] = MappingProxyType(
    {
        "pedestrian": (0.1, 1.3, 0.0, 1.1, 1.0, 2.2),
        "bicycle": (1.3, 2.3, 0.35, 0.9, 0.7, 2.1),
        "vehicle": (1.3, 6.2, 0.0, 2.6, 0.6, 2.6),
        "truck": (1.3, 18.0, 0.0, 3.2, 2.0, 4.0),
    }
)

_DROP_RULES: Mapping[str, float] = MappingProxyType(
    {
        "max_length_m": 20.0,
        "max_height_m": 4.1,
        "pole_max_width_m": 0.7,
        "pole_min_height_m": 2.4,
        "tall_band_m": 2.0,
        "wall_max_width_m": 0.4,
        "wall_min_height_m": 2.5,
    }
)

#: Prior [length, width] in metres that a partly seen box of the class is grown to (see
#: :func:`._box_fit.complete_boxes`).  Vehicle: a mid-size car; truck: 10 m, between a rigid
#: delivery truck (~8 m, the simulator's) and a long rigid truck (~12 m, KITTI 000001's).
_SIZE_PRIORS: Mapping[str, tuple[float, float]] = MappingProxyType(
    {"vehicle": (4.5, 1.8), "truck": (10.0, 2.5)}
)

_CLASS_NAMES: Mapping[str, ObjectClass] = MappingProxyType(
    {c.value: c for c in ObjectClass if c is not ObjectClass.UNKNOWN}
)


def _warm_up_sweep() -> _F32:
    """A small sweep that takes every step of :meth:`ClusterDetector.detect`: a flat ground
    1.8 m below the sensor and a car-sized box of points 10 m ahead (sensor frame), read-only."""
    g = np.arange(-20.0, 20.0, 0.5)
    gx, gy = np.meshgrid(g, g)
    ground = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, -1.8)], axis=1)
    b = np.arange(0.0, 1.0, 0.1)
    u, v = np.meshgrid(b, b)
    sides = [
        np.stack([8.0 + 4.0 * u.ravel(), np.full(u.size, y), -1.7 + 1.5 * v.ravel()], axis=1)
        for y in (-1.0, 1.0)
    ] + [
        np.stack([np.full(u.size, x), -1.0 + 2.0 * u.ravel(), -1.7 + 1.5 * v.ravel()], axis=1)
        for x in (8.0, 12.0)
    ]
    xyz = np.ascontiguousarray(np.concatenate([ground, *sides]), dtype=np.float32)
    xyz.flags.writeable = False  # as a decoded cloud's: numba compiles read-only arrays apart
    return xyz


def _rules_array(rules: Mapping[str, Any]) -> tuple[list[ObjectClass], npt.NDArray[np.float64]]:
    classes: list[ObjectClass] = []
    bounds: list[list[float]] = []
    for name, values in rules.items():
        cls = _CLASS_NAMES.get(str(name).lower())
        row = [float(v) for v in values] if isinstance(values, list | tuple) else []
        if cls is None or len(row) != 6:
            msg = (
                f"ClusterDetector config class_rules[{name!r}]: expected a class name "
                f"({', '.join(_CLASS_NAMES)}) → [l_min, l_max, w_min, w_max, h_min, h_max] in "
                f"metres, got {values!r}; fix the entry or drop it"
            )
            raise ConfigError(msg)
        classes.append(cls)
        bounds.append(row)
    return classes, np.asarray(bounds, dtype=np.float64).reshape(-1, 6)


class ClusterDetector(Algorithm):
    """LiDAR objects by ground removal, BEV Euclidean clustering, L-shape box fitting and size
    classes (VEHICLE, TRUCK, PEDESTRIAN, BICYCLE, UNKNOWN); boxes in base_link.

    Config (``defaults``): see the module docstring for the steps they control.

    * ``lidar_sensor`` (None): sensor id to use; None = the first LIDAR sensor of the log.
    * ``range_m`` (70.0): half side of the square crop around base_link, metres.
    * ``min_range_m`` (2.5): points closer than this to the sensor (x-y) are the ego; dropped.
    * ``ground_method`` ("grid"): ``"grid"`` or ``"plane"``.
    * ``ground_cell_m`` (1.0): ground grid cell, metres.
    * ``ground_max_step_m`` (0.5): grid ground more than this above the plane is not ground.
    * ``ground_threshold_m`` (0.25): points less than this above ground are ground.
    * ``max_height_m`` (5.0): points higher above ground are not clustered; those up to
      ``drop_rules.tall_band_m`` higher mark the cluster under them as scenery.
    * ``cluster_tolerance_m`` (0.3): BEV cell of the clustering grid, metres.
    * ``min_points`` (12), ``max_points`` (20000): cluster size limits, points.
    * ``box_criterion`` ("closeness"): ``"closeness"`` (L-shape) or ``"area"`` (min-area).
    * ``fit_max_points`` (96): points per cluster used by the box search.
    * ``class_rules``: class → [l_min, l_max, w_min, w_max, h_min, h_max], metres, first match.
    * ``drop_rules``: ``max_length_m`` 20, ``max_height_m`` 4.1, ``pole_max_width_m`` 0.7,
      ``pole_min_height_m`` 2.4, ``tall_band_m`` 2.0, ``wall_max_width_m`` 0.4,
      ``wall_min_height_m`` 2.5 (metres; see the module docstring).
    * ``size_priors``: class → [length, width] a partly seen box grows to; vehicle [4.5, 1.8],
      truck [10.0, 2.5].
    """

    role = Role.PERCEPTION
    inputs: ClassVar[tuple[Input, ...]] = (SensorType.LIDAR,)
    version = "1"
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {
            "lidar_sensor": None,
            "range_m": 70.0,
            "min_range_m": 2.5,
            "ground_method": "grid",
            "ground_cell_m": 1.0,
            "ground_max_step_m": 0.5,
            "ground_threshold_m": 0.25,
            "max_height_m": 5.0,
            "cluster_tolerance_m": 0.3,
            "min_points": 12,
            "max_points": 20000,
            "box_criterion": "closeness",
            "fit_max_points": 96,
            "class_rules": _CLASS_RULES,
            "drop_rules": _DROP_RULES,
            "size_priors": _SIZE_PRIORS,
        }
    )

    def __init__(self, *, name: str | None = None) -> None:
        super().__init__(name=name)
        self.setup(self.config)

    def setup(self, config: Mapping[str, Any]) -> None:
        if config["ground_method"] not in ("grid", "plane"):
            msg = f"ClusterDetector: ground_method must be 'grid' or 'plane', got {config['ground_method']!r}"
            raise ConfigError(msg)
        if config["box_criterion"] not in ("closeness", "area"):
            msg = f"ClusterDetector: box_criterion must be 'closeness' or 'area', got {config['box_criterion']!r}"
            raise ConfigError(msg)
        for key in ("range_m", "ground_cell_m", "cluster_tolerance_m"):
            if not float(config[key]) > 0:
                msg = f"ClusterDetector: {key} must be > 0 m, got {config[key]!r}"
                raise ConfigError(msg)
        drop = dict(_DROP_RULES)
        unknown = sorted(set(config["drop_rules"]) - set(drop))
        if unknown:
            msg = f"ClusterDetector: unknown drop_rules key(s) {unknown}; known: {sorted(drop)}"
            raise ConfigError(msg)
        drop.update({k: float(v) for k, v in config["drop_rules"].items()})
        self._drop = drop
        self._classes, self._bounds = _rules_array(config["class_rules"])
        priors = np.full((len(self._classes) + 1, 2), np.nan)  # last row: UNKNOWN, no prior
        for name, value in config["size_priors"].items():
            cls = _CLASS_NAMES.get(str(name).lower())
            pair = [float(v) for v in value] if isinstance(value, list | tuple) else []
            if cls is None or len(pair) != 2 or not all(v > 0 for v in pair):
                msg = (
                    f"ClusterDetector config size_priors[{name!r}]: expected a class name → "
                    f"[length_m, width_m] > 0, got {value!r}"
                )
                raise ConfigError(msg)
            for row, rule_cls in enumerate(self._classes):
                if rule_cls is cls:
                    priors[row] = pair
        self._priors = priors
        self._ground_grid = GroundGrid(
            half_extent_m=float(config["range_m"]), cell_m=float(config["ground_cell_m"])
        )

    def bind(self, sensors: Mapping[str, SensorType], *, extras: Iterable[str] = ()) -> None:
        """As :meth:`Algorithm.bind`, then one made-up sweep through :meth:`detect`, so that
        numba loads its kernels from the cache (or compiles them after an install) here, before
        a run's first frame, not inside that frame's latency (≈ 0.4–0.7 s once a process)."""
        super().bind(sensors, extras=extras)
        self.warm_kernels()

    def warm_kernels(self) -> None:
        """One made-up sweep through :meth:`detect` (configured, not bound, is enough): numba's
        kernels loaded in this process (also by :mod:`redrive.batch.preload` in the local
        executor's forkserver, so that its forked cells find them loaded)."""
        self.detect(_warm_up_sweep(), sensor_location=(0.0, 0.0, 1.8))

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        data = self.sensor(frame, SensorType.LIDAR)
        cloud = data.data
        if not isinstance(cloud, PointCloud):
            msg = (
                f"frame {frame.index}: sensor {data.sensor_id!r} carries "
                f"{type(cloud).__name__}, not a PointCloud; map a 3D LiDAR to it"
            )
            raise AlgorithmError(msg)
        return self.detect(cloud.xyz, sensor_location=data.sensor_location)

    def detect(
        self,
        xyz: _F32,
        *,
        sensor_location: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> list[DetectedObject]:
        """Objects in one sweep: ``xyz`` (N, 3) float32 metres in the sensor frame, the sensor at
        ``sensor_location`` (metres, base_link, axes parallel).  Boxes are in base_link."""
        cfg = self.config
        if xyz.shape[0] == 0:
            return []
        sx, sy, sz = (np.float32(v) for v in sensor_location)
        grid = self._ground_grid
        r0 = np.float32(cfg["min_range_m"])
        if xyz.dtype != np.float32 or xyz.flags.writeable:  # a cloud's own xyz is neither
            xyz = np.array(xyz, dtype=np.float32)  # (numba compiles a writable array as
            xyz.flags.writeable = False  # another type: one read-only float32 type to load)
        # a decoded xyz is a strided view of the message (row stride = its point_step): the
        # kernel reads it in place, one pass, where a packed copy cost as much as the kernel
        x, y, z, keys, minima = crop_cell_minima(
            xyz,
            sx,
            sy,
            sz,
            np.float32(grid.crop_m),
            r0 * r0,
            np.float32(grid.half_extent_m),
            np.float32(1.0 / grid.cell_m),
            grid.n,
        )
        if x.size == 0:
            return []
        ground = ground_heights(
            grid,
            minima,
            method=str(cfg["ground_method"]),
            max_step_m=float(cfg["ground_max_step_m"]),
            fallback_z_m=float(sz) - 1.8,
        ).ravel()
        max_h = np.float32(cfg["max_height_m"])
        ox, oy, oz, og, tall_x, tall_y = split_obstacles(
            x,
            y,
            z,
            keys,
            ground,
            np.float32(cfg["ground_threshold_m"]),
            max_h,
            max_h + np.float32(self._drop["tall_band_m"]),
        )
        clusters = cluster_points(
            ox,
            oy,
            half_extent_m=grid.half_extent_m,
            cell_m=float(cfg["cluster_tolerance_m"]),
            min_points=int(cfg["min_points"]),
            max_points=int(cfg["max_points"]),
            tall_xy=(tall_x, tall_y),
        )
        if clusters.starts.size == 0:
            return []
        return self._boxes((ox, oy, oz, og), clusters, sensor_xy=(float(sx), float(sy)))

    def _boxes(
        self,
        points: tuple[_F32, _F32, _F32, _F32],
        clusters: Clusters,
        *,
        sensor_xy: tuple[float, float],
    ) -> list[DetectedObject]:
        """Boxes, classes and scores of the clusters of obstacle points (x, y, z, ground z)."""
        ox, oy, oz, og = points
        index, starts, counts = clusters.index, clusters.starts, clusters.counts
        z_top = np.maximum.reduceat(oz[index], starts).astype(np.float64)
        z_ground = np.minimum.reduceat(og[index], starts).astype(np.float64)
        height = z_top - z_ground
        # An even subsample of at most fit_max_points per cluster for the box search.
        k = starts.size
        xy, sub_starts = subsample_clusters(
            ox, oy, index, starts, counts, int(self.config["fit_max_points"])
        )
        fit = fit_boxes(xy, sub_starts, criterion=str(self.config["box_criterion"]))

        length, width = fit.length_m, fit.width_m
        drop = self._drop
        scenery = (
            (length > drop["max_length_m"])
            | (height > drop["max_height_m"])
            | ((length < drop["pole_max_width_m"]) & (height > drop["pole_min_height_m"]))
        )
        thin_tall = (width < drop["wall_max_width_m"]) & (height > drop["wall_min_height_m"])
        scenery |= collinear_walls(fit.center_xy, fit.yaw_rad, thin_tall & ~scenery)
        b = self._bounds
        sizes = np.stack([length, width, height], axis=1)
        match = np.all(
            (sizes[:, None, :] >= b[None, :, 0::2]) & (sizes[:, None, :] <= b[None, :, 1::2]),
            axis=2,
        )  # (K, rules)
        has_class = match.any(axis=1)
        which = np.where(has_class, np.argmax(match, axis=1), len(self._classes))
        confidence = (1.0 - np.exp(-counts / 40.0)) * fit.edge_fraction
        confidence = np.where(has_class, confidence, 0.5 * confidence)
        center, length, width, yaw = complete_boxes(
            fit.center_xy,
            length,
            width,
            fit.yaw_rad,
            prior_length_m=self._priors[which, 0],
            prior_width_m=self._priors[which, 1],
            sensor_xy=sensor_xy,
        )
        classes = [*self._classes, ObjectClass.UNKNOWN]
        z_mid = 0.5 * (z_top + z_ground)
        keep = np.flatnonzero(~scenery)
        yaw_kept = yaw[keep]
        out = DetectedObject.many(
            object_class=[classes[w] for w in which[keep].tolist()],
            confidence=np.clip(confidence[keep], 0.0, 1.0),
            center_m=np.stack([center[keep, 0], center[keep, 1], z_mid[keep]], axis=1),
            size_m=np.stack([length[keep], width[keep], height[keep]], axis=1),
            yaw_rad=yaw_kept,
            orientation_rad=np.stack(
                [yaw_kept, np.zeros_like(yaw_kept), np.zeros_like(yaw_kept)], axis=1
            ),
        )
        logger.debug("ClusterDetector: %d clusters, %d objects", k, len(out))
        return out
