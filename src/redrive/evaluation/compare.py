"""A/B comparison of two evaluated runs of the same log: per-value deltas with a paired bootstrap
significance note, per-frame deltas, and the frames where B is most worse than A.

Definitions (B − A throughout):

* **value delta** ``Δ = B − A``, relative ``Δ / |A|`` (NaN when A is 0 or either is NaN);
  ``better`` / ``worse`` by the value's stored ``higher_is_better``, ``same`` when Δ = 0.
* **paired bootstrap over frames** (percentile bootstrap, Efron & Tibshirani 1993, *An
  Introduction to the Bootstrap*, ch. 13; the paired form resamples the per-frame differences as
  in Koehn 2004, *Statistical Significance Tests for Machine Translation Evaluation*): for one
  per-frame series present in both runs, ``d_f = B_f − A_f`` on the frames both have (finite in
  both); each of ``bootstrap`` resamples draws ``n`` frame indices with replacement
  (``numpy.random.default_rng(seed)``, a fresh generator per series, so every series of the same
  frames sees the same resampled frames) and takes the mean of ``d`` over them; the 95 % CI is
  the 2.5th and 97.5th percentile of those means. *Significant* means the CI excludes 0.
  What is resampled is frames, never objects within a frame.
* Values that are not per-frame means (mAP, MOTA, HOTA …) have no frame-level decomposition; their
  note reports the bootstrap of the metric's per-frame series instead and says so.
* **worse frames**: per directional series, B's worsening at frame f is ``B_f − A_f`` (lower is
  better) or ``A_f − B_f`` (higher is better); a frame's score is the sum over series of its
  positive worsening divided by the series' largest absolute per-frame difference (each series
  adds at most 1, so series in different units can be added); frames are ranked by score.

Only metrics whose name, version and ``params_hash`` agree in both manifests are compared; the
others are listed in :attr:`Comparison.skipped` with the reason.

>>> cmp = compare_runs("runs/a", "runs/b")                  # doctest: +SKIP
>>> cmp.worst_frames(5)[0].differences                       # doctest: +SKIP
"""

from __future__ import annotations

import base64
import html
import io
import json
import logging
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from redrive.errors import ConfigError
from redrive.evaluation.store import Evaluation, read_evaluation
from redrive.results import Run, open_run

__all__ = [
    "Bootstrap",
    "Comparison",
    "SeriesDelta",
    "SkippedMetric",
    "ValueDelta",
    "WorseFrame",
    "compare_runs",
    "paired_bootstrap",
]

logger = logging.getLogger(__name__)

_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
#: elements of one block of resampled indices (bounds memory: 2000 resamples × 10k frames).
_BLOCK = 2_000_000
#: per-frame series that count the log, not the algorithm (the same in A and B of one log).
_NEUTRAL = frozenset({"gt", "num_gt", "n_gt", "ground_truth", "num_frames", "frames"})


def _words(text: str) -> frozenset[str]:
    return frozenset(text.split())


#: tokens of per-frame series names: counts of errors (lower is better) and of successes.
_LOWER = _words(
    "fp fps fn fns missed miss misses switch switches idsw frag fragmentations error errors err "
    "collision collisions latency jerk deadline late violation violations rmse ade fde"
)
_HIGHER = _words("tp tps hit hits match matches progress recall precision ttc")


def _evaluation(run: Run) -> Evaluation:
    """The stored evaluation of ``run`` (the one place this module reads it)."""
    return read_evaluation(run)


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


def paired_bootstrap(delta: _F64, *, resamples: int = 2000, seed: int = 0) -> Bootstrap:
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


