"""The numbers of an A/B comparison: one run's side of it (its evaluation's values, per-frame
series and frame stamps), the per-value and per-series deltas of one metric with their bootstrap,
and the frames where B is most worse than A (definitions in :mod:`redrive.evaluation.compare`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.evaluation.bootstrap import (
    Bootstrap,
    paired_bootstrap,
    paired_statistic_bootstrap,
    statistic_of,
)
from redrive.evaluation.store import Evaluation, read_evaluation
from redrive.results import Run

__all__ = [
    "RunSide",
    "SeriesDelta",
    "SkippedMetric",
    "ValueDelta",
    "WorseFrame",
    "metric_deltas",
    "pair_label",
    "pair_subject",
    "series_direction",
    "verdict",
    "worst_frames",
]

_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
#: per-frame series that count the log, not the algorithm (the same in A and B of one log).
_NEUTRAL = frozenset({"gt", "num_gt", "n_gt", "ground_truth", "num_frames", "frames"})


def _words(text: str) -> frozenset[str]:
    return frozenset(text.split())


#: tokens of per-frame series names: counts of errors (lower is better) and of successes.
_LOWER = _words(
    "fp fps fn fns missed miss misses switch switches idsw frag fragmentations error errors err "
    "collision collisions latency jerk deadline late violation violations rmse ade fde"
)
_HIGHER = _words("tp tps hit hits match matches matched progress recall precision ttc")


def _evaluation(run: Run) -> Evaluation:
    """The stored evaluation of ``run`` (the one place this module reads it)."""
    return read_evaluation(run)


def verdict(a: float, b: float, higher_is_better: bool | None) -> str:
    """B against A: ``same`` when equal (``inf`` and ``inf`` too, whose difference is NaN),
    ``n/a`` when either is NaN, ``changed`` for a value without a direction, else ``better`` or
    ``worse`` (``inf`` against a finite value included)."""
    if math.isnan(a) or math.isnan(b):
        return "n/a"
    if a == b:
        return "same"
    if higher_is_better is None:
        return "changed"
    return "better" if (b > a) == higher_is_better else "worse"


@dataclass(frozen=True, slots=True, kw_only=True)
class SeriesDelta:
    """One per-frame series of one metric, A against B on the frames both have.

    Attributes:
        frames: frame indices int64 (N,) present (finite) in both; ``a``, ``b`` float64 (N,).
        higher_is_better: the series' direction; None for series that count the log (``gt``).
        only_a, only_b: frames present in one run only (a failed step, a shorter run).
        subject: whose motion or output the series scores (:func:`pair_subject`): ``log`` for
            the logged ego of open-loop runs, else the algorithm (``run``: a whole-run metric).
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
    subject: str = ""

    @property
    def label(self) -> str:
        return f"{self.metric}{pair_label(self.algorithm_a, self.algorithm_b)}/{self.series}"

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
    of the same name, when there is one; otherwise ``note`` reports the metric's series.
    ``in_a``/``in_b``: the run has the value (False: only the other run has it; its side is
    NaN). ``subject``: whose motion or output the value scores (:func:`pair_subject`; ``log``:
    the logged ego of open-loop runs, the log's value, not an algorithm's)."""

    metric: str
    metric_version: str
    algorithm_a: str
    algorithm_b: str
    key: str
    unit: str
    higher_is_better: bool | None  # None: neither (a count of the data, a parameter)
    a: float
    b: float
    series: str
    bootstrap: Bootstrap | None
    note: str
    in_a: bool = True
    in_b: bool = True
    subject: str = ""

    @property
    def delta(self) -> float:
        return self.b - self.a

    @property
    def is_log(self) -> bool:
        """The value scores the logged ego in both runs: the log's, not an algorithm's."""
        return self.subject == "log"

    @property
    def relative_delta(self) -> float:
        if not math.isfinite(self.a) or self.a == 0.0:
            return float("nan")
        return self.delta / abs(self.a)

    @property
    def significance(self) -> str:
        """Short form of the note: the CI of the matching series and whether it excludes 0."""
        if self.bootstrap is None:
            if self.is_log:
                return "the log's"
            return "aggregate: see the series" if "per-frame series" in self.note else "—"
        b = self.bootstrap
        if b.n_frames == 0:
            return "no common frames"
        what = "" if b.statistic == "mean" else f"{b.statistic} "
        return f"{what}[{b.ci_low:+.3g}, {b.ci_high:+.3g}] " + ("≠ 0" if b.excludes_zero else "∋ 0")

    @property
    def verdict(self) -> str:
        """``better``, ``worse``, ``same`` (B against A), ``changed`` for a value without a
        direction, ``only A`` / ``only B`` when one run has no such value, or ``n/a`` when
        either is NaN."""
        if not (self.in_a and self.in_b):
            return "only A" if self.in_a else "only B"
        return verdict(self.a, self.b, self.higher_is_better)


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


def pair_subject(a: str | None, b: str | None) -> str:
    """One subject for a pair: the common one (``log`` when both score the logged ego), the one
    side that has it, else ``A→B`` (an open-loop run's ``log`` beside a closed loop's ``run``)."""
    if not a or not b:
        return a or b or ""
    return a if a == b else f"{a}→{b}"


def pair_label(a: str, b: str) -> str:
    """``[a]`` for one algorithm, ``[a→b]`` for a pair, nothing for run-level metrics."""
    if not a and not b:
        return ""
    return f"[{a}]" if a == b else f"[{a}→{b}]"


def _stored_direction(row: Mapping[str, Any]) -> bool | None:
    """A stored value's direction: True, False, or None (neither)."""
    hib = row.get("higher_is_better")
    return None if hib is None else bool(hib)


