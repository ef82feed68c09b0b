"""``--agents reactive`` on a log without a road map: a logged vehicle the driven ego holds up
moves along its own logged path (:class:`PathAgent`; the IDM step is
:meth:`redrive.closedloop.logreplay.LogSimulator._idm_step`)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ["PathAgent"]


class PathAgent:
    """A logged vehicle under IDM along its own logged path (``reactive`` without a road map)."""

    __slots__ = ("logged_speed_mps", "path_s", "path_xy", "path_yaw", "s_m", "speed_mps")

    def __init__(self, xy: npt.NDArray[np.float64], yaw_rad: float, speed_mps: float) -> None:
        self.path_xy: list[npt.NDArray[np.float64]] = [xy]
        self.path_yaw: list[float] = [yaw_rad]
        self.path_s: list[float] = [0.0]
        self.s_m = 0.0
        self.speed_mps = speed_mps
        self.logged_speed_mps = speed_mps

    def log(self, xy: npt.NDArray[np.float64], yaw_rad: float, dt_s: float) -> None:
        step = float(np.hypot(*(xy - self.path_xy[-1])))
        self.path_xy.append(xy)
        self.path_yaw.append(yaw_rad)
        self.path_s.append(self.path_s[-1] + step)
        self.logged_speed_mps = step / dt_s if dt_s > 0 else self.logged_speed_mps

    def pose(self) -> tuple[float, float, float]:
        """x, y, yaw (map) at ``s_m`` along the logged path."""
        s = self.path_s
        i = int(np.searchsorted(s, self.s_m, side="right")) - 1
        i = min(max(i, 0), len(s) - 1)
        if i == len(s) - 1 or s[i + 1] <= s[i]:
            x, y = self.path_xy[i]
            return float(x), float(y), self.path_yaw[i]
        a = (self.s_m - s[i]) / (s[i + 1] - s[i])
        x, y = self.path_xy[i] + a * (self.path_xy[i + 1] - self.path_xy[i])
        dyaw = math.remainder(self.path_yaw[i + 1] - self.path_yaw[i], math.tau)
        return float(x), float(y), self.path_yaw[i] + a * dyaw
