"""``redrive report BATCH``: an evaluated batch as one self-contained HTML page and a workbook.

``BATCH/report/report.html`` (no network, no JavaScript; plots are inline PNG): the batch's
facts; per pipeline × loop the pooled values (the headline of each metric and algorithm, the
pooling rule, logs and frames); the per-log distribution of each headline (quartiles over the
logs, and a box plot with one box per pipeline × loop); the worst logs of each headline (in the
value's direction); the most severe bookmarked frames of all cells; and every cell with a link to
its own report (``RUN/report/report.html``, written by :func:`redrive.evaluation.report.write_report`
unless told not to).  ``BATCH/report/report.xlsx``: sheets ``pooled``, ``cells`` (every value of
every cell), ``worst_logs``, ``worst_frames``, ``cells_left_out``.
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from redrive.batch.evaluate import BATCH_EVALUATION, read_cell_values, read_pooled
from redrive.batch.manifest import CellStatus, read_batch_manifest
from redrive.errors import ConfigError, RedriveError
from redrive.evaluation import html as h
from redrive.evaluation.pooling import rule_text
from redrive.evaluation.report import write_report
from redrive.output.atomic import write_atomic
from redrive.output.xlsx import Sheet, write_xlsx
from redrive.results.evaluation import read_evaluation

__all__ = ["BatchReportFiles", "write_batch_report"]

logger = logging.getLogger(__name__)

#: logs listed per headline in "worst logs", frames in "worst frames".
WORST_LOGS = 5
WORST_FRAMES = 20


@dataclass(frozen=True, slots=True, kw_only=True)
class BatchReportFiles:
    """What :func:`write_batch_report` wrote."""

    html: Path
    xlsx: Path
    cell_reports: tuple[Path, ...]

    def paths(self) -> tuple[Path, ...]:
        return (self.html, self.xlsx, *self.cell_reports)


#: what the fleet report says above the values of the logged ego (subject ``log``).
LOG_NOTE = (
    "The log's values: these score the logged ego of the open-loop runs (at-fault collisions, "
    "comfort, progress, drivable area, nuPlan's score, the controller's tracking error), the "
    "same whatever the pipeline did — not a result of this pipeline's algorithms."
)


def _fmt(value: Any) -> str:
    return h.fmt_number(value)


def _headlines(pooled: list[dict[str, Any]]) -> list[tuple[str, str, str]]:
    """(metric, algorithm, key) of each metric's headline (its first value), in stored order."""
    seen: dict[tuple[str, str], str] = {}
    for r in pooled:
        seen.setdefault((r["metric"], r["algorithm"]), r["key"])
    return [(m, a, k) for (m, a), k in seen.items()]


def _box_png(title: str, groups: Sequence[tuple[str, list[float]]]) -> bytes:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.5, 0.6 + 0.45 * max(1, len(groups))), layout="constrained")
    ax = fig.add_subplot()
    data = [np.asarray(v, dtype=np.float64) for _, v in groups]
    ax.boxplot(data, orientation="horizontal", showmeans=True)
    for i, values in enumerate(data, start=1):
        ax.plot(values, np.full(values.size, float(i)), "o", markersize=3, alpha=0.5)
    ax.set_yticks(range(1, len(groups) + 1), [g.replace("$", r"\$") for g, _ in groups])
    ax.set_title(title.replace("$", r"\$"), fontsize=10)
    ax.grid(True, axis="x", alpha=0.3)
    return h.png(fig, dpi=100)


def _link(href: str, text: str) -> h.Markup:
    return h.Markup(f'<a href="{h.esc(href)}">{h.esc(text)}</a>')


