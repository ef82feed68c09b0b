"""``redrive new-algorithm NAME --role perception``: a LiDAR grid-cluster detector and its tests."""

from __future__ import annotations

__all__ = ["ALGORITHM", "TEST"]

ALGORITHM = '''\
"""$cls: a perception algorithm for redrive (written by `redrive new-algorithm`).

A LiDAR baseline to start from: the points of one LiDAR are moved into base_link, the ground
plane is fitted with RANSAC (base_link's origin may sit anywhere above the road: at the rear
axle on the ground, or at the LiDAR as on KITTI, 1.7 m up), the points near it are cut away, the
rest is binned into a coarse grid in the x-y plane, and each connected group of occupied cells
that is not too tall or too long becomes one box standing on the fitted ground.
Replace ``step`` with your detector; keep its signature and its output type.

    python -m pytest test_$module.py                          its tests
    redrive algorithms $module.py:$cls                  what redrive sees
    redrive run LOG --perception $module.py:$cls        run it on a log
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt
from redrive.algorithms import Algorithm, Role, StageOutputs
from redrive.errors import AlgorithmError, ConfigError
from redrive.types import (
    Box3D,
    DetectedObject,
    Frame,
    ObjectClass,
    PointCloud,
    SensorType,
)
from scipy import ndimage

#: 8-connectivity: diagonal neighbour cells belong to the same object.
_NEIGHBOURS = np.ones((3, 3), dtype=bool)


class $cls(Algorithm):
    """Boxes around clusters of above-ground LiDAR points (a grid baseline to build on).

    Input: one LiDAR (``SensorType.LIDAR``; the first of the log unless the config key
    ``lidar_sensor`` names one).  Output: a list of :class:`DetectedObject` with boxes in
    base_link (x forward, y left, z up, metres), axis aligned (yaw 0), standing on the ground
    plane fitted to the sweep, without ids (-1: a tracker assigns them).

    Assumes the LiDAR's axes are parallel to base_link, as for a roof-mounted sensor: its points
    are moved by ``sensor_location`` only.  Configuration (metres unless said otherwise):

    ================  =======  ==============================================================
    key               default  meaning
    ================  =======  ==============================================================
    lidar_sensor      None     sensor id of the LiDAR to use; None: the first one
    min_height_m      0.3      points lower than this above the ground plane are ground
    ground_tolerance  0.15     RANSAC: points this close to a candidate plane support it (m)
    ground_tries      60       RANSAC: candidate planes per sweep (seeded: runs repeat)
    ground_max_tilt   10.0     RANSAC: planes tilted more than this (degrees) are not ground
    max_height_m      4.0      clusters reaching higher are poles, trees or buildings
    ceiling_m         6.0      points higher than this (bridges, overhead signs) are ignored
    min_range_m       3.0      nearer points (horizontal, from the LiDAR) hit the ego itself
    max_range_m       40.0     farther points are ignored
    cell_m            0.7      grid cell size; cells that touch form one object
    min_points        5        clusters with fewer points are noise
    max_length_m      15.0     clusters longer than this are walls or buildings, not objects
    ================  =======  ==============================================================
    """

    role = Role.PERCEPTION
    inputs = (SensorType.LIDAR,)
    version = "0.1"
    defaults = MappingProxyType(
        {
            "lidar_sensor": None,
            "min_height_m": 0.3,
            "ground_tolerance": 0.15,
            "ground_tries": 60,
            "ground_max_tilt": 10.0,
            "max_height_m": 4.0,
            "ceiling_m": 6.0,
            "min_range_m": 3.0,
            "max_range_m": 40.0,
            "cell_m": 0.7,
            "min_points": 5,
            "max_length_m": 15.0,
        }
    )

    def setup(self, config: Mapping[str, Any]) -> None:
        """Check the configuration once per run (``config`` = defaults + the run's values)."""
        if not 0.0 < float(config["cell_m"]) <= float(config["max_range_m"]):
            msg = f"{self.name}: cell_m must lie in (0, max_range_m], got {config['cell_m']}"
            raise ConfigError(msg)
        if (
            not float(config["min_height_m"])
            < float(config["max_height_m"])
            <= float(config["ceiling_m"])
        ):
            msg = f"{self.name}: need min_height_m < max_height_m <= ceiling_m"
            raise ConfigError(msg)

    def reset(self) -> None:
        """Forget all state between runs (this detector keeps none)."""

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        """The objects in this frame's LiDAR sweep, boxes in base_link."""
        lidar = self.sensor(frame, SensorType.LIDAR)
        if not isinstance(lidar.data, PointCloud):
            msg = f"{self.name}: {lidar.sensor_id} carries {type(lidar.data).__name__}"
            raise AlgorithmError(msg)
        cfg = self.config
        # points in base_link, metres (float64 for the arithmetic below)
        xyz = lidar.data.xyz.astype(np.float64) + np.asarray(lidar.sensor_location)
        sensor_xy = np.asarray(lidar.sensor_location[:2])
        range_m = np.hypot(xyz[:, 0] - sensor_xy[0], xyz[:, 1] - sensor_xy[1])
        in_range = (range_m >= cfg["min_range_m"]) & (range_m < cfg["max_range_m"])
        plane = self._ground_plane(xyz[in_range])
        # height above the fitted ground: z - (a x + b y + c)
        height = xyz[:, 2] - (plane[0] * xyz[:, 0] + plane[1] * xyz[:, 1] + plane[2])
        keep = in_range & (height >= cfg["min_height_m"]) & (height <= cfg["ceiling_m"])
        points = np.column_stack([xyz[keep, :2], height[keep]])  # x, y, height above ground
        if len(points) == 0:
            return []
        labels = self._cluster(points[:, :2] - sensor_xy)
        objects = []
        order = np.argsort(labels, kind="stable")
        starts = np.flatnonzero(np.diff(labels[order], prepend=-1))
        for members in np.split(order, starts[1:]):
            found = self._object(points[members], plane)
            if found is not None:
                objects.append(found)
        return objects

    def _ground_plane(self, xyz: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """(a, b, c) of the ground z = a x + b y + c, base_link metres: the RANSAC plane, no
        steeper than ``ground_max_tilt``, that the most points lie within ``ground_tolerance``
        of, refined by least squares on them.  The flat z = 0 when the sweep has too few
        points."""
        flat = np.zeros(3)
        if len(xyz) < 3:
            return flat
        tolerance = float(self.config["ground_tolerance"])
        min_nz = np.cos(np.radians(float(self.config["ground_max_tilt"])))
        rng = np.random.default_rng(0)  # the same planes for the same sweep: runs repeat
        # candidates from the lower half of the sweep: the road is below what stands on it
        low = xyz[xyz[:, 2] <= np.median(xyz[:, 2])]
        tries = int(self.config["ground_tries"])
        triples = low[rng.integers(0, len(low), size=(tries, 3))]
        normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
        lengths = np.linalg.norm(normals, axis=1)
        ok = lengths > 1e-9
        normals = normals[ok] / lengths[ok, None]
        normals *= np.sign(normals[:, 2:3] + 1e-12)  # pointing up
        level = normals[:, 2] >= min_nz
        if not level.any():
            return flat
        normals, origins = normals[level], triples[ok][level, 0]
        # each candidate's support, counted on at most 4,000 of the points (enough to rank)
        sample = xyz[rng.permutation(len(xyz))[:4000]]
        offsets = np.einsum("kj,kj->k", normals, origins)  # the plane: n · p = offset
        support = np.abs(sample @ normals.T - offsets) < tolerance  # (points, candidates)
        k = int(np.argmax(support.sum(axis=0)))
        best = np.abs(xyz @ normals[k] - offsets[k]) < tolerance
        if best.sum() < 3:
            return flat
        ground = xyz[best]
        design = np.column_stack([ground[:, 0], ground[:, 1], np.ones(len(ground))])
        fitted: npt.NDArray[np.float64] = np.linalg.lstsq(design, ground[:, 2], rcond=None)[0]
        return fitted

    def _cluster(self, xy: npt.NDArray[np.float64]) -> npt.NDArray[np.intp]:
        """A cluster label per point: connected occupied cells of a grid centred on the LiDAR."""
        cell_m = float(self.config["cell_m"])
        half = float(self.config["max_range_m"])
        size = int(np.ceil(2.0 * half / cell_m))
        ij = np.clip(np.floor((xy + half) / cell_m).astype(np.intp), 0, size - 1)
        grid = np.zeros((size, size), dtype=bool)
        grid[ij[:, 0], ij[:, 1]] = True
        cells, _ = ndimage.label(grid, structure=_NEIGHBOURS)
        labels: npt.NDArray[np.intp] = cells[ij[:, 0], ij[:, 1]].astype(np.intp)
        return labels

    def _object(
        self, points: npt.NDArray[np.float64], plane: npt.NDArray[np.float64]
    ) -> DetectedObject | None:
        """One box around a cluster's points (x, y in base_link and height above the ground
        ``plane``, metres), or None for noise and walls."""
        if len(points) < int(self.config["min_points"]):
            return None
        lo, hi = points.min(axis=0), points.max(axis=0)
        length_m, width_m = float(hi[0] - lo[0]), float(hi[1] - lo[1])
        height_m = float(hi[2])  # the box stands on the ground
        too_long = max(length_m, width_m) > float(self.config["max_length_m"])
        if too_long or height_m > float(self.config["max_height_m"]):
            return None
        x_m, y_m = (lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0
        ground_z = plane[0] * x_m + plane[1] * y_m + plane[2]
        center = np.array([x_m, y_m, ground_z + height_m / 2.0])
        object_class = _classify(length_m, width_m, height_m)
        if object_class is None:
            return None
        return DetectedObject(
            object_id=-1,
            object_class=object_class,
            confidence=min(1.0, len(points) / 50.0),  # TODO: a real score
            box=Box3D(center=center, size=np.array([length_m, width_m, height_m]), yaw_rad=0.0),
        )


def _classify(length_m: float, width_m: float, height_m: float) -> ObjectClass | None:
    """A class from the box size alone, None for a pole (a crude rule; use a classifier)."""
    footprint_m = max(length_m, width_m)
    if footprint_m <= 1.2 and height_m > 2.3:
        return None  # thin and taller than a person: a pole, a sign post, a tree trunk
    if footprint_m <= 1.2 and height_m >= 1.0:
        return ObjectClass.PEDESTRIAN
    if footprint_m > 7.0:
        return ObjectClass.TRUCK
    if footprint_m >= 2.5:
        return ObjectClass.VEHICLE
    return ObjectClass.UNKNOWN
'''

