"""``redrive report RUN``: an evaluated run as one self-contained HTML page, an Excel workbook and
CSV files.

The HTML page (``report.html``) needs no network and no JavaScript: CSS is inline and every plot
is a PNG (matplotlib, Agg) inside a ``data:`` URI.  It shows the run's facts (log, hash,
algorithms with versions and config hashes, status, frames, real-time factor), a headline table
per algorithm, precision/recall curves (the ``PR/…`` curves of the evaluation), per-frame metric
timelines, step-latency histograms, bird's-eye views of the worst frames (ranked by
:func:`redrive.evaluation.plots.frame_scores`: missed objects + false positives + identity
switches, or any stored per-frame series with ``rank_by``; without either, the frames with most
missed objects) with ground truth beside the detections, and the bookmarks.  Every string from the run is HTML-escaped.

The workbook (``report.xlsx``, openpyxl write-only) has the sheets ``summary`` (one tidy table:
every value per metric and algorithm with unit, direction, headline flag and definition),
``run`` (the facts), ``algorithms``, ``per_frame`` (one row per frame,
one column per algorithm / metric / series), ``curves``, ``bookmarks`` and ``metrics`` (metric
definitions: versions, parameters, their hash).  CSV files: ``values``, ``per_frame``,
``curves``, ``bookmarks`` as stored.  Text cells that a spreadsheet would run as a formula get a
leading ``'`` (the one XLSX writer, :mod:`redrive.output.xlsx`).

``beside=OTHER`` puts another evaluated run of the same log or situation next to this one — an
open-loop run beside a closed-loop run of the same scenario, seed and pipeline, in either role
(:mod:`redrive.evaluation.beside`): a section of the page, the sheet ``beside`` and
``beside.csv`` with both runs' values, the pairing and how the pipelines differ.

>>> files = write_report("runs/first")     # doctest: +SKIP
>>> files.html                              # doctest: +SKIP
PosixPath('runs/first/report/report.html')
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from redrive.evaluation import html as h
from redrive.evaluation import plots
from redrive.evaluation.beside import REPORT_RESAMPLES, Beside, beside_rows, beside_section
from redrive.evaluation.compare import compare_runs
from redrive.evaluation.store import Evaluation, read_evaluation
from redrive.output.atomic import atomic_path, write_atomic
from redrive.output.xlsx import Sheet, neutralize_cell, write_xlsx
from redrive.results import Run, open_run

__all__ = [
    "DEFAULT_WORST",
    "ReportFiles",
    "load_evaluation",
    "render_html",
    "write_report",
]

logger = logging.getLogger(__name__)

#: bird's-eye snapshots in a report unless told otherwise.
DEFAULT_WORST = 6
#: rows of the bookmarks table in the HTML page (all of them are in the XLSX and CSV).
HTML_MAX_BOOKMARKS = 500


@dataclass(frozen=True, slots=True, kw_only=True)
class ReportFiles:
    """The files :func:`write_report` wrote."""

    html: Path
    xlsx: Path
    csvs: tuple[Path, ...]

    def paths(self) -> tuple[Path, ...]:
        return (self.html, self.xlsx, *self.csvs)


def load_evaluation(run: Run) -> Evaluation:
    """The stored evaluation of ``run`` (``RUN/metrics/*.parquet`` and the manifest).

    Raises:
        ConfigError: the run has not been evaluated (run ``redrive evaluate RUN`` first).
    """
    return read_evaluation(run)


# -- the HTML page -------------------------------------------------------------------------


def _facts(run: Run, evaluation: Evaluation) -> list[tuple[str, Any]]:
    m, s = run.manifest, run.manifest.summary
    return [
        ("run", str(run.path)),
        ("status", m.status.value),
        ("coverage", m.partial_note() or _complete_coverage(m.pipeline)),
        ("log", m.log.path),
        ("log sha256", m.log.sha256 or ""),
        ("log format", m.log.format),
        ("frames", m.frames_done if s is None else s.frames),
        ("late frames", None if s is None else s.late_frames),
        ("real-time factor (× real time)", None if s is None else s.realtime_factor),
        ("frames per second", None if s is None else s.frames_per_s),
        ("log span (s)", None if s is None else s.log_span_s),
        ("pipeline mode", m.pipeline.mode),
        ("created", m.created),
        ("finished", m.finished),
        ("redrive version", m.redrive_version),
        ("evaluated", evaluation.evaluated),
    ]


def _complete_coverage(pipeline: Any) -> str:
    first, stop = pipeline.first_frame, pipeline.stop_frame
    if first is None and stop is None:
        return "the whole log (the run is complete)"
    return f"frames {first or 0}:{'' if stop is None else stop} of the log, as asked (--frames)"


def _shown(value: Any) -> str:
    if value is None:
        return "n/a"
    return h.fmt_number(value) if isinstance(value, float) else str(value)


def _algorithms_table(run: Run) -> h.Markup:
    stats = {r["algorithm"]: r for r in run.summary().to_pylist()}
    rows = []
    for a in run.manifest.algorithms:
        s = stats.get(a.name, {})
        digest = a.config_hash
        short = h.Markup(f'<span class="mono" title="{h.esc(digest)}">{h.esc(digest[:12])}</span>')
        rows.append(
            [a.name, a.role.value, a.stage, a.plugin, a.version, short,
             *(_shown(s.get(k)) for k in ("ok", "error", "timeout", "skipped",
                                          "latency_p50_ms", "latency_p95_ms"))]
        )  # fmt: skip
    head = ["algorithm", "role", "stage", "plugin", "version", "config hash", "ok", "error",
            "timeout", "skipped", "latency p50 (ms)", "latency p95 (ms)"]  # fmt: skip
    return h.table(head, rows, numeric=range(6, 12))


#: the heading of the values of the logged ego (subject ``log``) in the report.
LOG_HEADING = "the log (logged ego of this open-loop run)"
_LOG_NOTE = (
    "These values score the logged ego: in an open-loop run the ego moved as it was recorded, "
    "so they are the same whatever the pipeline did — the log's, not an algorithm's result. A "
    "closed-loop run (redrive run LOG --closed-loop) scores the pipeline's own driving."
)


def _subject_order(run: Run, subjects: Sequence[str]) -> list[str]:
    """The algorithms in pipeline order, then the run as a whole, then the log."""
    algos = plots.algorithm_order(run, [s for s in subjects if s not in ("run", "log")])
    return algos + [s for s in ("run", "log") if s in subjects]


def _headline_tables(run: Run, evaluation: Evaluation) -> list[h.Markup]:
    v = evaluation.values
    by_subject = plots.group_rows(v, ["subject"])
    out = []
    for subject in _subject_order(run, [k[0] for k in by_subject]):
        rows = by_subject[(subject,)]
        heads, every = [], []
        seen: set[str] = set()
        for i in rows:
            r = {name: v.column(name)[int(i)].as_py() for name in v.column_names}
            better = {True: "higher ↑", False: "lower ↓", None: "—"}[r["higher_is_better"]]
            line = [r["metric"], r["key"], h.fmt_number(r["value"]), r["unit"], better]
            every.append(line)
            if r["metric"] not in seen:
                seen.add(r["metric"])
                heads.append(line)
        head = ["metric", "value name", "value", "unit", "better"]
        title = {"run": "(run as a whole)", "log": LOG_HEADING}.get(subject, subject)
        out.append(h.Markup(f"<h3>{h.esc(title)}</h3>"))
        if subject == "log":
            out.append(h.paragraph(_LOG_NOTE, class_="muted"))
        out.append(h.table(head, heads, numeric=[2]))
        out.append(h.details(f"all {len(every)} values", h.table(head, every, numeric=[2])))
    return out


def _metrics_table(evaluation: Evaluation) -> h.Markup:
    rows = [
        [m.get("name", ""), m.get("version", ""), m.get("role", ""), m.get("unit", ""),
         "higher" if m.get("higher_is_better") else "lower",
         json.dumps(m.get("params", {}), sort_keys=True), str(m.get("params_hash", ""))[:12],
         ", ".join(a or "(run)" for a in m.get("algorithms", ()))]
        for m in evaluation.metrics
    ]  # fmt: skip
    head = ["metric", "version", "role", "unit", "better", "parameters", "params hash", "scored"]
    return h.table(head, rows)


def _bookmarks_table(evaluation: Evaluation) -> h.Markup:
    b = evaluation.bookmarks
    rows = [
        [r["frame_index"], r["kind"], r["metric"], r["algorithm"] or "(run)", r["detail"],
         h.fmt_number(r["severity"], digits=3)]
        for r in b.slice(0, HTML_MAX_BOOKMARKS).to_pylist()
    ]  # fmt: skip
    head = ["frame", "kind", "metric", "algorithm", "detail", "severity"]
    note = (
        h.paragraph(
            f"first {HTML_MAX_BOOKMARKS} of {b.num_rows}; all in report.xlsx", class_="muted"
        )
        if b.num_rows > HTML_MAX_BOOKMARKS
        else ""
    )
    return h.Markup(h.table(head, rows, numeric=[0, 5]) + note)


def _grid(items: Sequence[h.Markup], empty: str) -> h.Markup:
    if not items:
        return h.paragraph(empty, class_="muted")
    return h.Markup('<div class="grid">' + "".join(items) + "</div>")


def render_html(
    run: Run,
    evaluation: Evaluation,
    *,
    worst: int = DEFAULT_WORST,
    beside: Beside | None = None,
    rank_by: str | None = None,
) -> str:
    """The report page of ``run`` (see the module docstring), with the run ``beside`` it."""
    facts = h.table(None, [(k, _shown(v)) for k, v in _facts(run, evaluation)])
    snaps = plots.snapshot_figures(
        run, plots.worst_frames(run, evaluation, count=worst, rank_by=rank_by)
    )
    sections = [
        h.section("run", "Run", facts, h.Markup("<h3>Algorithms</h3>"), _algorithms_table(run)),
        h.section("headline", "Headline values", *_headline_tables(run, evaluation),
                  h.details("metric definitions", _metrics_table(evaluation))),
        h.section("pr", "Precision / recall", _grid(plots.pr_figures(evaluation), "no PR curves")),
        h.section("timelines", "Per-frame metrics",
                  _grid(plots.timeline_figures(evaluation), "no per-frame series")),
        h.section("latency", "Latency", _grid(plots.latency_figures(run), "no steps")),
        h.section("worst", "Worst frames (bird's-eye, base_link)",
                  _grid(snaps, "no bookmarks and no missed objects")),
        h.section("bookmarks", f"Bookmarks ({evaluation.bookmarks.num_rows})",
                  _bookmarks_table(evaluation)),
    ]  # fmt: skip
    nav = [("run", "run"), ("headline", "headline"), ("pr", "PR curves"),
           ("timelines", "per-frame"), ("latency", "latency"), ("worst", "worst frames"),
           ("bookmarks", "bookmarks")]  # fmt: skip
    if beside is not None:
        sections.insert(2, beside_section(beside))
        nav.insert(
            2, ("beside", "open/closed loop" if beside.cmp.pairing.open_closed else "beside")
        )
    title = f"redrive report: {run.path.resolve().name}"
    log = run.manifest.log.path
    return h.page(title=title, subtitle=f"log {log}", nav=nav, body=h.Markup("".join(sections)))


# -- XLSX and CSV --------------------------------------------------------------------------


def _rows(table: pa.Table) -> Iterator[list[Any]]:
    yield list(table.column_names)
    for row in table.to_pylist():
        yield list(row.values())


def _wide_per_frame(evaluation: Evaluation, run: Run) -> Iterator[list[Any]]:
    p = evaluation.per_frame
    groups = plots.group_rows(p, ["algorithm", "metric", "series"])
    order = plots.algorithm_order(run, [g[0] for g in groups])
    keys = sorted(groups, key=lambda k: order.index(k[0]))
    frames = np.unique(np.asarray(p.column("frame_index").to_numpy(), dtype=np.int64))
    grid = np.full((frames.size, len(keys)), np.nan)
    for j, key in enumerate(keys):
        rows = groups[key]
        grid[np.searchsorted(frames, plots.column_at(p, "frame_index", rows)), j] = plots.column_at(
            p, "value", rows
        )
    yield ["frame_index", *(" / ".join(x or "(run)" for x in k) for k in keys)]
    for i, frame in enumerate(frames.tolist()):
        yield [frame, *grid[i].tolist()]


#: the summary sheet: one tidy table, a row per stored value.
SUMMARY_COLUMNS = (
    "metric", "algorithm", "value", "number", "unit", "better", "headline", "definition",
    "scores",
)  # fmt: skip


def summary_rows(evaluation: Evaluation) -> Iterator[list[Any]]:
    """The summary sheet's rows after its header: metric, algorithm ("(run)" for run-level
    metrics), the value's name, the number, its unit, which way is better (higher / lower /
    —), whether it is the metric's headline, the definition (version and parameter hash), and
    whose motion or output the value scores (``log``: the logged ego of an open-loop run)."""
    v = evaluation.values
    defs = {m.get("name"): m for m in evaluation.metrics}
    seen: set[tuple[str, str]] = set()
    for r in v.to_pylist():
        key = (r["metric"], r["algorithm"])
        first = key not in seen
        seen.add(key)
        d = defs.get(r["metric"], {})
        definition = f"v{r['metric_version']} params {str(d.get('params_hash', ''))[:12]}"
        better = {True: "higher", False: "lower", None: "—"}[r["higher_is_better"]]
        yield [r["metric"], r["algorithm"] or "(run)", r["key"], r["value"], r["unit"], better,
               first, definition, r["subject"]]  # fmt: skip


def _write_xlsx(path: Path, run: Run, evaluation: Evaluation, beside: Beside | None) -> None:
    algos = [[a.name, a.role.value, a.version, a.config_hash] for a in run.manifest.algorithms]
    metrics = [[m.get("name"), m.get("version"), m.get("role"), m.get("unit"),
                m.get("higher_is_better"), json.dumps(m.get("params", {}), sort_keys=True),
                m.get("params_hash"), ", ".join(m.get("algorithms", ()))]
               for m in evaluation.metrics]  # fmt: skip
    sheets: dict[str, Callable[[], Iterator[list[Any]]]] = {
        "summary": lambda: iter([list(SUMMARY_COLUMNS), *summary_rows(evaluation)]),
        "run": lambda: iter(
            [["fact", "value"],
             *([k, _shown(x) if x is None else x] for k, x in _facts(run, evaluation))]
        ),
        "algorithms": lambda: iter([["algorithm", "role", "version", "config_hash"], *algos]),
        "per_frame": lambda: _wide_per_frame(evaluation, run),
        "curves": lambda: _rows(evaluation.curves),
        "bookmarks": lambda: _rows(evaluation.bookmarks),
        "metrics": lambda: iter([["metric", "version", "role", "unit", "higher_is_better",
                                  "params", "params_hash", "algorithms"], *metrics]),
    }  # fmt: skip
    if beside is not None:
        sheets["beside"] = lambda: beside_rows(beside)
    write_xlsx(path, [Sheet(name=name, rows=rows) for name, rows in sheets.items()])


def _neutralized(table: pa.Table) -> pa.Table:
    """``table`` with formula-like strings quoted (``neutralize_cell`` on each distinct value)."""
    for i, field in enumerate(table.schema):
        if pa.types.is_string(field.type) and table.num_rows:
            enc = table.column(i).combine_chunks().dictionary_encode()
            safe = pa.array([neutralize_cell(s) for s in enc.dictionary.to_pylist()], pa.string())
            col = pa.DictionaryArray.from_arrays(enc.indices, safe).cast(pa.string())
            table = table.set_column(i, field, col)
    return table


def _write_csv(path: Path, table: pa.Table) -> None:
    with atomic_path(path) as tmp:
        pacsv.write_csv(table, tmp)


def write_report(
    run_dir: str | Path,
    *,
    out: str | Path | None = None,
    worst: int = DEFAULT_WORST,
    beside: str | Path | None = None,
    rank_by: str | None = None,
) -> ReportFiles:
    """Write ``report.html``, ``report.xlsx`` and ``values|per_frame|curves|bookmarks.csv`` of
    the evaluated run ``run_dir`` into ``out`` (default ``RUN/report/``, created); ``worst``
    bird's-eye snapshots; ``beside``: another evaluated run of the same log or situation (an
    open-loop run beside a closed-loop one …) shown next to it, plus ``beside.csv``.

    Raises:
        ConfigError: the run (or ``beside``) has not been evaluated (run ``redrive evaluate RUN``
            first), or ``beside`` is not a run of the same log or situation (the message says
            what differs).
    """
    run = open_run(run_dir)
    evaluation = load_evaluation(run)
    other = None
    if beside is not None:
        other = Beside(compare_runs(run, open_run(beside), bootstrap=REPORT_RESAMPLES))
    folder = Path(out) if out is not None else run.path / "report"
    folder.mkdir(parents=True, exist_ok=True)
    page = render_html(run, evaluation, worst=worst, beside=other, rank_by=rank_by)
    html_path = folder / "report.html"
    write_atomic(html_path, page)
    xlsx_path = folder / "report.xlsx"
    _write_xlsx(xlsx_path, run, evaluation, other)
    csvs = []
    for name in ("values", "per_frame", "curves", "bookmarks"):
        path = folder / f"{name}.csv"
        _write_csv(path, _neutralized(getattr(evaluation, name)))
        csvs.append(path)
    if other is not None:
        path = folder / "beside.csv"
        _write_csv(path, _neutralized(other.cmp.to_tables()["values"]))
        csvs.append(path)
    logger.info("report of %s: %s", run.path, folder)
    return ReportFiles(html=html_path, xlsx=xlsx_path, csvs=tuple(csvs))