@dataclass(frozen=True, slots=True, kw_only=True)
class SeriesDelta:
    """One per-frame series of one metric, A against B on the frames both have.

    Attributes:
        frames: frame indices int64 (N,) present (finite) in both; ``a``, ``b`` float64 (N,).
        higher_is_better: the series' direction; None for series that count the log (``gt``).
        only_a, only_b: frames present in one run only (a failed step, a shorter run).
    """

    metric: str
    algorithm_a: str
    algorithm_b: str
    series: str
    higher_is_better: bool | None
    frames: _I64
    a: _F64
    b: _F64
    only_a: int
    only_b: int
    bootstrap: Bootstrap

    @property
    def label(self) -> str:
        return f"{self.metric}{_algos(self.algorithm_a, self.algorithm_b)}/{self.series}"

    @property
    def delta(self) -> _F64:
        return self.b - self.a

    @property
    def worsening(self) -> _F64:
        """How much worse B is than A per frame (positive = worse); zeros if no direction."""
        if self.higher_is_better is None:
            return np.zeros_like(self.a)
        return self.a - self.b if self.higher_is_better else self.b - self.a


@dataclass(frozen=True, slots=True, kw_only=True)
class ValueDelta:
    """One stored value of a metric in A and B. ``series``/``bootstrap``: the per-frame series
    of the same name, when there is one; otherwise ``note`` reports the metric's series."""

    metric: str
    metric_version: str
    algorithm_a: str
    algorithm_b: str
    key: str
    unit: str
    higher_is_better: bool
    a: float
    b: float
    series: str
    bootstrap: Bootstrap | None
    note: str

    @property
    def delta(self) -> float:
        return self.b - self.a

    @property
    def relative_delta(self) -> float:
        if not math.isfinite(self.a) or self.a == 0.0:
            return float("nan")
        return self.delta / abs(self.a)

    @property
    def significance(self) -> str:
        """Short form of the note: the CI of the matching series and whether it excludes 0."""
        if self.bootstrap is None:
            return "aggregate: see the series" if "per-frame series" in self.note else "—"
        b = self.bootstrap
        if b.n_frames == 0:
            return "no common frames"
        return f"[{b.ci_low:+.3g}, {b.ci_high:+.3g}] " + ("≠ 0" if b.excludes_zero else "∋ 0")

    @property
    def verdict(self) -> str:
        """``better``, ``worse``, ``same`` (B against A), or ``n/a`` when either is NaN."""
        if math.isnan(self.a) or math.isnan(self.b):
            return "n/a"
        if self.delta == 0.0:
            return "same"
        return "better" if (self.delta > 0.0) == self.higher_is_better else "worse"


