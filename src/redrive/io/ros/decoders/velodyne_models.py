"""What each Velodyne model is: its laser angles, range unit and factory byte.

The values are nebula's calibration files (``tier4/nebula``,
``nebula_velodyne_decoders/calibration/{VLP16,VLP32,HDL32}.yaml``: ``vert_correction`` and
``rot_correction`` per laser in radians, ``distance_resolution`` in metres; every other correction
of those files is 0) and the Velodyne manuals' factory bytes (packet byte 1205: 0x22 VLP-16,
0x28 VLP-32C, 0x21 HDL-32E; byte 1204 the return mode: 0x37 strongest, 0x38 last, 0x39 dual).
A laser's ring is its rank by vertical angle, lowest first, as nebula's calibration loader
(``velodyne_calibration_decoder.cpp``) numbers them.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["MODELS_BY_PRODUCT_ID", "ReturnMode", "VelodyneModel"]


class ReturnMode(enum.IntEnum):
    """Packet byte 1204."""

    STRONGEST = 0x37
    LAST = 0x38
    DUAL = 0x39


@dataclass(frozen=True, slots=True, kw_only=True)
class VelodyneModel:
    """One sensor model.

    Attributes:
        name: the model's name (``VLP-16``).
        product_id: packet byte 1205.
        vert_rad: (L,) each laser's vertical angle (elevation), radians.
        rot_rad: (L,) each laser's azimuth correction, radians.
        distance_resolution_m: the unit of a return's 16-bit distance.
        firings_per_block: 2 for the 16-laser models (two firing sequences per 32-return block),
            1 for the 32-laser ones.
    """

    name: str
    product_id: int
    vert_rad: npt.NDArray[np.float64]
    rot_rad: npt.NDArray[np.float64]
    distance_resolution_m: float
    firings_per_block: int

    @property
    def lasers(self) -> int:
        return int(self.vert_rad.shape[0])

    @property
    def rings(self) -> npt.NDArray[np.uint16]:
        """(L,) each laser's ring: its rank by vertical angle, lowest first."""
        order = np.argsort(self.vert_rad, kind="stable")
        rings = np.empty(self.lasers, np.uint16)
        rings[order] = np.arange(self.lasers, dtype=np.uint16)
        return rings


def _deg(values: list[float]) -> npt.NDArray[np.float64]:
    return np.array([math.radians(v) for v in values])


def _radians(values: list[float]) -> npt.NDArray[np.float64]:
    return np.array(values, dtype=np.float64)


VLP16 = VelodyneModel(
    name="VLP-16",
    product_id=0x22,
    # VLP16.yaml: -15°, 1°, -13°, 3°, … 15° (laser id order)
    vert_rad=_deg([-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15]),
    rot_rad=np.zeros(16),
    distance_resolution_m=0.002,
    firings_per_block=2,
)

VLP32C = VelodyneModel(
    name="VLP-32C",
    product_id=0x28,
    vert_rad=_radians(
        [
            -0.4363323129985824,
            -0.017453292519943295,
            -0.029094638630745476,
            -0.2729520417193932,
            -0.19739673840055869,
            0.0,
            -0.011641346110802179,
            -0.15433946575385857,
            -0.12660618393966866,
            0.005811946409141118,
            -0.005811946409141118,
            -0.10730284241261137,
            -0.0930784090088576,
            0.02326523892908441,
            0.011641346110802179,
            -0.06981317007977318,
            -0.08145451619057535,
            0.029094638630745476,
            0.017453292519943295,
            -0.06400122367063206,
            -0.058171823968971005,
            0.058171823968971005,
            0.04071853144902771,
            -0.04654793115068877,
            -0.05235987755982989,
            0.12217304763960307,
            0.08145451619057535,
            -0.04071853144902771,
            -0.03490658503988659,
            0.2617993877991494,
            0.18034487160857407,
            -0.02326523892908441,
        ]
    ),
    # VLP32.yaml: the 1.4° / 4.2° horizontal offsets of the staggered lasers.
    rot_rad=_radians(
        [
            -0.024434609527920613,
            0.07330382858376185,
            -0.024434609527920613,
            0.024434609527920613,
            -0.024434609527920613,
            0.024434609527920613,
            -0.07330382858376185,
            0.024434609527920613,
            -0.024434609527920613,
            0.07330382858376185,
            -0.024434609527920613,
            0.024434609527920613,
            -0.07330382858376185,
            0.024434609527920613,
            -0.07330382858376185,
            0.024434609527920613,
            -0.024434609527920613,
            0.07330382858376185,
            -0.024434609527920613,
            0.07330382858376185,
            -0.07330382858376185,
            0.024434609527920613,
            -0.024434609527920613,
            0.024434609527920613,
            -0.024434609527920613,
            0.024434609527920613,
            -0.024434609527920613,
            0.07330382858376185,
            -0.07330382858376185,
            0.024434609527920613,
            -0.024434609527920613,
            0.024434609527920613,
        ]
    ),
    distance_resolution_m=0.004,
    firings_per_block=1,
)

HDL32E = VelodyneModel(
    name="HDL-32E",
    product_id=0x21,
    # HDL32.yaml: -30.67° … +10.67°, lasers alternating between the lower and upper half.
    vert_rad=_radians(
        [
            -0.5352924815866609,
            -0.1628392174657417,
            -0.5119050696099369,
            -0.13962634015954636,
            -0.4886921905584123,
            -0.11641346285335104,
            -0.4654793115068877,
            -0.09302604738596851,
            -0.44209189953016365,
            -0.06981317007977318,
            -0.4188790204786391,
            -0.046600292773577856,
            -0.39566614142711454,
            -0.023212879051524585,
            -0.3722787294503905,
            0.0,
            -0.3490658503988659,
            0.023212879051524585,
            -0.32585297134734137,
            0.046600292773577856,
            -0.30246555937061725,
            0.06981317007977318,
            -0.2792526803190927,
            0.09302604738596851,
            -0.25603980126756815,
            0.11641346285335104,
            -0.23265238929084414,
            0.13962634015954636,
            -0.20943951023931956,
            0.1628392174657417,
            -0.18622663118779495,
            0.18622663118779495,
        ]
    ),
    rot_rad=np.zeros(32),
    distance_resolution_m=0.002,
    firings_per_block=1,
)

for _model in (VLP16, VLP32C, HDL32E):
    _model.vert_rad.flags.writeable = False
    _model.rot_rad.flags.writeable = False

#: packet byte 1205 → model.
MODELS_BY_PRODUCT_ID: dict[int, VelodyneModel] = {m.product_id: m for m in (VLP16, VLP32C, HDL32E)}