def write_batch_report(
    batch_dir: Path,
    *,
    out: Path | None = None,
    cell_reports: bool = True,
    worst: int = 6,
) -> BatchReportFiles:
    """Write the fleet report of the evaluated batch in ``batch_dir`` into ``out`` (default
    ``BATCH/report/``); with ``cell_reports`` also each evaluated cell's own report (``worst``
    bird's-eye snapshots each).

    Raises:
        ConfigError: not a batch, or not evaluated (``redrive evaluate BATCH`` first).
    """
    manifest = read_batch_manifest(batch_dir)
    pooled = read_pooled(batch_dir).to_pylist()
    cells = read_cell_values(batch_dir).to_pylist()
    folder = out if out is not None else batch_dir / "report"
    folder.mkdir(parents=True, exist_ok=True)
    by_id = {c.cell_id: c for c in manifest.cells}
    evaluated = sorted({(r["pipeline"], r["loop"], r["log"]) for r in cells})
    written: list[Path] = []
    links: dict[tuple[str, str, str], str] = {}
    frames_rows: list[list[Any]] = []
    for pipeline, loop, log in evaluated:
        cell = by_id.get(f"{pipeline}/{loop}/{log}")
        if cell is None:
            continue
        run_dir = batch_dir / cell.run_dir
        target = run_dir / "report" / "report.html"
        if cell_reports:
            try:
                target = write_report(run_dir, worst=worst).html
                written.append(target)
            except RedriveError as err:  # a cell whose report cannot be written: said, not fatal
                logger.warning("report of cell %s: %s", cell.cell_id, err)
        if target.is_file():
            links[(pipeline, loop, log)] = os.path.relpath(target, folder)
        try:
            marks = read_evaluation(run_dir).bookmarks
        except ConfigError:
            continue
        for m in marks.slice(0, WORST_FRAMES).to_pylist():
            frames_rows.append([
                m["severity"], pipeline, loop, log, m["frame_index"], m["kind"], m["metric"],
                m["algorithm"], m["detail"],
            ])  # fmt: skip
    frames_rows.sort(key=lambda r: -float(r[0]) if math.isfinite(r[0]) else math.inf)
    frames_rows = frames_rows[:WORST_FRAMES]

    groups = sorted({(r["pipeline"], r["loop"]) for r in pooled})
    heads = _headlines(pooled)
    body: list[h.Markup] = []
    counts = {s.value: sum(c.status is s for c in manifest.cells) for s in CellStatus}
    facts = [
        ("batch", str(batch_dir)),
        ("status", manifest.status),
        ("cells", ", ".join(f"{n} {s}" for s, n in counts.items() if n)),
        ("pipelines × loops", ", ".join(f"{p}/{lp}" for p, lp in groups)),
        ("logs evaluated", str(len({log for _, _, log in evaluated}))),
        ("redrive", manifest.redrive_version),
    ]
    body.append(h.section("facts", "Batch", h.table(None, facts)))

    pooled_parts: list[h.Markup] = []
    for pipeline, loop in groups:
        mine = [
            r for r in pooled
            if (r["pipeline"], r["loop"]) == (pipeline, loop)
            and (r["metric"], r["algorithm"], r["key"]) in heads
        ]  # fmt: skip
        pooled_parts.append(h.Markup(f"<h3>{h.esc(pipeline)} ({h.esc(loop)} loop)</h3>"))
        for of_log in (False, True):
            rows = [
                [r["algorithm"] or ("(log)" if of_log else "(run)"), r["metric"], r["key"],
                 _fmt(r["value"]), r["unit"], r["logs"], r["frames"], r["rule"]]
                for r in mine
                if (r.get("subject") == "log") == of_log
            ]  # fmt: skip
            if not rows:
                continue
            if of_log:
                pooled_parts.append(h.paragraph(LOG_NOTE, class_="muted"))
            pooled_parts.append(
                h.table(
                    ["algorithm", "metric", "headline", "pooled", "unit", "logs", "frames",
                     "rule"],
                    rows,
                    numeric=(3, 5, 6),
                )
            )  # fmt: skip
    rules = sorted({r["rule"] for r in pooled})
    pooled_parts.append(
        h.paragraph("; ".join(f"{r}: {rule_text(r)}" for r in rules), class_="muted")
    )
    body.append(h.section("pooled", "Pooled values per pipeline", *pooled_parts))

    dist_parts: list[h.Markup] = []
    worst_parts: list[h.Markup] = []
    worst_rows: list[list[Any]] = []
    for metric, algo, key in heads:
        sel = [r for r in cells if (r["metric"], r["algorithm"], r["key"]) == (metric, algo, key)]
        if not sel:
            continue
        label = f"{metric}.{key}" + (f" [{algo}]" if algo else "")
        if any(r.get("subject") == "log" for r in sel):
            label += " (the log's: logged ego)"
        stats, box = [], []
        for pipeline, loop in groups:
            vals = [
                float(r["value"])
                for r in sel
                if (r["pipeline"], r["loop"]) == (pipeline, loop) and math.isfinite(r["value"])
            ]
            if not vals:
                continue
            q = np.percentile(vals, [0, 25, 50, 75, 100])
            stats.append([f"{pipeline}/{loop}", len(vals), *(_fmt(float(x)) for x in q)])
            box.append((f"{pipeline}/{loop}", vals))
        if not box:
            continue
        dist_parts.append(h.Markup(f"<h3>{h.esc(label)}</h3>"))
        dist_parts.append(
            h.table(
                ["pipeline/loop", "logs", "min", "p25", "median", "p75", "max"],
                stats,
                numeric=(1, 2, 3, 4, 5, 6),
            )
        )
        dist_parts.append(h.img(_box_png(label, box), alt=f"{label} per log"))
        hib = sel[0]["higher_is_better"]
        if hib is None:
            continue
        ranked = sorted(
            (r for r in sel if math.isfinite(r["value"])),
            key=lambda r: r["value"] if hib else -r["value"],
        )[:WORST_LOGS]
        rows = []
        for r in ranked:
            where = (r["pipeline"], r["loop"], r["log"])
            href = links.get(where)
            name = _link(href, r["log"]) if href else h.esc(r["log"])
            rows.append([name, f"{r['pipeline']}/{r['loop']}", _fmt(r["value"]), r["frames"]])
            worst_rows.append([label, *where, r["value"], r["frames"]])
        direction = "lowest" if hib else "highest"
        worst_parts.append(h.Markup(f"<h3>{h.esc(label)} ({direction} first)</h3>"))
        worst_parts.append(
            h.table(["log", "pipeline/loop", "value", "frames"], rows, numeric=(2, 3))
        )
    body.append(h.section("distribution", "Per-log distribution of the headlines", *dist_parts))
    body.append(h.section("worst-logs", "Worst logs", *worst_parts))

    frame_table = [
        [_fmt(float(r[0])), f"{r[1]}/{r[2]}",
         _link(links[(r[1], r[2], r[3])], r[3]) if (r[1], r[2], r[3]) in links else r[3],
         r[4], r[5], r[6], r[7] or "(run)", r[8]]
        for r in frames_rows
    ]  # fmt: skip
    body.append(
        h.section(
            "worst-frames",
            "Worst frames (most severe bookmarks of all cells)",
            h.table(
                [
                    "severity",
                    "pipeline/loop",
                    "log",
                    "frame",
                    "kind",
                    "metric",
                    "algorithm",
                    "detail",
                ],
                frame_table,
                numeric=(0, 3),
            )
            if frame_table
            else h.paragraph("No bookmarked frame in any cell.", class_="muted"),
        )
    )

    left = [c for c in manifest.cells if (c.pipeline, c.loop, c.log_id) not in set(evaluated)]
    cell_rows = [
        [f"{p}/{lp}", _link(links[(p, lp, log)], log) if (p, lp, log) in links else log,
         by_id[f"{p}/{lp}/{log}"].frames if f"{p}/{lp}/{log}" in by_id else "", "evaluated"]
        for p, lp, log in evaluated
    ] + [[f"{c.pipeline}/{c.loop}", c.log_id, c.frames or "", f"{c.status.value}: {c.error or ''}"]
         for c in left]  # fmt: skip
    body.append(
        h.section(
            "cells",
            "Cells (links: each cell's own report)",
            h.table(["pipeline/loop", "log", "frames", "evaluation"], cell_rows, numeric=(2,)),
        )
    )
    page = h.page(
        title=f"redrive fleet report — {batch_dir.name}",
        subtitle=f"{len(evaluated)} cells evaluated; {batch_dir / BATCH_EVALUATION}",
        nav=[
            ("facts", "batch"),
            ("pooled", "pooled"),
            ("distribution", "per-log distribution"),
            ("worst-logs", "worst logs"),
            ("worst-frames", "worst frames"),
            ("cells", "cells"),
        ],
        body=h.Markup("".join(body)),
    )
    html_path = folder / "report.html"
    write_atomic(html_path, page)

    def rows_of(items: list[dict[str, Any]]) -> Iterator[list[Any]]:
        if items:
            yield list(items[0])
        for r in items:
            yield list(r.values())

    xlsx_path = folder / "report.xlsx"
    sheets: dict[str, Callable[[], Iterator[list[Any]]]] = {
            "pooled": lambda: rows_of(pooled),
            "cells": lambda: rows_of(cells),
            "worst_logs": lambda: iter(
                [["headline", "pipeline", "loop", "log", "value", "frames"], *worst_rows]
            ),
            "worst_frames": lambda: iter(
                [
                    [
                        "severity",
                        "pipeline",
                        "loop",
                        "log",
                        "frame",
                        "kind",
                        "metric",
                        "algorithm",
                        "detail",
                    ],
                    *frames_rows,
                ]
            ),
            "cells_left_out": lambda: iter(
                [
                    ["cell", "status", "error"],
                    *([c.cell_id, c.status.value, c.error or ""] for c in left),
                ]
            ),
        }  # fmt: skip
    write_xlsx(xlsx_path, [Sheet(name=name, rows=rows) for name, rows in sheets.items()])
    return BatchReportFiles(html=html_path, xlsx=xlsx_path, cell_reports=tuple(written))
