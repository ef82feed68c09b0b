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

__all__ = ["Bootstrap", "paired_bootstrap", "paired_statistic_bootstrap", "statistic_of"]

#: elements of one block of resampled indices (bounds memory: 2000 resamples × 10k frames).
_BLOCK = 2_000_000


@dataclass(frozen=True, slots=True, kw_only=True)
class Bootstrap:
    """Paired percentile bootstrap over frames of ``statistic(B) − statistic(A)``; for the
    default statistic ``mean`` that is the mean per-frame difference B − A (see module doc).

    ``mean_delta`` is the observed difference of the statistic on the frames both runs have
    (for ``max``: max of B − max of A, not a mean)."""

    n_frames: int
    mean_delta: float
    ci_low: float
    ci_high: float
    resamples: int
    statistic: str = "mean"

    @property
    def excludes_zero(self) -> bool:
        """True when the 95 % CI lies entirely above or below 0 (a significant difference)."""
        return bool(self.ci_low > 0.0 or self.ci_high < 0.0)

    def describe(self) -> str:
        if self.n_frames == 0:
            return "no common frames"
        verdict = "excludes 0" if self.excludes_zero else "includes 0"
        if self.statistic != "mean":
            return (
                f"Δ of the {self.statistic} over frames {self.mean_delta:+.4g}, 95% CI "
                f"[{self.ci_low:+.4g}, {self.ci_high:+.4g}] {verdict} (the {self.statistic} "
                f"bootstrapped: {self.resamples} resamples of {self.n_frames} frames)"
            )
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


def statistic_of(values: npt.NDArray[np.float64], statistic: str) -> npt.NDArray[np.float64]:
    """``statistic`` (``redrive.evaluation.base.STATISTICS``) over the last axis of ``values``."""
    v = np.asarray(values, dtype=np.float64)
    if statistic == "mean":
        return np.asarray(v.mean(axis=-1))
    if statistic == "sum":
        return np.asarray(v.sum(axis=-1))
    if statistic == "max":
        return np.asarray(v.max(axis=-1))
    if statistic == "min":
        return np.asarray(v.min(axis=-1))
    if statistic == "max_abs":
        return np.asarray(np.abs(v).max(axis=-1))
    if statistic == "rms":
        return np.asarray(np.sqrt((v**2).mean(axis=-1)))
    if statistic in ("p50", "p95", "p99"):  # numpy's default (linear) percentile
        return np.asarray(np.percentile(v, float(statistic[1:]), axis=-1))
    msg = f"unknown statistic {statistic!r} (mean, sum, max, min, max_abs, rms, p50, p95, p99)"
    raise ConfigError(msg)


def paired_statistic_bootstrap(
    a: npt.NDArray[np.float64],
    b: npt.NDArray[np.float64],
    *,
    statistic: str,
    resamples: int = 2000,
    seed: int = 0,
) -> Bootstrap:
    """Percentile bootstrap of ``statistic(b) − statistic(a)`` over paired frames (``a[i]`` and
    ``b[i]`` are one frame): each resample draws the frames with replacement and takes the
    statistic of each run over them; 95 % CI of the difference.  ``mean`` gives exactly
    :func:`paired_bootstrap` of ``b − a`` (the same draws)."""
    if resamples < 1:
        msg = f"bootstrap resamples must be at least 1, got {resamples}"
        raise ConfigError(msg)
    va, vb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if va.shape != vb.shape or va.ndim != 1:
        msg = f"paired bootstrap: A has shape {va.shape}, B {vb.shape}; give the same frames"
        raise ValueError(msg)
    ok = np.isfinite(va) & np.isfinite(vb)
    va, vb = va[ok], vb[ok]
    if statistic == "mean":
        return paired_bootstrap(vb - va, resamples=resamples, seed=seed)
    n = int(va.size)
    if n == 0:
        nan = float("nan")
        return Bootstrap(
            n_frames=0,
            mean_delta=nan,
            ci_low=nan,
            ci_high=nan,
            resamples=resamples,
            statistic=statistic,
        )
    observed = float(statistic_of(vb, statistic) - statistic_of(va, statistic))
    rng = np.random.default_rng(seed)
    deltas = np.empty(resamples, dtype=np.float64)
    rows = max(1, _BLOCK // n)
    for start in range(0, resamples, rows):
        stop = min(resamples, start + rows)
        idx = rng.integers(0, n, size=(stop - start, n))
        deltas[start:stop] = statistic_of(vb[idx], statistic) - statistic_of(va[idx], statistic)
    low, high = np.percentile(deltas, [2.5, 97.5])
    return Bootstrap(
        n_frames=n,
        mean_delta=observed,
        ci_low=float(low),
        ci_high=float(high),
        resamples=resamples,
        statistic=statistic,
    )