TEST = '''\
"""Tests of $cls on hand-built frames (run: python -m pytest test_$module.py)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from redrive.algorithms import StageOutputs, StepStatus
from redrive.types import (
    DetectedObject,
    Frame,
    ObjectClass,
    PointCloud,
    SensorData,
    SensorType,
)

# the module under test, apart from the libraries above
# isort: split
from $module import $cls

LIDAR_HEIGHT_M = 1.9  # the LiDAR sits 1.9 m above the ground, over the rear axle


def _frame(xyz_base: npt.NDArray[np.float64]) -> Frame:
    """A frame with one LiDAR sweep; ``xyz_base`` are points in base_link (metres)."""
    in_sensor = (xyz_base - [0.0, 0.0, LIDAR_HEIGHT_M]).astype(np.float32)
    lidar = SensorData(
        sensor_id="lidar_top",
        sensor_type=SensorType.LIDAR,
        stamp_ns=1_000_000_000,
        frame_id="lidar_top",
        sensor_location=(0.0, 0.0, LIDAR_HEIGHT_M),
        data=PointCloud(xyz=in_sensor),
    )
    return Frame(stamp_ns=1_000_000_000, index=0, sensors={"lidar_top": lidar})


def _ground() -> npt.NDArray[np.float64]:
    """Flat ground (z = 0) around the ego, a point every 0.5 m."""
    xs, ys = np.meshgrid(np.arange(-30.0, 30.0, 0.5), np.arange(-30.0, 30.0, 0.5))
    return np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)


def _car(x_m: float, y_m: float) -> npt.NDArray[np.float64]:
    """Points on the sides of a 4.5 x 1.8 x 1.5 m car centred at (x_m, y_m)."""
    rng = np.random.default_rng(0)
    local = rng.uniform([-2.25, -0.9, 0.0], [2.25, 0.9, 1.5], size=(400, 3))
    local[:200, 1] = np.where(local[:200, 1] > 0, 0.9, -0.9)  # the long sides
    local[200:, 0] = np.where(local[200:, 0] > 0, 2.25, -2.25)  # front and back
    points: npt.NDArray[np.float64] = local + np.array([x_m, y_m, 0.0])
    return points


def _run(algo: $cls, frame: Frame) -> tuple[DetectedObject, ...]:
    result = algo.run_step(frame, StageOutputs())
    assert result.status is StepStatus.OK, result.error
    assert isinstance(result.output, tuple)
    return result.output


def _ready() -> $cls:
    algo = $cls()
    algo.configure({})  # the defaults; a run's config goes here
    algo.bind({"lidar_top": SensorType.LIDAR})
    return algo


def test_finds_the_car_and_not_the_ground() -> None:
    frame = _frame(np.concatenate([_ground(), _car(12.0, 3.0)]))
    objects = _run(_ready(), frame)
    assert all(isinstance(o, DetectedObject) for o in objects)
    assert len(objects) == 1
    car = objects[0]
    assert np.allclose(car.box.center[:2], [12.0, 3.0], atol=0.3)
    assert car.object_class is ObjectClass.VEHICLE
    assert 1.3 < car.box.size[2] < 1.6


def test_two_cars_are_two_objects() -> None:
    frame = _frame(np.concatenate([_ground(), _car(12.0, 3.0), _car(-8.0, -4.0)]))
    centers = sorted(tuple(o.box.center[:2].round(1)) for o in _run(_ready(), frame))
    assert len(centers) == 2
    assert np.allclose(centers, [(-8.0, -4.0), (12.0, 3.0)], atol=0.3)


def test_finds_the_car_on_a_ground_below_base_link() -> None:
    # base_link at the LiDAR, as on KITTI: the road 1.7 m below, sloping 2 % uphill
    lowered = np.concatenate([_ground(), _car(12.0, 3.0)])
    lowered[:, 2] += -1.7 + 0.02 * lowered[:, 0]
    objects = _run(_ready(), _frame(lowered))
    assert len(objects) == 1
    car = objects[0]
    assert np.allclose(car.box.center[:2], [12.0, 3.0], atol=0.3)
    assert 1.3 < car.box.size[2] < 1.6
    bottom_m = car.box.center[2] - car.box.size[2] / 2
    assert abs(bottom_m - (-1.7 + 0.02 * 12.0)) < 0.15  # standing on the road


def test_ground_only_and_empty_sweeps_give_no_objects() -> None:
    algo = _ready()
    assert _run(algo, _frame(_ground())) == ()
    assert _run(algo, _frame(np.zeros((0, 3)))) == ()


def test_step_returns_a_list() -> None:
    algo = _ready()
    assert isinstance(algo.step(_frame(_ground()), StageOutputs()), list)
'''
