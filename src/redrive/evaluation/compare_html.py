"""The A/B comparison as one self-contained HTML page, rendered with the report builders of
:mod:`redrive.evaluation.html` (inline CSS, plots as base64 PNG, no network): the two runs and
their log, the metrics not compared, the value deltas with a bar chart of relative changes, the
per-frame series with a timeline of per-frame deltas, and the frames where B is most worse.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from redrive.evaluation import html as h
from redrive.evaluation.deltas import ValueDelta, pair_label

if TYPE_CHECKING:
    from redrive.evaluation.comparison import Comparison

__all__ = ["CHART_CLIP_PCT", "chart_panels", "delta_bars", "render_comparison"]

#: dots per inch of the comparison's charts.
CHART_DPI = 90
_BETTER, _WORSE = "#187a2f", "#b3261e"
#: the bar chart's axis ends at ± this many percent; a longer bar stops there, labelled with
#: its number (a latency 50 times slower must not flatten every other bar to nothing).
CHART_CLIP_PCT = 100.0


def _is_timing(v: ValueDelta) -> bool:
    """A value of how long the run took (latency), not of what the algorithms did."""
    return v.metric == "latency" or v.unit == "ms"


def delta_bars(c: Comparison, *, timing: bool | None = None) -> list[tuple[str, float]]:
    """The bar chart's bars, headline values first: (label, relative change of B against A in
    %, positive when B is better in the value's own direction — a latency that drops is a
    positive bar, a recall that drops a negative one).  ``timing``: only the latency values
    (True), only the others (False), or all (None)."""
    rows = [
        v
        for v in c.values
        if math.isfinite(v.relative_delta)
        and v.verdict in ("better", "worse")
        and (timing is None or _is_timing(v) == timing)
    ]
    heads = {(v.metric, v.algorithm_a): v.key for v in reversed(c.values)}  # first key each
    rows = sorted(
        rows, key=lambda v: (heads[(v.metric, v.algorithm_a)] != v.key, -abs(v.relative_delta))
    )[:30]
    return [
        (
            f"{v.metric}{pair_label(v.algorithm_a, v.algorithm_b)} {v.key}",
            100.0 * abs(v.relative_delta) * (1 if v.verdict == "better" else -1),
        )
        for v in rows
    ]


def chart_panels(c: Comparison) -> list[tuple[str, list[tuple[str, float]]]]:
    """The bar chart's panels, each on its own axis: the algorithms' values (headlines first),
    then the run's timing (latency), whose relative changes are often far larger; a panel
    without bars is left out.  Each axis ends at ±:data:`CHART_CLIP_PCT` %."""
    panels = [
        ("values of the algorithms (and the run)", delta_bars(c, timing=False)),
        ("timing (latency)", delta_bars(c, timing=True)),
    ]
    return [(title, bars) for title, bars in panels if bars]


def _delta_chart(c: Comparison) -> bytes | None:
    from matplotlib.figure import Figure

    panels = chart_panels(c)
    if not panels:
        return None
    sizes = [len(bars) for _, bars in panels]
    fig = Figure(figsize=(8, 0.3 * sum(sizes) + 1.4 * len(panels)))
    axes = fig.subplots(len(panels), 1, squeeze=False, height_ratios=[n + 2 for n in sizes])[:, 0]
    for ax, (title, bars) in zip(axes, panels, strict=True):
        gain = np.array([g for _, g in bars], dtype=np.float64)
        shown = np.clip(gain, -CHART_CLIP_PCT, CHART_CLIP_PCT)
        colors = [_BETTER if g > 0 else _WORSE for g in gain]
        ax.barh(range(len(bars)), shown, color=colors)
        for i in np.flatnonzero(np.abs(gain) > CHART_CLIP_PCT):
            ax.text(
                float(shown[i]) * 0.98,
                float(i),
                f"{gain[i]:+.0f} %",
                va="center",
                ha="right" if gain[i] > 0 else "left",
                fontsize=7,
                color="white",
            )
        ax.set_yticks(range(len(bars)), [label for label, _ in bars], fontsize=7)
        ax.set_xlim(-CHART_CLIP_PCT * 1.05, CHART_CLIP_PCT * 1.05)
        ax.invert_yaxis()
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_title(title, fontsize=8, loc="left")
    axes[-1].set_xlabel(
        f"relative change of B against A, % (right = better; headline values first; axis "
        f"clipped at ±{CHART_CLIP_PCT:.0f} %, a longer bar shows its number)"
    )
    return h.png(fig, dpi=CHART_DPI, tight=True)


def _timeline(c: Comparison) -> bytes | None:
    from matplotlib.figure import Figure

    rows = [s for s in c.series if s.higher_is_better is not None and s.frames.size][:8]
    if not rows:
        return None
    fig = Figure(figsize=(9, 1.7 * len(rows) + 0.6))
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    for ax, s in zip(axes, rows, strict=True):
        w = s.worsening
        ax.bar(s.frames, s.delta, width=1.0, color=np.where(w > 0, _WORSE, _BETTER))
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(f"Δ {s.series}", fontsize=8)
        ax.set_title(s.label + ("  (red = B worse)"), fontsize=8, loc="left")
    axes[-1].set_xlabel("frame index")
    return h.png(fig, dpi=CHART_DPI, tight=True)


def _n(x: float) -> str:
    return f"{x:.4g}" if math.isfinite(x) else "n/a"


def _lines(texts: tuple[str, ...]) -> h.Markup:
    return h.Markup("<br>".join(h.esc(t) for t in texts))


def _chart(png: bytes | None, alt: str) -> h.Markup:
    return h.img(png, alt=alt) if png else h.Markup("")


def render_comparison(c: Comparison, *, worst: int) -> str:
    """The page of ``c`` with its ``worst`` worst frames (see the module doc)."""
    e = h.esc
    p = c.pairing
    runs = h.Markup(
        f"{e(p.label_a)}: <code>{e(str(c.run_a))}</code><br>"
        f"{e(p.label_b)}: <code>{e(str(c.run_b))}</code><br>"
        f"source <code>{e(c.log_sha256)}</code> (the same in both: log sha256, or scenario and seed)"
    )
    if p.open_closed:
        runs = h.Markup(
            runs
            + f"<br><strong>{e(p.describe())}</strong>"
            + "".join(f"<br>{e(n)}" for n in p.notes)
        )
    method = h.paragraph(
        f"Δ = B − A. Significance: paired percentile bootstrap over frames — the frames both "
        f"runs have are resampled with replacement {c.resamples} times (seed {c.seed}); the 95 % "
        f"CI beside a value is of that value — of the statistic it is over the frames (the "
        f"mean per-frame difference for a mean; 'max', 'sum' … when marked), significant when "
        f"it excludes 0; an aggregate that is none of those gets no CI."
    )
    sections = [method]
    nav = []
    if c.skipped:
        items = "".join(
            f"<li>{e(k.metric + pair_label(k.algorithm_a, k.algorithm_b))}: {e(k.reason)}</li>"
            for k in c.skipped
        )
        sections.append(h.section("skipped", "Not compared", h.Markup(f"<ul>{items}</ul>")))
        nav.append(("skipped", "not compared"))
    values = [
        [v.metric + pair_label(v.algorithm_a, v.algorithm_b), v.key, v.unit,
         _n(v.a) if v.in_a else "—", _n(v.b) if v.in_b else "—",
         _n(v.delta), _n(100.0 * v.relative_delta),
         h.Markup(f'<span class="{e(v.verdict)}">{e(v.verdict)}</span>'), v.significance]
        for v in c.values
    ]  # fmt: skip
    head = ["metric", "value", "unit", p.label_a, p.label_b, "Δ", "Δ %", f"{p.label_b} is",
            "significance"]  # fmt: skip
    sections.append(
        h.section("values", "Values", _chart(_delta_chart(c), "relative change per value"),
                  h.table(head, values, numeric=range(3, 7)))
    )  # fmt: skip
    if c.log_values:
        rows = [
            [v.metric, v.key, v.unit, _n(v.a) if v.in_a else "—",
             "same" if v.verdict == "same" else (_n(v.b) if v.in_b else "—")]
            for v in c.log_values
        ]  # fmt: skip
        sections.append(
            h.section(
                "log",
                "The log's values (not compared)",
                h.paragraph(
                    "These values score the logged ego of the open-loop runs — at-fault "
                    "collisions, comfort, progress, drivable area, nuPlan's score of the ego "
                    "table, the controller's tracking error: the same whatever the algorithms "
                    "did, so they are the log's, not a result of A or B."
                ),
                h.table(["metric", "value", "unit", "log (A)", "B"], rows, numeric=[3]),
            )
        )
        nav.append(("log", "the log's"))
    series = [
        [s.label, {True: "higher", False: "lower", None: "—"}[s.higher_is_better],
         str(s.bootstrap.n_frames), _n(s.bootstrap.mean_delta),
         f"[{_n(s.bootstrap.ci_low)}, {_n(s.bootstrap.ci_high)}]",
         "yes" if s.bootstrap.excludes_zero else "no"]
        for s in c.series
    ]  # fmt: skip
    head = ["series", "better", "frames", "mean Δ/frame", "95% CI", "excludes 0"]
    sections.append(
        h.section("series", "Per-frame series", _chart(_timeline(c), "per-frame delta timeline"),
                  h.table(head, series, numeric=[2, 3]))
    )  # fmt: skip
    frames = [
        [str(i + 1), str(w.frame_index), str(w.stamp_ns), _n(w.score), _lines(w.differences),
         _lines(w.new_bookmarks)]
        for i, w in enumerate(c.worst_frames(worst))
    ]  # fmt: skip
    head = ["#", "frame", "stamp ns", "score", "what differs", "new bookmarks in B"]
    sections.append(
        h.section("worst", f"Frames where B is most worse than A (top {worst})",
                  h.table(head, frames, numeric=range(4)))
    )  # fmt: skip
    nav += [("values", "values"), ("series", "per-frame"), ("worst", "worst frames")]
    return h.page(
        title=f"redrive compare: {c.run_a.name} vs {c.run_b.name}",
        heading="Open loop beside closed loop" if p.open_closed else "A/B comparison",
        subtitle=runs,
        nav=nav,
        body=h.Markup("".join(sections)),
    )
