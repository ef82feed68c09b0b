"""Report plots: PNG bytes (matplotlib through :func:`redrive.evaluation.html.png`), and the
figures of a report made from a run's tables and its evaluation.

Every ``*_png`` function returns the bytes of one PNG (``PNG_DPI`` dots per inch, no timestamp in the
metadata, so the same data gives the same bytes).  Text that comes from a run (algorithm, metric,
series names, bookmark details) is passed through :func:`plain` so that a ``$`` in it is drawn
as a dollar sign, not parsed as mathtext.

Bird's-eye views follow REP-103 base_link (x forward, y left, metres): forward is drawn up and
left is drawn left (the plot's horizontal axis is +y pointing left), the ego reference point
(rear-axle centre) at the origin.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyarrow.compute as pc
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon
from matplotlib.ticker import MaxNLocator
from matplotlib.transforms import Bbox

from redrive.errors import ConfigError
from redrive.evaluation import html as h
from redrive.evaluation.deltas import series_direction
from redrive.evaluation.frame_points import lidar_points_of_frames
from redrive.evaluation.store import Evaluation
from redrive.geometry.boxes import box_corners
from redrive.results import Run
from redrive.results.readers import objects_by_frame
from redrive.types import DetectedObject

__all__ = [
    "DETECTION_COLORS",
    "GROUND_TRUTH_COLOR",
    "MAX_TIMELINE_SERIES",
    "PNG_DPI",
    "algorithm_order",
    "birds_eye_png",
    "column_at",
    "group_rows",
    "latency_figures",
    "latency_histograms_png",
    "plain",
    "pr_curves_png",
    "pr_figures",
    "snapshot_figures",
    "timeline_figures",
    "timelines_png",
    "worst_frames",
]

PNG_DPI = 110  # 6-inch figures come out 660 px wide: readable without zooming
#: ground-truth boxes in bird's-eye views (green).
GROUND_TRUTH_COLOR = "#2ca02c"
#: detections of the 1st, 2nd … algorithm in bird's-eye views (red, blue, orange, purple).
DETECTION_COLORS = ("#d62728", "#1f77b4", "#ff7f0e", "#9467bd")
#: at most this many series (subplots) in one timeline figure.
MAX_TIMELINE_SERIES = 6
_LINE_STYLES = ("-", "--", "-.", ":")
_CURVE_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2")

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def plain(text: str) -> str:
    """``text`` drawn literally by matplotlib (``$`` escaped, so no mathtext)."""
    return text.replace("$", r"\$")


def pr_curves_png(curves: Sequence[tuple[str, FloatArray, FloatArray]], *, title: str) -> bytes:
    """Precision (y) over recall (x), one line per ``(label, recall, precision)``, both in [0, 1].

    Labels ``GROUP/VARIANT`` (``car/2.0``) share a colour per group and a line style per
    variant, so classes and thresholds can be told apart."""
    fig = Figure(figsize=(6.0, 4.5), layout="constrained")
    ax = fig.add_subplot()
    groups: dict[str, int] = {}
    variants: dict[str, int] = {}
    for label, recall, precision in curves:
        group, _, variant = label.rpartition("/")
        g = groups.setdefault(group, len(groups))
        v = variants.setdefault(variant, len(variants))
        ax.plot(recall, precision, color=_CURVE_COLORS[g % len(_CURVE_COLORS)],
                linestyle=_LINE_STYLES[v % len(_LINE_STYLES)], linewidth=1.5,
                label=plain(label))  # fmt: skip
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(0.0, 1.02)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_title(plain(title), fontsize=10)
    ax.grid(True, alpha=0.3)
    if curves:
        ax.legend(fontsize=6, loc="lower left", ncol=2 if len(curves) > 8 else 1)
    return h.png(fig, dpi=PNG_DPI)


def _timeline_figure(rows: int, again: dict[int, Figure] | None) -> Figure:
    """A figure of ``rows`` subplots sharing the frame axis: a new one, or the one of ``again``
    with that many rows emptied (its lines removed, data and view limits as a new figure's, the
    subplots back in their grid cells for the layout to start from), which draws the same pixels as a new one
    but keeps its axes, their ticks and its canvas (about half the work of a timeline figure)."""
    fig = again.get(rows) if again is not None else None
    if fig is None:
        fig = Figure(figsize=(9.0, 0.6 + 1.5 * rows), layout="constrained")
        fig.subplots(rows, 1, sharex=True, squeeze=False)
        if again is not None:
            again[rows] = fig
        return fig
    for ax in fig.axes:
        for line in list(ax.lines):
            line.remove()
        ax.relim()
        ax.viewLim.set_points(Bbox.unit().get_points())  # limits as a new axes' (not "set")
        spec = ax.get_subplotspec()
        if spec is not None:
            ax.set_subplotspec(spec)
    fig.set_layout_engine("constrained")
    return fig


def timelines_png(
    series: Sequence[tuple[str, npt.NDArray[np.int64], FloatArray]],
    *,
    title: str,
    marks: Sequence[int] = (),
    again: dict[int, Figure] | None = None,
) -> bytes:
    """One subplot per ``(name, frame_index, value)`` (at most :data:`MAX_TIMELINE_SERIES`),
    sharing the frame axis; ``marks`` (bookmarked frames) are drawn as thin red lines.
    ``again``: figures by row count to draw into again (one dict for a run of timelines)."""
    shown = list(series)[:MAX_TIMELINE_SERIES]
    rows = max(1, len(shown))
    fig = _timeline_figure(rows, again if shown else None)
    axes = fig.axes
    for k, (ax, (name, frames, values)) in enumerate(zip(axes, shown, strict=False)):
        color = _CURVE_COLORS[k % len(_CURVE_COLORS)]
        style = "-o" if frames.size <= 60 else "-"
        ax.plot(frames, values, style, color=color, markersize=3, linewidth=1.2)
        ax.set_ylabel(plain(name), fontsize=8)
        ax.grid(True, alpha=0.3)
        for frame in list(marks)[:50]:
            ax.axvline(frame, color="#d62728", alpha=0.25, linewidth=0.8)
    axes[-1].set_xlabel("frame index")
    axes[-1].xaxis.set_major_locator(MaxNLocator(integer=True))  # frames are whole numbers
    axes[0].set_title(plain(title), fontsize=10)
    return h.png(fig, dpi=PNG_DPI)


def latency_histograms_png(
    latencies_ms: Mapping[str, FloatArray], *, deadline_ms: float = 0.0
) -> bytes:
    """One histogram of step latency (ms) per algorithm, its p50 (solid) and p95 (dashed) as
    vertical lines and p50/p95/max written in the corner; the frame period ``deadline_ms`` as a
    red line when it lies within twice the largest latency (else only written)."""
    names = list(latencies_ms)
    cols = 2 if len(names) > 1 else 1
    rows = max(1, math.ceil(len(names) / cols))
    fig = Figure(figsize=(4.6 * cols, 0.4 + 2.6 * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for k, name in enumerate(names):
        ax = axes[k]
        lat = np.asarray(latencies_ms[name], dtype=np.float64)
        lat = lat[np.isfinite(lat)]
        lines = [f"n {lat.size}"]
        if lat.size:
            # one filled outline, not a rectangle per bin: the same pixels, a fifth of the work
            ax.hist(lat, bins=min(50, max(5, lat.size // 4)), color="#1f77b4", alpha=0.85,
                    histtype="stepfilled")  # fmt: skip
            for q, style in ((50, "-"), (95, "--")):
                value = float(np.percentile(lat, q))
                ax.axvline(value, color="#333333", linestyle=style, linewidth=1.0)
                lines.append(f"p{q} {value:.3g} ms")
            lines.append(f"max {float(lat.max()):.3g} ms")
        if deadline_ms > 0:
            if lat.size and deadline_ms <= 2.0 * float(lat.max()):
                ax.axvline(deadline_ms, color="#d62728", linewidth=1.2)
            lines.append(f"frame period {deadline_ms:.3g} ms")
        ax.text(0.98, 0.95, "\n".join(lines), transform=ax.transAxes, fontsize=7, ha="right",
                va="top", bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "#cccccc"})  # fmt: skip
        ax.set_title(plain(name), fontsize=9)
        ax.set_xlabel("latency (ms)", fontsize=8)
        ax.set_ylabel("steps", fontsize=8)
    for ax in axes[len(names) :]:
        ax.set_axis_off()
    return h.png(fig, dpi=PNG_DPI)


def _footprint(obj: DetectedObject) -> FloatArray:
    """(4, 2) bottom-face corners (x, y) in base_link, m."""
    return box_corners(obj.box)[:4, :2]


def _draw_boxes(
    ax: Axes, objects: Sequence[DetectedObject], *, color: str, label: str, dashed: bool
) -> None:
    """The footprints of ``objects`` (one collection of outlines, drawn as a patch each would
    be: mitred corners, dashes restarting at each box) and their heading ticks (one collection
    of segments, capped as a line each would be)."""
    style = "--" if dashed else "-"
    ax.plot([], [], color=color, linestyle=style, label=plain(f"{label} ({len(objects)})"))
    if not objects:
        return
    feet = [_footprint(obj) for obj in objects]
    outlines = [np.column_stack([xy[:, 1], xy[:, 0]]) for xy in feet]  # plot (y, x): forward up
    ax.add_collection(
        PolyCollection(outlines, closed=True, facecolors="none", edgecolors=color,
                       linewidths=2.0, linestyles=style, joinstyle="miter", zorder=1),
        autolim=False,
    )  # fmt: skip
    # a tick from the centre to the front face: the heading
    ticks = []
    for obj, xy in zip(objects, feet, strict=True):
        front, c = 0.5 * (xy[0] + xy[3]), obj.box.center
        ticks.append([(c[1], c[0]), (front[1], front[0])])
    ax.add_collection(
        LineCollection(ticks, colors=color, linewidths=1.0, capstyle="projecting", zorder=2),
        autolim=False,
    )


def _extent_m(objects: Sequence[DetectedObject]) -> float:
    """Half-width of the view: the farthest object within 60 m, + 5 m, in [20, 60] m."""
    reach = [float(np.max(np.abs(obj.box.center[:2]))) for obj in objects]
    near = [r for r in reach if r <= 60.0]
    return min(60.0, max(20.0, max(near, default=15.0) + 5.0))


def birds_eye_png(
    *,
    ground_truth: Sequence[DetectedObject],
    detections: Mapping[str, Sequence[DetectedObject]],
    paths: Mapping[str, FloatArray] | None = None,
    points_xy: FloatArray | None = None,
    title: str,
) -> bytes:
    """Top view of one frame in base_link: the LiDAR points ``points_xy`` ((N, 2) x, y in m,
    light grey dots) when given, ground truth (green, solid), each algorithm's
    detections (dashed, one colour each), planned paths ((K, 2) x, y in m), the ego box
    (4.7 m × 1.9 m from 0.95 m behind the rear axle) and range rings every 10 m.  The view spans
    the farthest object within 60 m, + 5 m (20 … 60 m); farther objects are cut off."""
    paths = paths or {}
    everything = list(ground_truth) + [o for objs in detections.values() for o in objs]
    extent = _extent_m(everything)
    fig = Figure(figsize=(5.5, 6.0), layout="constrained")
    ax = fig.add_subplot()
    for r in np.arange(10.0, extent * 1.5, 10.0):
        ax.add_patch(Circle((0.0, 0.0), float(r), fill=False, color="#bbbbbb", linewidth=0.7))
        if r < extent:
            ax.text(0.0, float(r), f"{r:.0f} m", fontsize=6, color="#888888", ha="center")
    if points_xy is not None and len(points_xy):
        near = points_xy[np.all(np.abs(points_xy) <= extent, axis=1)]
        ax.scatter(near[:, 1], near[:, 0], s=0.15, color="#9a9a9a", linewidths=0, zorder=0,
                   label="LiDAR", rasterized=True)  # fmt: skip
    ego = np.array([[3.75, 0.95], [-0.95, 0.95], [-0.95, -0.95], [3.75, -0.95]])
    ax.add_patch(Polygon(ego[:, ::-1], closed=True, color="#444444", alpha=0.8, label="ego"))
    _draw_boxes(ax, ground_truth, color=GROUND_TRUTH_COLOR, label="ground truth", dashed=False)
    for k, (name, objects) in enumerate(detections.items()):
        color = DETECTION_COLORS[k % len(DETECTION_COLORS)]
        _draw_boxes(ax, objects, color=color, label=name, dashed=True)
    for k, (name, xy) in enumerate(paths.items()):
        if xy.size:
            ax.plot(xy[:, 1], xy[:, 0], color=_CURVE_COLORS[(k + 4) % len(_CURVE_COLORS)],
                    linewidth=1.4, label=plain(f"path {name}"))  # fmt: skip
    ax.set_xlim(extent, -extent)  # +y (left) drawn on the left
    ax.set_ylim(-extent, extent)
    ax.set_aspect("equal")
    ax.set_xlabel("y (m, left +)", fontsize=8)
    ax.set_ylabel("x (m, forward +)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_title(plain(title), fontsize=9)
    fig.legend(fontsize=7, loc="outside lower center", ncol=3, frameon=False, markerscale=12)
    return h.png(fig, dpi=PNG_DPI)


# -- figures of a run and its evaluation ------------------------------------------------------------------------------


def group_rows(table: pa.Table, keys: Sequence[str]) -> dict[tuple[str, ...], IntArray]:
    """Key tuple (values of the string columns ``keys``) → row indices, groups in order of
    first appearance, rows in table order."""
    if table.num_rows == 0:
        return {}
    codes, names = [], []
    for key in keys:
        enc = table.column(key).combine_chunks().dictionary_encode()
        codes.append(np.asarray(enc.indices.to_numpy(zero_copy_only=False), dtype=np.int64))
        names.append([str(x) for x in enc.dictionary.to_pylist()])
    uniq, first, inverse = np.unique(
        np.column_stack(codes), axis=0, return_index=True, return_inverse=True
    )
    inverse = inverse.reshape(-1)
    by_group = np.argsort(inverse, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(np.bincount(inverse, minlength=len(uniq)))])
    out: dict[tuple[str, ...], IntArray] = {}
    for g in np.argsort(first, kind="stable"):
        group = tuple(names[k][int(uniq[g, k])] for k in range(len(keys)))
        out[group] = by_group[bounds[g] : bounds[g + 1]].astype(np.int64)
    return out


def column_at(table: pa.Table, name: str, rows: IntArray) -> npt.NDArray[Any]:
    """Column ``name`` of ``table`` at ``rows``, as numpy."""
    values: npt.NDArray[Any] = np.asarray(table.column(name).to_numpy())[rows]
    return values


def algorithm_order(run: Run, names: Sequence[str]) -> list[str]:
    """The distinct ``names`` in the run's pipeline order; unknown names, then "" (the run
    as a whole) last."""
    known = run.manifest.names()
    rank = {n: i for i, n in enumerate(known)}
    return sorted(set(names), key=lambda n: (n == "", rank.get(n, len(rank)), n))


# -- worst frames --------------------------------------------------------------------------


#: the default ranking's per-frame errors: (metric, series) → weight, per algorithm; a
#: detection metric's misses and false positives (the first of these metrics the run has) and
#: the tracker's identity switches each count 1.
FRAME_SCORE_TERMS: tuple[tuple[tuple[str, str], ...], ...] = (
    (("nuscenes_detection", "missed"), ("nuscenes_detection", "fp")),
    (("kitti_detection", "missed"), ("kitti_detection", "fp")),
    (("clear_mot", "misses"), ("clear_mot", "fp")),
)
FRAME_SCORE_SWITCHES = ("clear_mot", "switches")


def frame_scores(evaluation: Evaluation, rank_by: str | None = None) -> dict[int, float]:
    """Per frame, how bad it is (larger is worse).

    Default: for each algorithm, its missed objects + false positives (of the first detection
    metric in :data:`FRAME_SCORE_TERMS` stored for it) + identity switches (``clear_mot``); a
    frame's score is its largest over algorithms.  ``rank_by`` = ``METRIC.SERIES``: that stored
    per-frame series instead (its largest value over algorithms; negated when the series is
    higher-is-better by its name, e.g. ``tp``), so any metric can rank the frames.

    Raises:
        ConfigError: ``rank_by`` names a series the evaluation does not have.
    """
    pf = evaluation.per_frame.to_pylist()
    series: dict[tuple[str, str, str], dict[int, float]] = {}
    for r in pf:
        if r["value"] == r["value"]:  # not NaN
            series.setdefault((r["metric"], r["algorithm"], r["series"]), {})[
                int(r["frame_index"])
            ] = float(r["value"])
    score: dict[int, float] = {}
    if rank_by is not None:
        metric, _, name = rank_by.partition(".")
        hits = {k: v for k, v in series.items() if k[0] == metric and k[2] == name}
        if not hits:
            have = sorted({f"{m}.{n}" for m, _, n in series})
            msg = f"--rank-by {rank_by}: no such per-frame series (stored: {', '.join(have)})"
            raise ConfigError(msg)
        sign = -1.0 if series_direction(name) else 1.0
        for values in hits.values():
            for f, v in values.items():
                score[f] = max(score.get(f, -math.inf), sign * v)
        return score
    algorithms = {a for _, a, _ in series}
    for algo in algorithms:
        per: dict[int, float] = {}
        for terms in FRAME_SCORE_TERMS:
            if all((m, algo, n) in series for m, n in terms):
                for m, n in terms:
                    for f, v in series[(m, algo, n)].items():
                        per[f] = per.get(f, 0.0) + v
                break
        m, n = FRAME_SCORE_SWITCHES
        for f, v in series.get((m, algo, n), {}).items():
            per[f] = per.get(f, 0.0) + v
        for f, v in per.items():
            score[f] = max(score.get(f, 0.0), v)
    return score


def worst_frames(
    run: Run, evaluation: Evaluation, *, count: int, rank_by: str | None = None
) -> list[tuple[int, list[str]]]:
    """Up to ``count`` frames to look at, worst first, each with lines saying why.

    Ranked by :func:`frame_scores` (misses + false positives + identity switches by default, or
    the series ``rank_by`` names), ties and frames without a score by their most severe
    bookmark, then frame index; every bookmark of a chosen frame is listed.  When the run has
    neither scores nor bookmarks: the frames with the largest shortfall of objects
    (ground-truth objects minus the objects of the perception algorithm that returned fewest
    there, among those whose step was ``ok``).
    """
    scores = frame_scores(evaluation, rank_by)
    marks = sorted(
        evaluation.bookmarks.to_pylist(), key=lambda r: (-r["severity"], r["frame_index"])
    )
    why: dict[int, list[str]] = {}
    worst_mark: dict[int, float] = {}
    for m in marks:
        frame = int(m["frame_index"])
        who = "/".join(x for x in (m["metric"], m["algorithm"]) if x)
        text = f"{m['kind']} ({who}, severity {h.fmt_number(m['severity'], digits=3)})"
        why.setdefault(frame, []).append(text + (f": {m['detail']}" if m["detail"] else ""))
        worst_mark.setdefault(frame, float(m["severity"]))
    candidates = set(why) | {f for f, v in scores.items() if v > 0 or rank_by is not None}
    if candidates and count > 0:
        ranked = sorted(
            candidates,
            key=lambda f: (-scores.get(f, -math.inf), -worst_mark.get(f, -math.inf), f),
        )[:count]
        label = f"{rank_by} " if rank_by else "score (missed + false positives + switches) "
        out = []
        for f in ranked:
            lines = [f"{label}{h.fmt_number(abs(scores[f]), digits=3)}"] if f in scores else []
            out.append((f, lines + why.get(f, [])))
        return out
    if count <= 0:
        return []
    frames = run.table("frames")
    n_gt = {
        int(f): int(n)
        for f, n in zip(
            frames.column("frame_index").to_pylist(),
            frames.column("n_ground_truth").to_pylist(),
            strict=True,
        )
        if n is not None
    }
    steps = run.table("steps")
    ran = steps.filter(
        pc.and_(
            pc.equal(steps.column("role"), "perception"), pc.equal(steps.column("status"), "ok")
        )
    )
    dets = run.table("detections")
    found = {
        k[0]: column_at(dets, "frame_index", r) for k, r in group_rows(dets, ["algorithm"]).items()
    }
    short: dict[int, tuple[int, str, int]] = {}  # frame -> (missing, algorithm, found)
    for (algo,), rows in group_rows(ran, ["algorithm"]).items():
        counts = np.bincount(found.get(algo, np.zeros(0, dtype=np.int64)))
        for frame in column_at(ran, "frame_index", rows).tolist():
            if frame not in n_gt:
                continue
            have = int(counts[frame]) if frame < counts.size else 0
            if n_gt[frame] - have > short.get(frame, (0, "", 0))[0]:
                short[frame] = (n_gt[frame] - have, algo, have)
    ranked = sorted(short, key=lambda f: (-short[f][0], f))[:count]
    return [
        (f, [f"{n_gt[f]} ground-truth objects, {short[f][2]} found by {short[f][1]}"])
        for f in ranked
    ]


def snapshot_figures(run: Run, frames: Sequence[tuple[int, Sequence[str]]]) -> list[h.Markup]:
    """A bird's-eye figure per ``(frame, reasons)``: ground truth, the detections of up to four
    perception algorithms, planned paths in base_link; the reasons as caption."""
    if not frames:
        return []
    wanted = pa.array([f for f, _ in frames], pa.int64())

    def rows_of(name: str) -> pa.Table:
        table = run.table(name)
        return table.filter(pc.is_in(table.column("frame_index"), value_set=wanted))

    gt, dets, paths = rows_of("ground_truth"), rows_of("detections"), rows_of("paths")
    clouds = lidar_points_of_frames(run, [f for f, _ in frames])
    detectors = algorithm_order(run, run.table("detections").column("algorithm").to_pylist())
    out = []
    for frame, why in frames:
        gt_objs = objects_by_frame(gt.filter(pc.equal(gt.column("frame_index"), frame)))
        shown: dict[str, Sequence[DetectedObject]] = {}
        for algo in detectors[: len(DETECTION_COLORS)]:
            mine = dets.filter(
                pc.and_(pc.equal(dets.column("frame_index"), frame),
                        pc.equal(dets.column("algorithm"), algo))
            )  # fmt: skip
            shown[algo] = objects_by_frame(mine).get(frame, ())
        planned: dict[str, FloatArray] = {}
        here = paths.filter(pc.equal(paths.column("frame_index"), frame))
        for (algo, frame_id), rows in group_rows(here, ["algorithm", "frame_id"]).items():
            if frame_id == "base_link":
                planned[algo] = np.column_stack(
                    [column_at(here, "x", rows), column_at(here, "y", rows)]
                ).astype(np.float64)
        png = birds_eye_png(
            ground_truth=gt_objs.get(frame, ()), detections=shown, paths=planned,
            points_xy=clouds.get(frame), title=f"frame {frame}",
        )  # fmt: skip
        caption = h.Markup(f"<b>frame {frame}</b><br>" + "<br>".join(h.esc(line) for line in why))
        out.append(h.figure(png, caption=caption, alt=f"bird's-eye view of frame {frame}"))
    return out


def pr_figures(evaluation: Evaluation) -> list[h.Markup]:
    """A precision/recall figure per metric and algorithm with ``PR/…`` curves (x recall,
    y precision, in point order)."""
    c = evaluation.curves
    pr = c.filter(pc.starts_with(c.column("curve"), "PR/")) if c.num_rows else c
    by_owner: dict[tuple[str, str], list[tuple[str, Any, Any]]] = {}
    for (metric, algo, curve), rows in group_rows(pr, ["metric", "algorithm", "curve"]).items():
        order = rows[np.argsort(column_at(pr, "point", rows), kind="stable")]
        xy = (curve.removeprefix("PR/"), column_at(pr, "x", order), column_at(pr, "y", order))
        by_owner.setdefault((metric, algo), []).append(xy)
    out = []
    for (metric, algo), curves in by_owner.items():
        title = f"{metric} · {algo or 'run'}"
        png = pr_curves_png(curves, title=title)
        out.append(h.figure(png, caption=f"{title}: {len(curves)} curves", alt=title))
    return out


def timeline_figures(evaluation: Evaluation) -> list[h.Markup]:
    """A timeline figure per metric and algorithm with per-frame series; its bookmarked frames
    marked."""
    p, b = evaluation.per_frame, evaluation.bookmarks
    owners: dict[tuple[str, str], list[tuple[str, Any, Any]]] = {}
    for (metric, algo, series), rows in group_rows(p, ["metric", "algorithm", "series"]).items():
        order = rows[np.argsort(column_at(p, "frame_index", rows), kind="stable")]
        item = (series, column_at(p, "frame_index", order), column_at(p, "value", order))
        owners.setdefault((metric, algo), []).append(item)
    marks = group_rows(b, ["metric", "algorithm"])
    again: dict[int, Figure] = {}
    out = []
    for (metric, algo), items in owners.items():
        title = f"{metric} · {algo or 'run'}"
        rows = marks.get((metric, algo), np.zeros(0, dtype=np.int64))
        frames = column_at(b, "frame_index", rows).tolist()
        png = timelines_png(items, title=title, marks=frames, again=again)
        more = len(items) - MAX_TIMELINE_SERIES
        note = f" (first {MAX_TIMELINE_SERIES}; {more} more in report.xlsx)" if more > 0 else ""
        out.append(h.figure(png, caption=f"{title}: {len(items)} series{note}", alt=title))
    return out


def latency_figures(run: Run) -> list[h.Markup]:
    """Latency histograms of the ``steps`` table (every status but ``skipped``), ms."""
    steps = run.table("steps")
    ran = steps.filter(pc.not_equal(steps.column("status"), "skipped"))
    groups = group_rows(ran, ["algorithm"])
    latencies = {
        algo: column_at(ran, "latency_ns", groups[(algo,)]).astype(np.float64) / 1e6
        for algo in algorithm_order(run, [k[0] for k in groups])
    }
    if not latencies:
        return []
    stamps = np.sort(run.table("frames").column("stamp_ns").to_numpy())
    period_ms = float(np.median(np.diff(stamps))) / 1e6 if stamps.size > 1 else 0.0
    png = latency_histograms_png(latencies, deadline_ms=period_ms)
    caption = "step latency per algorithm (steps that ran); lines: p50, p95 (dashed)" + (
        f", frame period {period_ms:.1f} ms (red)" if period_ms > 0 else ""
    )
    return [h.figure(png, caption=caption, alt="latency histograms")]