@dataclass(frozen=True, slots=True, kw_only=True)
class WorseFrame:
    """A frame where B is worse than A: ``score`` (module doc), what differs, bookmarks of B
    at that frame that A does not have."""

    frame_index: int
    stamp_ns: int
    score: float
    differences: tuple[str, ...]
    new_bookmarks: tuple[str, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class SkippedMetric:
    """A metric not compared, and why (different version or parameters, missing in one run)."""

    metric: str
    algorithm_a: str
    algorithm_b: str
    reason: str


def _algos(a: str, b: str) -> str:
    if not a and not b:
        return ""
    return f"[{a}]" if a == b else f"[{a}→{b}]"


def _direction(series: str, key_dirs: Mapping[str, bool], default: bool) -> bool | None:
    """A per-frame series' direction: none for log counts, a value of the same name, name
    tokens (``missed``, ``fp`` … lower; ``tp`` … higher), else the metric's direction."""
    if series in _NEUTRAL:
        return None
    for key in (series, f"num_{series}"):
        if key in key_dirs:
            return key_dirs[key]
    tokens = set(re.split(r"[^a-z0-9]+", series.lower()))
    if tokens & _LOWER:
        return False
    if tokens & _HIGHER:
        return True
    return default


@dataclass(frozen=True, slots=True, kw_only=True)
class _Side:
    run: Run
    ev: Evaluation
    values: dict[tuple[str, str], list[dict[str, Any]]]
    series: dict[tuple[str, str, str], tuple[_I64, _F64]]
    stamps: dict[int, int]

    @classmethod
    def load(cls, run: Run) -> _Side:
        ev = _evaluation(run)
        values: dict[tuple[str, str], list[dict[str, Any]]] = {}
        for row in ev.values.to_pylist():
            values.setdefault((row["metric"], row["algorithm"]), []).append(row)
        cols = ev.per_frame.to_pydict()
        rows: dict[tuple[str, str, str], list[int]] = {}
        for i, key in enumerate(
            zip(cols["metric"], cols["algorithm"], cols["series"], strict=True)
        ):
            rows.setdefault(key, []).append(i)
        idx_all = np.asarray(cols["frame_index"], dtype=np.int64)
        val_all = np.asarray(cols["value"], dtype=np.float64)
        series = {k: (idx_all[r], val_all[r]) for k, r in rows.items()}
        frames = run.table("frames")
        idx, stamp = frames.column("frame_index").to_pylist(), frames.column("stamp_ns").to_pylist()
        stamps = dict(zip(idx, stamp, strict=True))
        return cls(run=run, ev=ev, values=values, series=series, stamps=stamps)

    def definition(self, metric: str, algorithm: str) -> list[Mapping[str, Any]]:
        return [
            m
            for m in self.ev.metrics
            if m.get("name") == metric and algorithm in m.get("algorithms", ())
        ]

    def algorithms(self) -> set[str]:
        return {algo for _, algo in self.values}


def _log_hash(run: Run) -> str:
    sha = run.manifest.log.sha256 or ""
    if not sha:
        msg = (
            f"{run.path / 'manifest.json'} records no log sha256; cannot check the runs share a log"
        )
        raise ConfigError(msg)
    return sha


def _pairs(
    a: _Side, b: _Side, algorithm_a: str | None, algorithm_b: str | None
) -> tuple[list[tuple[str, str]], list[SkippedMetric]]:
    algos_a, algos_b = a.algorithms(), b.algorithms()
    skipped: list[SkippedMetric] = []
    if algorithm_a is None and algorithm_b is None:
        pairs = [(x, x) for x in sorted(algos_a & algos_b)]
        for only, other in ((algos_a - algos_b, "B"), (algos_b - algos_a, "A")):
            for x in sorted(only):
                xa, xb = (x, "") if other == "B" else ("", x)
                reason = f"algorithm {x!r} has no evaluation in {other}"
                skipped.append(
                    SkippedMetric(metric="*", algorithm_a=xa, algorithm_b=xb, reason=reason)
                )
        return pairs, skipped
    pa_, pb_ = algorithm_a or algorithm_b or "", algorithm_b or algorithm_a or ""
    for name, have, side in ((pa_, algos_a, a), (pb_, algos_b, b)):
        if name not in have:
            known = ", ".join(sorted(x for x in have if x)) or "none"
            msg = f"{side.run.path}: no evaluated algorithm {name!r} (evaluated: {known})"
            raise ConfigError(msg)
    pairs = [(pa_, pb_)]
    if "" in algos_a and "" in algos_b:
        pairs.append(("", ""))  # run-level metrics (latency …) are about the run as a whole
    return pairs, skipped


def _definition_mismatch(metric: str, da: Mapping[str, Any], db: Mapping[str, Any]) -> str | None:
    if str(da.get("version")) != str(db.get("version")):
        return f"version {da.get('version')} in A, {db.get('version')} in B"
    if da.get("params_hash") != db.get("params_hash"):
        pa_, pb_ = dict(da.get("params") or {}), dict(db.get("params") or {})
        diff = [
            f"{k}: {pa_.get(k, '—')!r} → {pb_.get(k, '—')!r}"
            for k in sorted(set(pa_) | set(pb_))
            if pa_.get(k) != pb_.get(k)
        ]
        return "parameters differ (" + ("; ".join(diff) or "params_hash") + ")"
    return None


def compare_runs(
    run_a: str | os.PathLike[str] | Run,
    run_b: str | os.PathLike[str] | Run,
    *,
    algorithm_a: str | None = None,
    algorithm_b: str | None = None,
    bootstrap: int = 2000,
    seed: int = 0,
) -> Comparison:
    """Compare two evaluated runs of the same log (B against A); see the module doc.

    Algorithms are paired by name, or, with ``algorithm_a``/``algorithm_b`` (one defaults to the
    other), only that pair is compared (plus run-level metrics).

    Raises:
        ConfigError: the runs replayed different logs (both hashes and manifests named), a run is
            not evaluated, or a named algorithm has no evaluation.
    """
    ra = run_a if isinstance(run_a, Run) else open_run(Path(run_a))
    rb = run_b if isinstance(run_b, Run) else open_run(Path(run_b))
    sha_a, sha_b = _log_hash(ra), _log_hash(rb)
    if sha_a != sha_b:
        msg = (
            f"runs replayed different logs: A {ra.path / 'manifest.json'} has log sha256 {sha_a} "
            f"({ra.manifest.log.path}), B {rb.path / 'manifest.json'} has {sha_b} "
            f"({rb.manifest.log.path}); compare runs of the same log"
        )
        raise ConfigError(msg)
    a, b = _Side.load(ra), _Side.load(rb)
    pairs, skipped = _pairs(a, b, algorithm_a, algorithm_b)
    values: list[ValueDelta] = []
    series: list[SeriesDelta] = []
    metric_names = list(
        dict.fromkeys([m["name"] for m in a.ev.metrics] + [m["name"] for m in b.ev.metrics])
    )
    for metric in metric_names:
        for xa, xb in pairs:
            da, db = a.definition(metric, xa), b.definition(metric, xb)
            if not da and not db:
                continue
            reason = None
            if not da or not db:
                reason = f"not evaluated in {'A' if not da else 'B'}"
            elif len(da) > 1 or len(db) > 1:
                reason = "evaluated with several parameter sets in one run; values are ambiguous"
            else:
                reason = _definition_mismatch(metric, da[0], db[0])
            ver_a = {r["metric_version"] for r in a.values.get((metric, xa), [])}
            ver_b = {r["metric_version"] for r in b.values.get((metric, xb), [])}
            if reason is None and ver_a and ver_b and ver_a != ver_b:  # the values say so too
                reason = f"version {', '.join(sorted(ver_a))} in A, {', '.join(sorted(ver_b))} in B"
            if reason is not None:
                skipped.append(
                    SkippedMetric(metric=metric, algorithm_a=xa, algorithm_b=xb, reason=reason)
                )
                logger.info("not comparing %s%s: %s", metric, _algos(xa, xb), reason)
                continue
            hib = bool(da[0].get("higher_is_better", True))
            v, s = _compare_metric(a, b, (metric, xa, xb), hib=hib, resamples=bootstrap, seed=seed)
            values += v
            series += s
    compared = {(v.metric, v.algorithm_a, v.algorithm_b) for v in values}
    worst = _worst_frames(a, b, series, compared=compared)
    return Comparison(
        run_a=ra.path,
        run_b=rb.path,
        log_sha256=sha_a,
        pairs=tuple(pairs),
        values=tuple(values),
        series=tuple(series),
        worst=tuple(worst),
        skipped=tuple(skipped),
        resamples=bootstrap,
        seed=seed,
    )


def _compare_metric(
    a: _Side, b: _Side, which: tuple[str, str, str], *, hib: bool, resamples: int, seed: int
) -> tuple[list[ValueDelta], list[SeriesDelta]]:
    metric, xa, xb = which
    rows_a = {r["key"]: r for r in a.values.get((metric, xa), [])}
    rows_b = {r["key"]: r for r in b.values.get((metric, xb), [])}
    key_dirs = {k: bool(r["higher_is_better"]) for k, r in (rows_b | rows_a).items()}
    names = [s for m, x, s in a.series if m == metric and x == xa]
    names += [s for m, x, s in b.series if m == metric and x == xb and s not in names]
    series: list[SeriesDelta] = []
    for name in names:
        fa, va = a.series.get((metric, xa, name), (np.zeros(0, np.int64), np.zeros(0)))
        fb, vb = b.series.get((metric, xb, name), (np.zeros(0, np.int64), np.zeros(0)))
        fa, va = fa[np.isfinite(va)], va[np.isfinite(va)]
        fb, vb = fb[np.isfinite(vb)], vb[np.isfinite(vb)]
        common, ia, ib = np.intersect1d(fa, fb, assume_unique=False, return_indices=True)
        sa, sb = va[ia], vb[ib]
        series.append(
            SeriesDelta(
                metric=metric,
                algorithm_a=xa,
                algorithm_b=xb,
                series=name,
                higher_is_better=_direction(name, key_dirs, hib),
                frames=common.astype(np.int64),
                a=sa,
                b=sb,
                only_a=int(np.setdiff1d(fa, fb).size),
                only_b=int(np.setdiff1d(fb, fa).size),
                bootstrap=paired_bootstrap(sb - sa, resamples=resamples, seed=seed),
            )
        )
    by_name = {s.series: s for s in series}
    summary = "; ".join(
        f"{s.series} {s.bootstrap.mean_delta:+.3g} [{s.bootstrap.ci_low:+.3g}, "
        f"{s.bootstrap.ci_high:+.3g}]{' ≠0' if s.bootstrap.excludes_zero else ''}"
        for s in series
        if s.higher_is_better is not None and s.bootstrap.n_frames
    )
    values: list[ValueDelta] = []
    for key in list(rows_a) + [k for k in rows_b if k not in rows_a]:
        ra_, rb_ = rows_a.get(key), rows_b.get(key)
        row = ra_ or rb_
        assert row is not None
        match = by_name.get(key) or (by_name.get(key[4:]) if key.startswith("num_") else None)
        if match is not None:
            boot: Bootstrap | None = match.bootstrap
            note = f"per-frame {match.series}: {match.bootstrap.describe()}"
        else:
            boot = None
            note = (
                f"not a per-frame mean; paired bootstrap of the per-frame series, mean Δ/frame "
                f"[95% CI] (≠0: excludes 0): {summary}"
                if summary
                else "no per-frame series: no significance test"
            )
        values.append(
            ValueDelta(
                metric=metric,
                metric_version=str(row["metric_version"]),
                algorithm_a=xa,
                algorithm_b=xb,
                key=key,
                unit=str(row["unit"]),
                higher_is_better=bool(row["higher_is_better"]),
                a=float(ra_["value"]) if ra_ else float("nan"),
                b=float(rb_["value"]) if rb_ else float("nan"),
                series=match.series if match else "",
                bootstrap=boot,
                note=note,
            )
        )
    return values, series


def _worst_frames(
    a: _Side, b: _Side, series: Sequence[SeriesDelta], *, compared: set[tuple[str, str, str]]
) -> list[WorseFrame]:
    score: dict[int, float] = {}
    diffs: dict[int, list[tuple[float, str]]] = {}
    for s in series:
        w = s.worsening
        top = float(np.max(np.abs(w))) if w.size else 0.0
        if s.higher_is_better is None or top == 0.0:
            continue
        for k in np.flatnonzero(w != 0.0):
            f = int(s.frames[k])
            if w[k] > 0:
                score[f] = score.get(f, 0.0) + float(w[k]) / top
            word = "worse" if w[k] > 0 else "better"
            text = f"{s.label} {s.a[k]:.4g} → {s.b[k]:.4g} ({s.b[k] - s.a[k]:+.4g}, {word})"
            diffs.setdefault(f, []).append((-float(w[k]) / top, text))
    to_b = {(m, xa): xb for m, xa, xb in compared}  # bookmarks of compared metrics only
    marks_a = {
        (r["frame_index"], r["metric"], to_b[key], r["kind"], r["detail"])
        for r in a.ev.bookmarks.to_pylist()
        if (key := (r["metric"], r["algorithm"])) in to_b
    }
    keep_b = {(m, xb) for m, _, xb in compared}
    new: dict[int, list[str]] = {}
    for r in b.ev.bookmarks.to_pylist():
        mark = (r["frame_index"], r["metric"], r["algorithm"], r["kind"], r["detail"])
        if (r["metric"], r["algorithm"]) in keep_b and mark not in marks_a:
            text = (
                f"{r['metric']}{_algos(r['algorithm'], r['algorithm'])} {r['kind']}: {r['detail']}"
            )
            new.setdefault(int(r["frame_index"]), []).append(text)
    ranked = sorted((f for f, v in score.items() if v > 0), key=lambda f: (-score[f], f))
    return [
        WorseFrame(
            frame_index=f,
            stamp_ns=int(a.stamps.get(f, b.stamps.get(f, 0))),
            score=score[f],
            differences=tuple(t for _, t in sorted(diffs[f])),
            new_bookmarks=tuple(new.get(f, ())),
        )
        for f in ranked
    ]


def _schema(spec: str) -> pa.Schema:
    types = {"s": pa.string(), "f": pa.float64(), "b": pa.bool_(), "i": pa.int64()}
    return pa.schema([(n, types[t]) for n, t in (c.split(":") for c in spec.split())])


_VALUES = _schema(
    "metric:s metric_version:s algorithm_a:s algorithm_b:s key:s unit:s higher_is_better:b a:f "
    "b:f delta:f relative_delta:f verdict:s series:s ci_low:f ci_high:f excludes_zero:b note:s"
)
_SERIES = _schema(
    "metric:s algorithm_a:s algorithm_b:s series:s higher_is_better:b n_frames:i only_a:i "
    "only_b:i mean_delta:f ci_low:f ci_high:f excludes_zero:b resamples:i"
)
_PER_FRAME = _schema(
    "metric:s algorithm_a:s algorithm_b:s series:s frame_index:i a:f b:f delta:f worsening:f"
)
_WORST = _schema("frame_index:i stamp_ns:i score:f differences:s new_bookmarks:s")
_SKIPPED = _schema("metric:s algorithm_a:s algorithm_b:s reason:s")


def _get(obj: Any, name: str) -> Any:
    """Column ``name`` of a result object: its attribute, else its bootstrap's (None if none)."""
    if hasattr(obj, name):
        value = getattr(obj, name)
    else:
        boot = getattr(obj, "bootstrap", None)
        value = getattr(boot, name) if boot is not None else None
    return "\n".join(value) if isinstance(value, tuple) else value


def _table(schema: pa.Schema, objs: Sequence[Any]) -> pa.Table:
    return pa.table({n: [_get(o, n) for o in objs] for n in schema.names}, schema=schema)


def _num(x: Any) -> Any:
    return None if isinstance(x, float) and not math.isfinite(x) else x


@dataclass(frozen=True, slots=True, kw_only=True)
class Comparison:
    """The A/B comparison of two runs of one log (B against A); see the module doc.

    Attributes:
        pairs: the compared algorithm pairs (A's name, B's name); ("", "") = run-level metrics.
        values: per metric value; series: per per-frame series (with its bootstrap);
        worst: every frame where B is worse, worst first; skipped: metrics not compared.
        resamples, seed: the bootstrap's.
    """

    run_a: Path
    run_b: Path
    log_sha256: str
    pairs: tuple[tuple[str, str], ...]
    values: tuple[ValueDelta, ...]
    series: tuple[SeriesDelta, ...]
    worst: tuple[WorseFrame, ...]
    skipped: tuple[SkippedMetric, ...]
    resamples: int
    seed: int

    def worst_frames(self, n: int | None = None) -> tuple[WorseFrame, ...]:
        """The ``n`` frames where B is most worse than A (all of them for None), worst first."""
        return self.worst if n is None else self.worst[: max(n, 0)]

    def to_tables(self) -> dict[str, pa.Table]:
        """``values``, ``series`` (bootstrap per series), ``per_frame`` (A, B, Δ and B's
        worsening per frame and series), ``worst_frames`` (ranked) and ``skipped``."""
        per_frame: dict[str, list[Any]] = {n: [] for n in _PER_FRAME.names}
        for s in self.series:
            for col in ("metric", "algorithm_a", "algorithm_b", "series"):
                per_frame[col] += [getattr(s, col)] * s.frames.size
            for col in ("frames", "a", "b", "delta", "worsening"):
                per_frame["frame_index" if col == "frames" else col] += getattr(s, col).tolist()
        return {
            "values": _table(_VALUES, self.values),
            "series": _table(_SERIES, self.series),
            "per_frame": pa.table(per_frame, schema=_PER_FRAME),
            "worst_frames": _table(_WORST, self.worst),
            "skipped": _table(_SKIPPED, self.skipped),
        }

    def to_dict(self, *, worst: int | None = None) -> dict[str, Any]:
        """A JSON-ready summary (NaN → null; the per-frame rows left out)."""
        tables = self.to_tables()
        out: dict[str, Any] = {
            "run_a": str(self.run_a),
            "run_b": str(self.run_b),
            "log_sha256": self.log_sha256,
            "pairs": [list(p) for p in self.pairs],
            "bootstrap": {"resampled": "frames", "resamples": self.resamples, "seed": self.seed},
        }
        for name in ("values", "series", "worst_frames", "skipped"):
            rows = tables[name].to_pylist()
            if name == "worst_frames" and worst is not None:
                rows = rows[: max(worst, 0)]
            out[name] = [{k: _num(v) for k, v in r.items()} for r in rows]
        return out

    def to_json(self, *, worst: int | None = None) -> str:
        return json.dumps(self.to_dict(worst=worst), indent=2, allow_nan=False)

    def write_html(self, path: str | os.PathLike[str], *, worst: int = 20) -> Path:
        """One self-contained HTML file (inline CSS, plots as base64 PNG; no network), written
        atomically (temp + rename). Returns its path."""
        out = Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + ".tmp")
        tmp.write_text(_html(self, worst=worst), encoding="utf-8")
        os.replace(tmp, out)
        return out


