"""Published scan patterns of common LiDARs: beam elevations, columns, range, accuracy.

Elevation tables are given in **laser order** (the order the firmware fires and numbers its
lasers), as the manufacturers publish them; ``ring`` in a simulated cloud is the rank of a laser
by elevation, lowest beam = ring 0, as the ROS ``velodyne_pointcloud`` and ``ouster_ros``
drivers number it.

Sources:

* VLP-16: Velodyne *VLP-16 User Manual* (63-9243 Rev. D), Table 9-1 "Laser ID and vertical
  angle": −15, 1, −13, 3, … 15°, 2° apart; 0.1–0.4° azimuth resolution (0.2° at 10 Hz); 100 m;
  ±3 cm typical accuracy.
* HDL-32E: Velodyne *HDL-32E User's Manual* (63-9113 Rev. J), Appendix "Laser firing order /
  vertical angles": −30.67 … +10.67° in 4/3° steps, interleaved; 0.16° at 600 rpm is the
  datasheet figure for 5 Hz, 0.2° (1800 columns) is what drivers see at 10 Hz; 100 m; ±2 cm.
* HDL-64E S2/S3: Velodyne *HDL-64E S2 / S3 User's Manual*: upper block of 32 lasers +2° to
  −8.33° at 1/3° spacing, lower block of 32 lasers −8.83° to −24.33° at 1/2° spacing (nominal;
  every unit ships its own calibration, the datasheet rounds the FOV to +2°/−24.9°); 0.1728°
  azimuth at 10 Hz (2083 columns, 1 333 312 points/s); 120 m; < 2 cm.  Within a block the
  lasers are listed top to bottom (real units interleave them, see ``velodyne_driver``'s
  ``ring_sequence.h``; only the set of angles matters to a simulation).
* Ouster OS1-64 (gen 2, "uniform" beam spacing): Ouster *OS1 Mid-Range High-Resolution Imaging
  Lidar* datasheet rev. 2 / *Software User Manual*: 45° vertical FOV (+22.5° to −22.5°),
  64 beams evenly spaced; 512, 1024 or 2048 columns per turn (1024 × 10 Hz is the default mode);
  120 m; ±3 cm (1–20 m, Lambertian).
* Hokuyo UTM-30LX (2D): *Scanning Laser Range Finder UTM-30LX Specification*: 270° field of
  view, 0.25° step (1081 steps), 40 Hz, 0.1–30 m, ±30 mm (0.1–10 m).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import numpy.typing as npt

__all__ = ["LIDAR_PRESETS", "LidarPreset", "lidar_preset"]


@dataclass(frozen=True, slots=True, kw_only=True)
class LidarPreset:
    """One LiDAR model's scan pattern.

    Attributes:
        name: model name (the key of :data:`LIDAR_PRESETS`).
        elevations_deg: per laser, in laser order, degrees above the sensor's xy plane.
        columns: firings per laser per sweep (a sector of ``fov_deg`` < 360 includes both ends).
        fov_deg: horizontal field of view swept, degrees (360 for spinning units).
        min_range_m, max_range_m: returns closer or farther are dropped.
        range_accuracy_m: 1-σ range noise used when the rig does not give one.
    """

    name: str
    elevations_deg: tuple[float, ...]
    columns: int
    fov_deg: float = 360.0
    min_range_m: float = 0.5
    max_range_m: float = 100.0
    range_accuracy_m: float = 0.02

    @property
    def num_lasers(self) -> int:
        return len(self.elevations_deg)

    @property
    def azimuth_resolution_deg(self) -> float:
        """Step between columns: a full turn has ``columns`` steps, a sector ``columns − 1``."""
        if self.fov_deg >= 360.0:
            return 360.0 / self.columns
        return self.fov_deg / (self.columns - 1)

    @property
    def is_2d(self) -> bool:
        return self.num_lasers == 1

    def elevations_rad(self) -> npt.NDArray[np.float64]:
        """(L,) float64 elevations in laser order, radians."""
        return np.deg2rad(np.asarray(self.elevations_deg, dtype=np.float64))

    def rings(self) -> npt.NDArray[np.uint16]:
        """(L,) uint16: the ring of each laser (rank by elevation, lowest = 0)."""
        order = np.argsort(np.asarray(self.elevations_deg), kind="stable")
        ring = np.empty(self.num_lasers, dtype=np.uint16)
        ring[order] = np.arange(self.num_lasers, dtype=np.uint16)
        return ring


_VLP16 = (
    -15.0,
    1.0,
    -13.0,
    3.0,
    -11.0,
    5.0,
    -9.0,
    7.0,
    -7.0,
    9.0,
    -5.0,
    11.0,
    -3.0,
    13.0,
    -1.0,
    15.0,
)

_HDL32E = (
    -30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33,
    -25.33, -4.00, -24.00, -2.67, -22.67, -1.33, -21.33, 0.00,
    -20.00, 1.33, -18.67, 2.67, -17.33, 4.00, -16.00, 5.33,
    -14.67, 6.67, -13.33, 8.00, -12.00, 9.33, -10.67, 10.67,
)  # fmt: skip

_HDL64E = tuple(round(2.0 - i / 3.0, 2) for i in range(32)) + tuple(
    round(-8.83 - 0.5 * i, 2) for i in range(32)
)

_OS1_64 = tuple(22.5 - 45.0 * i / 63.0 for i in range(64))

#: The presets by name; HDL-64E is the S2/S3 nominal table, OS1-64 the gen-2 uniform one.
LIDAR_PRESETS: Mapping[str, LidarPreset] = MappingProxyType(
    {
        "VLP-16": LidarPreset(
            name="VLP-16",
            elevations_deg=_VLP16,
            columns=1800,
            min_range_m=0.5,
            max_range_m=100.0,
            range_accuracy_m=0.03,
        ),
        "HDL-32E": LidarPreset(
            name="HDL-32E",
            elevations_deg=_HDL32E,
            columns=1800,
            min_range_m=1.0,
            max_range_m=100.0,
            range_accuracy_m=0.02,
        ),
        "HDL-64E": LidarPreset(
            name="HDL-64E",
            elevations_deg=_HDL64E,
            columns=2083,
            min_range_m=0.9,
            max_range_m=120.0,
            range_accuracy_m=0.02,
        ),
        "OS1-64": LidarPreset(
            name="OS1-64",
            elevations_deg=_OS1_64,
            columns=1024,
            min_range_m=0.3,
            max_range_m=120.0,
            range_accuracy_m=0.03,
        ),
        "OS1-64-2048": LidarPreset(
            name="OS1-64-2048",
            elevations_deg=_OS1_64,
            columns=2048,
            min_range_m=0.3,
            max_range_m=120.0,
            range_accuracy_m=0.03,
        ),
        "UTM-30LX": LidarPreset(
            name="UTM-30LX",
            elevations_deg=(0.0,),
            columns=1081,
            fov_deg=270.0,
            min_range_m=0.1,
            max_range_m=30.0,
            range_accuracy_m=0.03,
        ),
    }
)


def lidar_preset(name: str) -> LidarPreset:
    """The preset called ``name``; KeyError listing the known names otherwise."""
    try:
        return LIDAR_PRESETS[name]
    except KeyError:
        msg = f"unknown LiDAR preset {name!r}; known: {', '.join(sorted(LIDAR_PRESETS))}"
        raise KeyError(msg) from None
