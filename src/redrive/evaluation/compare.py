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

* **whose motion a value scores** (its stored ``subject``): a value of the *logged* ego of
  open-loop runs (at-fault collisions, comfort, progress, drivable area, nuPlan's score … of the
  ego table, the controller's tracking error) is the log's, the same whatever the algorithms
  did; such values are kept apart in :attr:`Comparison.log_values` (shown once, as the log's),
  out of the algorithm comparison and the worse frames.  An open-loop run beside a closed-loop
  one compares them (the log's ego against the driven one, subject ``log→run``).
* **the CI beside a value is of that value**: the paired bootstrap of the statistic the value
  is — the one its metric declares (``max`` over frames of ``max_lon_accel_mps2`` …), or, for the
  per-frame series of its name, the one (mean, sum, max, min …) the stored value equals in both
  runs — resampling the frames both runs have; a value that is none of those gets no CI (its
  note says so) rather than the CI of another number.

Only metrics whose name, version and ``params_hash`` agree in both manifests are compared; the
others are listed in :attr:`Comparison.skipped` with the reason.

Which runs pair (:mod:`redrive.evaluation.pairing`): two runs of the same log, two closed-loop
runs of the same scenario, seed, duration and agents, or — either order — an open-loop run of a
``redrive synth`` log beside a closed-loop run of the scenario it was made from (same name, seed,
duration; or both on the same recorded log). In that open/closed pairing every algorithm and
metric either run has is shown: a value only one run has is NaN on the other side with
``in_a``/``in_b`` False (``—`` in the tables), never dropped; :attr:`Comparison.pairing` says
which run is which loop and how the pipelines differ.

This module pairs the runs, their algorithms and their metric definitions; the numbers are in
:mod:`redrive.evaluation.deltas` and :mod:`redrive.evaluation.bootstrap`, the result and its
tables/JSON in :mod:`redrive.evaluation.comparison`, the HTML page in
:mod:`redrive.evaluation.compare_html`. Every name of the comparison is importable from here.

>>> cmp = compare_runs("runs/a", "runs/b")                  # doctest: +SKIP
>>> cmp.worst_frames(5)[0].differences                       # doctest: +SKIP
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from redrive.errors import ConfigError
from redrive.evaluation.bootstrap import Bootstrap, paired_bootstrap
from redrive.evaluation.comparison import Comparison
from redrive.evaluation.deltas import (
    RunSide,
    SeriesDelta,
    SkippedMetric,
    ValueDelta,
    WorseFrame,
    metric_deltas,
    pair_label,
    worst_frames,
)
from redrive.evaluation.pairing import Pairing, pair_runs
from redrive.results import Run, open_run

__all__ = [
    "Bootstrap",
    "Comparison",
    "Pairing",
    "SeriesDelta",
    "SkippedMetric",
    "ValueDelta",
    "WorseFrame",
    "compare_runs",
    "paired_bootstrap",
]

logger = logging.getLogger(__name__)


def _pairs(
    a: RunSide,
    b: RunSide,
    algorithm_a: str | None,
    algorithm_b: str | None,
    *,
    one_sided: bool,
    role_pairs: list[tuple[str, str, str]],
) -> tuple[list[tuple[str, str]], list[SkippedMetric]]:
    algos_a, algos_b = a.algorithms(), b.algorithms()
    skipped: list[SkippedMetric] = []
    if algorithm_a is None and algorithm_b is None and one_sided:
        return [(x, x) for x in sorted(algos_a | algos_b)], skipped
    if algorithm_a is None and algorithm_b is None:
        pairs = [(x, x) for x in sorted(algos_a & algos_b)]
        by_role = _pair_by_role(a, b, algos_a - algos_b, algos_b - algos_a)
        role_pairs += by_role
        pairs += [(x, y) for x, y, _ in by_role]
        paired_a = {x for x, _, _ in by_role}
        paired_b = {y for _, y, _ in by_role}
        for only, other in (
            (algos_a - algos_b - paired_a, "B"),
            (algos_b - algos_a - paired_b, "A"),
        ):
            for x in sorted(only):
                xa, xb = (x, "") if other == "B" else ("", x)
                reason = f"algorithm {x!r} has no evaluation in {other}"
                if x:  # an algorithm, not the run-level metrics
                    reason += (
                        " and no single algorithm of its role there to pair with: pair it with "
                        "--algorithm-a/--algorithm-b"
                    )
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


def _pair_by_role(
    a: RunSide, b: RunSide, only_a: set[str], only_b: set[str]
) -> list[tuple[str, str, str]]:
    """Algorithms with different names in A and B, paired when each is the only unpaired
    algorithm of its role on its side (``det_v1`` ↔ ``det_v2``: a new version renamed; a file
    plugin, named after its class, against an installed one), else — a role with several
    (a detector and a tracker, both renamed) — when each is the only unpaired algorithm of its
    role *and stage* (``perception_1``) on its side: (A's, B's, how: the role [and stage])."""
    info_a = {x.name: (x.role, x.stage) for x in a.run.manifest.algorithms}
    info_b = {x.name: (x.role, x.stage) for x in b.run.manifest.algorithms}
    pairs = []
    for role in dict.fromkeys(r for r, _ in info_a.values()):
        xa = [x for x in sorted(only_a) if x and x in info_a and info_a[x][0] is role]
        xb = [x for x in sorted(only_b) if x and x in info_b and info_b[x][0] is role]
        if len(xa) == 1 and len(xb) == 1:
            pairs.append((xa[0], xb[0], role.value))
            continue
        for stage in dict.fromkeys(info_a[x][1] for x in xa):
            sa = [x for x in xa if info_a[x][1] == stage]
            sb = [x for x in xb if info_b[x][1] == stage]
            if stage and len(sa) == 1 and len(sb) == 1:
                pairs.append((sa[0], sb[0], f"{role.value}, stage {stage}"))
    return pairs


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
    """Compare two evaluated runs of the same log or situation (B against A); see the module
    doc. An open-loop and a closed-loop run of the same scenario pair in either order.

    Algorithms are paired by name, then by role: an algorithm whose name the other run lacks
    pairs with the other run's one unpaired algorithm of its role (``Comparison.role_pairs``
    says which pairs were made so); or, with ``algorithm_a``/``algorithm_b`` (one defaults to the
    other), only that pair is compared (plus run-level metrics).

    Raises:
        ConfigError: the runs replayed different logs (both hashes and manifests named), an
            open/closed pair ran different scenarios, seeds or durations (what differs named,
            and the closed-loop options that match), a run is
            not evaluated, or a named algorithm has no evaluation.
    """
    ra = run_a if isinstance(run_a, Run) else open_run(Path(run_a))
    rb = run_b if isinstance(run_b, Run) else open_run(Path(run_b))
    pairing = pair_runs(ra, rb)
    if pairing.open_closed:
        logger.info("%s", pairing.describe())
    one_sided = pairing.open_closed  # side by side: what only one run has is shown, not dropped
    a, b = RunSide.load(ra), RunSide.load(rb)
    role_pairs: list[tuple[str, str, str]] = []
    pairs, skipped = _pairs(
        a, b, algorithm_a, algorithm_b, one_sided=one_sided, role_pairs=role_pairs
    )
    for xa, xb, role in role_pairs:
        logger.info("pairing %s of A with %s of B by role (%s)", xa, xb, role)
    # every pair of different names (by role, or --algorithm-a/-b): a whole-run metric's
    # values of one algorithm (latency per algorithm) pair under both names
    renamed = [(xa, xb) for xa, xb in pairs if xa and xb and xa != xb]
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
            if (not da or not db) and one_sided:
                only = da or db
                if len(only) == 1:
                    hib_one = bool(only[0].get("higher_is_better", True))
                    v, s = metric_deltas(
                        a, b, (metric, xa, xb), hib=hib_one, resamples=bootstrap, seed=seed,
                        renamed=renamed,
                    )  # fmt: skip
                    values += v
                    series += s
                    continue
                reason = "evaluated with several parameter sets in one run; values are ambiguous"
            elif not da or not db:
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
                logger.info("not comparing %s%s: %s", metric, pair_label(xa, xb), reason)
                continue
            hib = bool(da[0].get("higher_is_better", True))
            v, s = metric_deltas(
                a, b, (metric, xa, xb), hib=hib, resamples=bootstrap, seed=seed, renamed=renamed
            )
            values += v
            series += s
    # values of the logged ego (open loop, both sides): the log's, the same whatever the
    # algorithms did; shown apart, never as an algorithm's result nor in the worse frames
    log_values = tuple(v for v in values if v.is_log)
    values = [v for v in values if not v.is_log]
    series = [s for s in series if s.subject != "log"]
    compared = {(v.metric, v.algorithm_a, v.algorithm_b) for v in values}
    worst = worst_frames(a, b, series, compared=compared)
    return Comparison(
        run_a=ra.path,
        run_b=rb.path,
        log_sha256=pairing.source,
        pairing=pairing,
        pairs=tuple(pairs),
        role_pairs=tuple(role_pairs),
        values=tuple(values),
        log_values=log_values,
        series=tuple(series),
        worst=tuple(worst),
        skipped=tuple(skipped),
        resamples=bootstrap,
        seed=seed,
    )
