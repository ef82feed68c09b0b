"""Paired percentile bootstrap over frames: the significance test of an A/B comparison (the
definition is in :mod:`redrive.evaluation.compare`).

>>> paired_bootstrap(np.array([1.0, 2.0, 3.0]), resamples=200).excludes_zero      # doctest: +SKIP
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.errors import ConfigError

__all__ = ["Bootstrap", "paired_bootstrap"]

#: elements of one block of resampled indices (bounds memory: 2000 resamples × 10k frames).
_BLOCK = 2_000_000


@dataclass(frozen=True, slots=True, kw_only=True)
class Bootstrap:
    """Paired percentile bootstrap of the mean per-frame difference B − A (see module doc)."""

    n_frames: int
    mean_delta: float
    ci_low: float
    ci_high: float
    resamples: int

    @property
    def excludes_zero(self) -> bool:
        """True when the 95 % CI lies entirely above or below 0 (a significant difference)."""
        return bool(self.ci_low > 0.0 or self.ci_high < 0.0)

    def describe(self) -> str:
        if self.n_frames == 0:
            return "no common frames"
        verdict = "excludes 0" if self.excludes_zero else "includes 0"
        return (
            f"mean Δ {self.mean_delta:+.4g}/frame, 95% CI [{self.ci_low:+.4g}, "
            f"{self.ci_high:+.4g}] {verdict} ({self.resamples} resamples of {self.n_frames} frames)"
        )


def paired_bootstrap(
    delta: npt.NDArray[np.float64], *, resamples: int = 2000, seed: int = 0
) -> Bootstrap:
    """Percentile bootstrap of ``mean(delta)``: resample the frames (entries of ``delta``, the
    per-frame differences B − A) with replacement ``resamples`` times; 95 % CI of the mean."""
    if resamples < 1:
        msg = f"bootstrap resamples must be at least 1, got {resamples}"
        raise ConfigError(msg)
    d = np.asarray(delta, dtype=np.float64)
    d = d[np.isfinite(d)]
    n = int(d.size)
    if n == 0:
        nan = float("nan")
        return Bootstrap(n_frames=0, mean_delta=nan, ci_low=nan, ci_high=nan, resamples=resamples)
    rng = np.random.default_rng(seed)
    means = np.empty(resamples, dtype=np.float64)
    rows = max(1, _BLOCK // n)
    for start in range(0, resamples, rows):
        stop = min(resamples, start + rows)
        means[start:stop] = d[rng.integers(0, n, size=(stop - start, n))].mean(axis=1)
    low, high = np.percentile(means, [2.5, 97.5])
    return Bootstrap(
        n_frames=n,
        mean_delta=float(d.mean()),
        ci_low=float(low),
        ci_high=float(high),
        resamples=resamples,
    )
