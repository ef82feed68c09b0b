"""What the GUI shows of a closed-loop run beyond an open-loop one — no Qt here.

- :class:`Deviation`: the run's ``closed_loop`` table as series (distance and heading of the
  driven from the logged ego per frame) and the frames where the ``deviated`` flag turns on
  (the threshold crossings the timeline bookmarks).
- :class:`RunFrames`: the frames of an object-level run, rebuilt from its stored tables (the
  driven ego, the ground truth) — such a run has no sensor log to play.
- :func:`ghost_segments`: the logged ego's box in the driven ego's base_link.
- (the road map's layers are :mod:`redrive.gui.map_layers`')
- :func:`driven_from_frame`: the pose difference that re-expresses a recorded log's frame in the
  driven ego's base_link (a closed loop on a recorded log).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.closedloop.logreplay import driven_from_logged
from redrive.geometry.boxes import box_corners
from redrive.results import Run
from redrive.types import Box3D, Frame, VehicleState

__all__ = [
    "EGO_BOX",
    "Deviation",
    "RunFrames",
    "driven_from_frame",
    "ghost_segments",
    "read_deviation",
]

Float = npt.NDArray[np.float64]

#: a mid-size car with its rear axle at base_link (REP-105's ego reference point).
EGO_BOX = Box3D(center=np.array([1.4, 0.0, 0.8]), size=np.array([4.6, 1.9, 1.6]), yaw_rad=0.0)

#: the edges of :func:`redrive.geometry.boxes.box_corners`' corner order (bottom, top, pillars)
#: and a cross on the front face, as for every box the planview draws.
_EDGES = np.array(
    [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
     [0, 4], [1, 5], [2, 6], [3, 7], [0, 7], [3, 4]],
    dtype=np.intp,
)  # fmt: skip


@dataclass(frozen=True, slots=True, kw_only=True)
class Deviation:
    """The ``closed_loop`` table of a run, one entry per frame (ascending frame index).

    Attributes:
        frames: (N,) int64 frame indices.
        stamps_ns: (N,) int64 stamps.
        distance_m: (N,) float64 distance of the driven from the logged ego (NaN: no logged ego).
        heading_rad: (N,) float64 |heading difference| (NaN: no logged ego).
        deviated: (N,) bool, the run's flag (False where it was not known).
        threshold_m, threshold_rad: the run's thresholds (manifest ``closed_loop``), if stored.
    """

    frames: npt.NDArray[np.int64]
    stamps_ns: npt.NDArray[np.int64]
    distance_m: Float
    heading_rad: Float
    deviated: npt.NDArray[np.bool_]
    threshold_m: float | None = None
    threshold_rad: float | None = None

    def crossings(self) -> tuple[int, ...]:
        """Frame indices where ``deviated`` turns on (off → on; the first frame counts when it
        is on)."""
        on = self.deviated
        turned = on & ~np.concatenate(([False], on[:-1]))
        return tuple(int(f) for f in self.frames[turned])


def read_deviation(run: Run) -> Deviation | None:
    """The run's deviation series; None for a run without a ``closed_loop`` table."""
    table = run.table("closed_loop").to_pydict()
    if not table["frame_index"]:
        return None

    def floats(name: str) -> Float:
        return np.array([math.nan if v is None else v for v in table[name]], dtype=np.float64)

    entry = run.manifest.closed_loop
    return Deviation(
        frames=np.array(table["frame_index"], dtype=np.int64),
        stamps_ns=np.array(table["stamp_ns"], dtype=np.int64),
        distance_m=floats("deviation_m"),
        heading_rad=floats("deviation_yaw_rad"),
        deviated=np.array([bool(v) for v in table["deviated"]], dtype=np.bool_),
        threshold_m=_number(entry.get("deviation_threshold_m")),
        threshold_rad=_number(entry.get("deviation_threshold_rad")),
    )


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) else None


class RunFrames:
    """The frames of a run rebuilt from its tables: frame *k* holds the run's stamp, its ego
    state (the driven ego) and its ground truth (base_link) — what an object-level closed loop's
    algorithms were given.  Same ``frame(index)`` contract as :class:`~redrive.gui.session.
    LogSession`.

    Args:
        stamps_ns: frame index → stamp, for frames ``0 … N-1``.
        ego: frame index → ego state.
        ground_truth: frame index → objects.
    """

    def __init__(
        self,
        stamps_ns: dict[int, int] | Any,
        *,
        ego: Any,
        ground_truth: Any,
    ) -> None:
        self.indices = sorted(stamps_ns)
        self._stamps = stamps_ns
        self._ego = ego
        self._truth = ground_truth

    def __len__(self) -> int:
        return len(self.indices)

    def frame(self, index: int) -> Frame:
        """Frame ``index`` (0-based position among the run's frames).

        Raises:
            IndexError: no such frame.
        """
        if not 0 <= index < len(self.indices):
            raise IndexError(index)
        k = self.indices[index]
        return Frame(
            stamp_ns=int(self._stamps[k]),
            index=index,
            vehicle_state=self._ego.get(k),
            ground_truth=self._truth.get(k),
        )


def _pose(state: VehicleState) -> tuple[float, float, float]:
    return float(state.position[0]), float(state.position[1]), float(state.heading_rad)


def _to_base(state: VehicleState, xy: Float) -> Float:
    """Map-frame (M, 2) points into ``state``'s base_link (M, 2)."""
    x0, y0, h = _pose(state)
    c, s = math.cos(h), math.sin(h)
    dx, dy = xy[:, 0] - x0, xy[:, 1] - y0
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)


def ghost_segments(driven: VehicleState, logged: VehicleState) -> Float:
    """(28, 3) endpoints of the ego box at the logged pose, in the driven ego's base_link."""
    mat = driven_from_logged(driven, logged)
    corners = box_corners(EGO_BOX)  # (8, 3) in logged base_link
    moved = corners @ mat[:3, :3].T + mat[:3, 3]
    return np.asarray(moved[_EDGES.reshape(-1)], dtype=np.float64)


def driven_from_frame(driven: VehicleState, recorded: VehicleState) -> Float | None:
    """4×4 driven base_link ← the recorded frame's base_link; None when they coincide (within
    1 mm / 1e-6 rad: nothing to move)."""
    mat = driven_from_logged(driven, recorded)
    if np.allclose(mat, np.eye(4), atol=1e-6, rtol=0.0):
        return None
    return mat
