"""Rigid transforms between named frames."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from redrive.types._arrays import frozen_array, frozen_vector

__all__ = ["Transform"]


def _identity_quat() -> npt.NDArray[np.float64]:
    return np.array([0.0, 0.0, 0.0, 1.0])


@dataclass(frozen=True, slots=True, kw_only=True)
class Transform:
    """``parent_from_child``: maps points in ``child_frame`` into ``parent_frame``.

    Attributes:
        parent_frame, child_frame: frame names (a tf ``header.frame_id`` / ``child_frame_id``).
        translation: (3,) float64 metres, the child origin in the parent frame.
        rotation: (4,) float64 unit quaternion x, y, z, w.
        stamp_ns: when it holds; 0 for a static transform.
    """

    parent_frame: str
    child_frame: str
    translation: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    rotation: npt.NDArray[np.float64] = field(default_factory=_identity_quat)
    stamp_ns: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "translation",
            frozen_vector(self.translation, name="Transform.translation", size=3),
        )
        q = np.asarray(self.rotation, dtype=np.float64)
        norm = float(np.linalg.norm(q)) if q.shape == (4,) else 0.0
        if not np.isfinite(norm) or norm < 1e-9:
            msg = f"Transform.rotation must be a non-zero quaternion (x, y, z, w), got {q.tolist()}"
            raise ValueError(msg)
        q = q / norm
        object.__setattr__(
            self,
            "rotation",
            frozen_array(q, name="Transform.rotation", dtype=np.float64, shape=(4,)),
        )
        object.__setattr__(self, "stamp_ns", int(self.stamp_ns))

    @property
    def matrix(self) -> npt.NDArray[np.float64]:
        """The 4×4 homogeneous matrix ``parent_from_child``."""
        x, y, z, w = self.rotation
        rot = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        out = np.eye(4)
        out[:3, :3] = rot
        out[:3, 3] = self.translation
        return out