def series_direction(series: str) -> bool | None:
    """A per-frame series' direction by its name alone: True higher is better (``tp`` …),
    None a count of the log (``gt`` …), else False (``missed``, ``fp``, anything unnamed)."""
    return _direction(series, {}, False)


def _direction(series: str, key_dirs: Mapping[str, bool | None], default: bool) -> bool | None:
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
class RunSide:
    """One run of the comparison: its evaluation, values by (metric, algorithm), per-frame series
    by (metric, algorithm, series) and frame stamps by index."""

    run: Run
    ev: Evaluation
    values: dict[tuple[str, str], list[dict[str, Any]]]
    series: dict[tuple[str, str, str], tuple[_I64, _F64]]
    stamps: dict[int, int]
    series_subjects: dict[tuple[str, str, str], str]

    @classmethod
    def load(cls, run: Run) -> RunSide:
        ev = _evaluation(run)
        values: dict[tuple[str, str], list[dict[str, Any]]] = {}
        for row in ev.values.to_pylist():
            values.setdefault((row["metric"], row["algorithm"]), []).append(row)
        cols = ev.per_frame.to_pydict()
        rows: dict[tuple[str, str, str], list[int]] = {}
        subjects: dict[tuple[str, str, str], str] = {}
        for i, (key, subject) in enumerate(
            zip(
                zip(cols["metric"], cols["algorithm"], cols["series"], strict=True),
                cols["subject"],
                strict=True,
            )
        ):
            rows.setdefault(key, []).append(i)
            subjects.setdefault(key, subject)
        idx_all = np.asarray(cols["frame_index"], dtype=np.int64)
        val_all = np.asarray(cols["value"], dtype=np.float64)
        series = {k: (idx_all[r], val_all[r]) for k, r in rows.items()}
        frames = run.table("frames")
        idx, stamp = frames.column("frame_index").to_pylist(), frames.column("stamp_ns").to_pylist()
        stamps = dict(zip(idx, stamp, strict=True))
        return cls(
            run=run,
            ev=ev,
            values=values,
            series=series,
            stamps=stamps,
            series_subjects=subjects,
        )

    def definition(self, metric: str, algorithm: str) -> list[Mapping[str, Any]]:
        return [
            m
            for m in self.ev.metrics
            if m.get("name") == metric and algorithm in m.get("algorithms", ())
        ]

    def algorithms(self) -> set[str]:
        return {algo for _, algo in self.values}


def _renamer(renames: Mapping[str, str]) -> Callable[[str], str]:
    """A function putting ``NAME/ALGO`` (a whole-run metric's value or series of one algorithm,
    ``p95_ms/det_v1``) under the shown name of its algorithm pair (``p95_ms/det_v1→det_v2``)."""

    def rename(name: str) -> str:
        head, sep, algo = name.rpartition("/")
        return f"{head}/{renames[algo]}" if sep and algo in renames else name

    return rename