_CSS = """
body{font-family:system-ui,sans-serif;margin:2em;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:13px}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#f0f0f0}
.better{color:#187a2f}.worse{color:#b3261e}.muted{color:#777}
img{max-width:100%}code{background:#f4f4f4;padding:0 3px}
"""


def _png(fig: Any) -> str:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _delta_chart(c: Comparison) -> str | None:
    from matplotlib.figure import Figure

    rows = [
        v for v in c.values if math.isfinite(v.relative_delta) and v.verdict in ("better", "worse")
    ]
    heads = {(v.metric, v.algorithm_a): v.key for v in reversed(c.values)}  # first key each
    rows = sorted(
        rows, key=lambda v: (heads[(v.metric, v.algorithm_a)] != v.key, -abs(v.relative_delta))
    )[:30]
    if not rows:
        return None
    fig = Figure(figsize=(8, 0.3 * len(rows) + 1.2))
    ax = fig.add_subplot()
    gain = [100.0 * abs(v.relative_delta) * (1 if v.verdict == "better" else -1) for v in rows]
    colors = ["#187a2f" if g > 0 else "#b3261e" for g in gain]
    ax.barh(range(len(rows)), gain, color=colors)
    ax.set_yticks(
        range(len(rows)),
        [f"{v.metric}{_algos(v.algorithm_a, v.algorithm_b)} {v.key}" for v in rows],
        fontsize=7,
    )
    ax.invert_yaxis()
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_xlabel("relative change of B against A, % (right = better; headline values first)")
    return _png(fig)


