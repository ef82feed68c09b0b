"""What the simulated sensors see: one instant of the world, in the map frame.

The world (:mod:`redrive.sim.world`) produces a :class:`Scene` at any time; the sensors
(:mod:`redrive.sim.lidar`, :mod:`redrive.sim.camera`, …) render from it.  This module is the
contract between the two and knows nothing of either.

Geometry of the synthetic world:

* the ground is the plane z = 0 of the map frame; what lies on it (grass, road, lane markings,
  sidewalk, stop lines) is a top-down label raster, :class:`GroundMap`;
* everything that stands on the ground (agents, parked cars, buildings, walls, poles, traffic-light
  posts) is an oriented box, a row of :class:`~redrive.types.ObjectColumns` (with its
  :class:`ObjectLooks`), whose bottom face rests on z = 0 unless its centre says otherwise.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.types import LightState, ObjectColumns
from redrive.types._arrays import frozen_array

__all__ = ["GroundLabel", "GroundMap", "ObjectLooks", "Scene", "TrafficLightState"]


class GroundLabel(enum.IntEnum):
    """What the ground is made of at a cell of the :class:`GroundMap`."""

    GRASS = 0
    ROAD = 1
    LANE_MARKING = 2
    SIDEWALK = 3
    STOP_LINE = 4


@dataclass(frozen=True, slots=True, kw_only=True)
class GroundMap:
    """A top-down raster of the ground plane z = 0.

    Attributes:
        origin_xy: (2,) float64, metres: map coordinates of the *corner* of cell (row 0, col 0).
        resolution_m: edge length of one square cell.
        labels: (H, W) uint8 :class:`GroundLabel` codes; row i covers
            y ∈ [origin_y + i·res, origin_y + (i+1)·res), column j likewise x.  Outside the raster
            the ground is GRASS.
    """

    origin_xy: npt.NDArray[np.float64]
    resolution_m: float
    labels: npt.NDArray[np.uint8]

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "origin_xy",
            frozen_array(self.origin_xy, name="GroundMap.origin_xy", dtype=np.float64, shape=(2,)),
        )
        object.__setattr__(
            self,
            "labels",
            frozen_array(self.labels, name="GroundMap.labels", dtype=np.uint8, shape=(None, None)),
        )
        if not self.resolution_m > 0:
            msg = f"GroundMap.resolution_m must be > 0, got {self.resolution_m}"
            raise ValueError(msg)

    def label_at(self, xy: npt.ArrayLike) -> npt.NDArray[np.uint8]:
        """Labels at map points ``xy`` (..., 2); GRASS outside the raster."""
        pts = np.asarray(xy, dtype=np.float64)
        ij = np.floor((pts - self.origin_xy) / self.resolution_m).astype(np.int64)
        col, row = ij[..., 0], ij[..., 1]
        h, w = self.labels.shape
        inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
        out = np.full(pts.shape[:-1], GroundLabel.GRASS, dtype=np.uint8)
        out[inside] = self.labels[row[inside], col[inside]]
        return out


@dataclass(frozen=True, slots=True, kw_only=True)
class ObjectLooks:
    """What the sensors need of the N boxes of a scene besides their geometry (row i belongs to
    row i of the :class:`~redrive.types.ObjectColumns` it goes with; arrays share the first axis).

    Attributes:
        colors_rgb: (N, 3) uint8: RGB albedo the camera shades.
        reflectivity: (N,) float32 in [0, 1]: what the LiDAR intensity scales with.
        is_ground_truth: (N,) bool: whether the object is reported as ground truth (agents and
            parked vehicles are; buildings, walls and poles are scenery).
    """

    colors_rgb: npt.NDArray[np.uint8]
    reflectivity: npt.NDArray[np.float32]
    is_ground_truth: npt.NDArray[np.bool_]

    def __post_init__(self) -> None:
        n = len(self.is_ground_truth)
        specs: tuple[tuple[str, npt.DTypeLike, tuple[int, ...]], ...] = (
            ("colors_rgb", np.uint8, (n, 3)),
            ("reflectivity", np.float32, (n,)),
            ("is_ground_truth", np.bool_, (n,)),
        )
        for name, dtype, shape in specs:
            value = frozen_array(
                getattr(self, name), name=f"ObjectLooks.{name}", dtype=dtype, shape=shape
            )
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.is_ground_truth)

    def take(self, rows: npt.NDArray[np.intp | np.int64]) -> ObjectLooks:
        """The looks of these rows, in this order."""
        return ObjectLooks(
            colors_rgb=self.colors_rgb[rows],
            reflectivity=self.reflectivity[rows],
            is_ground_truth=self.is_ground_truth[rows],
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class TrafficLightState:
    """One signal head: its id, state, and where its lamp is (map frame, metres)."""

    light_id: int
    state: LightState
    position: tuple[float, float, float]


@dataclass(frozen=True, slots=True, kw_only=True)
class Scene:
    """The world at ``stamp_ns``: ground, boxes and traffic lights (map frame).

    ``objects`` are the N boxes standing in the world (map frame; ids unique and stable over
    time, sizes > 0; buildings, walls and poles are ``STATIC``), ``looks`` their colours,
    reflectivity and ground-truth flags.  ``map_from_base`` is the ego's pose (4×4 float64,
    rear-axle centre, REP-103 axes); the ego's own box is *not* among ``objects`` (sensors would
    hit their own car).
    """

    stamp_ns: int
    ground: GroundMap
    objects: ObjectColumns
    looks: ObjectLooks
    traffic_lights: tuple[TrafficLightState, ...]
    map_from_base: npt.NDArray[np.float64]

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "map_from_base",
            frozen_array(
                self.map_from_base, name="Scene.map_from_base", dtype=np.float64, shape=(4, 4)
            ),
        )
        n = len(self.objects)
        if len(self.looks) != n:
            msg = f"Scene: {len(self.looks)} looks for {n} objects"
            raise ValueError(msg)
        if len(np.unique(self.objects.object_id)) != n:
            msg = "Scene.objects.object_id must be unique"
            raise ValueError(msg)
        if np.any(self.objects.size_m <= 0):
            msg = "Scene.objects.size_m must be > 0"
            raise ValueError(msg)