def metric_deltas(
    a: RunSide,
    b: RunSide,
    which: tuple[str, str, str],
    *,
    hib: bool,
    resamples: int,
    seed: int,
    renamed: Sequence[tuple[str, str]] = (),
) -> tuple[list[ValueDelta], list[SeriesDelta]]:
    """The value and series deltas of one metric (``which`` = metric, A's and B's algorithm).

    ``renamed``: algorithm pairs of different names (A's, B's); a whole-run metric's values and
    series of one algorithm (``latency``'s ``p95_ms/ALGO``) pair under ``ALGO_A→ALGO_B``."""
    metric, xa, xb = which
    pairs = {x: f"{x}→{y}" for x, y in renamed} if not xa and not xb else {}
    ren_a = _renamer(pairs)
    ren_b = _renamer({y: f"{x}→{y}" for x, y in renamed} if pairs else {})
    rows_a = {
        ren_a(r["key"]): {**r, "series": ren_a(str(r.get("series") or ""))}
        for r in a.values.get((metric, xa), [])
    }
    rows_b = {
        ren_b(r["key"]): {**r, "series": ren_b(str(r.get("series") or ""))}
        for r in b.values.get((metric, xb), [])
    }
    key_dirs = {k: _stored_direction(r) for k, r in (rows_b | rows_a).items()}
    stored_a = {ren_a(s): s for m, x, s in a.series if m == metric and x == xa}
    stored_b = {ren_b(s): s for m, x, s in b.series if m == metric and x == xb}
    names = list(stored_a) + [s for s in stored_b if s not in stored_a]
    series: list[SeriesDelta] = []
    full: dict[str, tuple[_F64, _F64]] = {}
    for name in names:
        key_a, key_b = (
            (metric, xa, stored_a.get(name, name)),
            (metric, xb, stored_b.get(name, name)),
        )
        fa, va = a.series.get(key_a, (np.zeros(0, np.int64), np.zeros(0)))
        fb, vb = b.series.get(key_b, (np.zeros(0, np.int64), np.zeros(0)))
        full[name] = (va, vb)
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
                subject=pair_subject(a.series_subjects.get(key_a), b.series_subjects.get(key_b)),
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
        subject = pair_subject(
            str(ra_["subject"]) if ra_ else None, str(rb_["subject"]) if rb_ else None
        )
        boot, note, used = _value_interval(
            key, (ra_, rb_), by_name, full, resamples=resamples, seed=seed
        )
        if not note:
            note = (
                "not a per-frame mean; paired bootstrap of the per-frame series, mean Δ/frame "
                f"[95% CI] (≠0: excludes 0): {summary}"
                if summary
                else "no per-frame series: no significance test"
            )
        if subject == "log":
            boot, note = (
                None,
                (
                    "the logged ego's motion (open loop): the log's value, the same whatever the "
                    "algorithm did; not an algorithm result"
                ),
            )
        values.append(
            ValueDelta(
                metric=metric,
                metric_version=str(row["metric_version"]),
                algorithm_a=xa,
                algorithm_b=xb,
                key=key,
                unit=str(row["unit"]),
                higher_is_better=_stored_direction(row),
                a=float(ra_["value"]) if ra_ else float("nan"),
                b=float(rb_["value"]) if rb_ else float("nan"),
                series=used,
                bootstrap=boot,
                note=note,
                in_a=ra_ is not None,
                in_b=rb_ is not None,
                subject=subject,
            )
        )
    return values, series


def _statistic_matching(
    rows: tuple[Mapping[str, Any] | None, Mapping[str, Any] | None],
    full: tuple[_F64, _F64],
) -> str | None:
    """The statistic (``mean``, ``sum``, ``max`` …) that each stored value is of its run's whole
    stored series, the same in both runs (a side without the value does not object); None."""
    for stat in ("mean", "sum", "max", "min", "max_abs", "rms", "p50", "p95", "p99"):
        ok = True
        for row, series in zip(rows, full, strict=True):
            if row is None:
                continue
            finite = series[np.isfinite(series)]
            value = float(row["value"])
            if finite.size == 0 or not math.isfinite(value):
                ok = False
                break
            got = float(statistic_of(finite, stat))
            ok &= bool(np.isclose(value, got, rtol=1e-9, atol=1e-12))
        if ok:
            return stat
    return None


def _value_interval(
    key: str,
    rows: tuple[Mapping[str, Any] | None, Mapping[str, Any] | None],
    by_name: Mapping[str, SeriesDelta],
    full: Mapping[str, tuple[_F64, _F64]],
    *,
    resamples: int,
    seed: int,
) -> tuple[Bootstrap | None, str, str]:
    """The CI that belongs to value ``key`` (its bootstrap, note, series): the bootstrap of
    the statistic the value is — declared by the metric (``max`` over frames …), or, for the
    series of its name (``num_X``: of ``X``), the statistic the stored value equals in both
    runs — else none, with a note saying why."""
    ra_, rb_ = rows
    declared = {
        (str(r.get("series") or ""), str(r.get("statistic") or ""))
        for r in (ra_, rb_)
        if r is not None
    }
    declared.discard(("", ""))
    name, stat = next(iter(declared)) if len(declared) == 1 else ("", "")
    if not name:
        name = key if key in by_name else (key[4:] if key.startswith("num_") else key)
    match = by_name.get(name)
    if match is None:
        return None, "", ""
    if not stat:
        stat = _statistic_matching(rows, full[name]) or ""
    if not stat:
        return (
            None,
            f"an aggregate, not the mean, sum, max or min of per-frame {name}: no CI of its "
            f"own (the series' {match.bootstrap.describe()} is of its mean Δ/frame, not of "
            "this value)",
            "",
        )
    boot = paired_statistic_bootstrap(
        match.a, match.b, statistic=stat, resamples=resamples, seed=seed
    )
    note = f"{stat} of per-frame {name}: {boot.describe()}"
    if match.only_a or match.only_b:
        note += (
            f"; on the {match.frames.size} frames both runs have ({match.only_a} only in A, "
            f"{match.only_b} only in B), so its Δ can differ from the values' Δ"
        )
    return boot, note, name


def worst_frames(
    a: RunSide, b: RunSide, series: Sequence[SeriesDelta], *, compared: set[tuple[str, str, str]]
) -> list[WorseFrame]:
    """Every frame where B is worse than A on the ``compared`` metrics, worst first."""
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
            text = f"{r['metric']}{pair_label(r['algorithm'], r['algorithm'])} {r['kind']}: {r['detail']}"
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