def _timeline(c: Comparison) -> str | None:
    from matplotlib.figure import Figure

    rows = [s for s in c.series if s.higher_is_better is not None and s.frames.size][:8]
    if not rows:
        return None
    fig = Figure(figsize=(9, 1.7 * len(rows) + 0.6))
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    for ax, s in zip(axes, rows, strict=True):
        w = s.worsening
        ax.bar(s.frames, s.delta, width=1.0, color=np.where(w > 0, "#b3261e", "#187a2f"))
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(f"Δ {s.series}", fontsize=8)
        ax.set_title(s.label + ("  (red = B worse)"), fontsize=8, loc="left")
    axes[-1].set_xlabel("frame index")
    return _png(fig)


def _n(x: float) -> str:
    return f"{x:.4g}" if math.isfinite(x) else "n/a"


def _table_html(head: str, rows: Sequence[Sequence[str]]) -> str:
    """An HTML table; ``head`` is space-separated plain words (``_`` for spaces); cells are
    already escaped."""
    th = "".join(f"<th>{html.escape(h.replace('_', ' '))}</th>" for h in head.split())
    trs = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{trs}</table>"


def _html(c: Comparison, *, worst: int) -> str:
    e = html.escape
    out = [
        '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">',
        f"<title>redrive compare: {e(c.run_a.name)} vs {e(c.run_b.name)}</title>",
        f"<style>{_CSS}</style></head><body><h1>A/B comparison</h1>",
        f"<p>A: <code>{e(str(c.run_a))}</code><br>B: <code>{e(str(c.run_b))}</code><br>",
        f"log sha256 <code>{e(c.log_sha256)}</code> (the same in both)</p>",
        f"<p>Δ = B − A. Significance: paired percentile bootstrap over frames — the frames both "
        f"runs have are resampled with replacement {c.resamples} times (seed {c.seed}); the 95 % "
        f"CI of the mean per-frame difference is reported, significant when it excludes 0.</p>",
    ]
    if c.skipped:
        out.append("<h2>Not compared</h2><ul>")
        for k in c.skipped:
            out.append(
                f"<li>{e(k.metric + _algos(k.algorithm_a, k.algorithm_b))}: {e(k.reason)}</li>"
            )
        out.append("</ul>")
    out.append("<h2>Values</h2>")
    for alt, png in (("relative change per value", _delta_chart(c)),):
        out += [f'<img alt="{alt}" src="data:image/png;base64,{png}">'] if png else []
    rows = [
        [e(v.metric + _algos(v.algorithm_a, v.algorithm_b)), e(v.key), e(v.unit), _n(v.a),
         _n(v.b), _n(v.delta), _n(100.0 * v.relative_delta),
         f'<span class="{e(v.verdict)}">{e(v.verdict)}</span>', e(v.significance)]
        for v in c.values
    ]  # fmt: skip
    out.append(_table_html("metric value unit A B Δ Δ_% B_is significance", rows))
    out.append("<h2>Per-frame series</h2>")
    for alt, png in (("per-frame delta timeline", _timeline(c)),):
        out += [f'<img alt="{alt}" src="data:image/png;base64,{png}">'] if png else []
    rows = [
        [e(s.label), {True: "higher", False: "lower", None: "—"}[s.higher_is_better],
         str(s.bootstrap.n_frames), _n(s.bootstrap.mean_delta),
         f"[{_n(s.bootstrap.ci_low)}, {_n(s.bootstrap.ci_high)}]",
         "yes" if s.bootstrap.excludes_zero else "no"]
        for s in c.series
    ]  # fmt: skip
    out.append(_table_html("series better frames mean_Δ/frame 95%_CI excludes_0", rows))
    out.append(f"<h2>Frames where B is most worse than A (top {worst})</h2>")
    rows = [
        [str(i + 1), str(w.frame_index), str(w.stamp_ns), _n(w.score),
         "<br>".join(e(t) for t in w.differences), "<br>".join(e(t) for t in w.new_bookmarks)]
        for i, w in enumerate(c.worst_frames(worst))
    ]  # fmt: skip
    out.append(_table_html("# frame stamp_ns score what_differs new_bookmarks_in_B", rows))
    out.append("</body></html>\n")
    return "\n".join(out)
