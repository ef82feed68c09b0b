"""The result of an A/B comparison (:func:`redrive.evaluation.compare.compare_runs`) and its
outputs: Arrow tables, a JSON summary, the HTML page (:mod:`redrive.evaluation.compare_html`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa

from redrive.evaluation.compare_html import render_comparison
from redrive.evaluation.deltas import SeriesDelta, SkippedMetric, ValueDelta, WorseFrame
from redrive.evaluation.pairing import Pairing
from redrive.output.atomic import write_atomic

__all__ = ["Comparison"]


def _schema(spec: str) -> pa.Schema:
    types = {"s": pa.string(), "f": pa.float64(), "b": pa.bool_(), "i": pa.int64()}
    return pa.schema([(n, types[t]) for n, t in (c.split(":") for c in spec.split())])


_VALUES = _schema(
    "metric:s metric_version:s algorithm_a:s algorithm_b:s key:s unit:s higher_is_better:b a:f "
    "b:f delta:f relative_delta:f verdict:s series:s ci_low:f ci_high:f excludes_zero:b note:s "
    "in_a:b in_b:b subject:s"
)
_SERIES = _schema(
    "metric:s algorithm_a:s algorithm_b:s series:s higher_is_better:b n_frames:i only_a:i "
    "only_b:i mean_delta:f ci_low:f ci_high:f excludes_zero:b resamples:i subject:s"
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
    """The comparison of two runs of one log or situation (B against A); see the module doc.

    Attributes:
        log_sha256: what both were made from (``pairing.source``).
        pairing: an A/B of one loop, or an open-loop run beside a closed-loop one; the
            pipelines' differences.
        pairs: the compared algorithm pairs (A's name, B's name); ("", "") = run-level metrics.
        role_pairs: the pairs of different names made by role: (A's, B's, the role).
        values: per metric value of the algorithms (or the run); log_values: per value of the
            logged ego in both runs (open loop): the log's, kept out of the comparison;
        series: per per-frame series (with its bootstrap);
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
    pairing: Pairing
    log_values: tuple[ValueDelta, ...] = ()
    role_pairs: tuple[tuple[str, str, str], ...] = ()

    def worst_frames(self, n: int | None = None) -> tuple[WorseFrame, ...]:
        """The ``n`` frames where B is most worse than A (all of them for None), worst first."""
        return self.worst if n is None else self.worst[: max(n, 0)]

    def to_tables(self) -> dict[str, pa.Table]:
        """``values``, ``log_values`` (the logged ego's, apart), ``series`` (bootstrap per
        series), ``per_frame`` (A, B, Δ and B's worsening per frame and series),
        ``worst_frames`` (ranked) and ``skipped``."""
        per_frame: dict[str, list[Any]] = {n: [] for n in _PER_FRAME.names}
        for s in self.series:
            for col in ("metric", "algorithm_a", "algorithm_b", "series"):
                per_frame[col] += [getattr(s, col)] * s.frames.size
            for col in ("frames", "a", "b", "delta", "worsening"):
                per_frame["frame_index" if col == "frames" else col] += getattr(s, col).tolist()
        return {
            "values": _table(_VALUES, self.values),
            "log_values": _table(_VALUES, self.log_values),
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
            "pairing": self.pairing.to_dict(),
            "pairs": [list(p) for p in self.pairs],
            "role_pairs": [
                {"algorithm_a": x, "algorithm_b": y, "role": r} for x, y, r in self.role_pairs
            ],
            "bootstrap": {"resampled": "frames", "resamples": self.resamples, "seed": self.seed},
        }
        for name in ("values", "log_values", "series", "worst_frames", "skipped"):
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
        return write_atomic(out, render_comparison(self, worst=worst))
