"""``redrive report RUN`` — an evaluated run as a self-contained HTML page, Excel and CSV;
``redrive report BATCH`` — the fleet report of an evaluated batch."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive evaluate runs/first && redrive report runs/first     into runs/first/report/
  redrive report runs/first -o out/ --worst 12                 12 bird's-eye snapshots
  redrive report runs/closed --beside runs/open                open loop beside closed loop

report.html needs no network (plots are inline PNG images, no JavaScript): open it from disk or
mail it. report.xlsx: sheets summary (one tidy table: a row per value), run, algorithms,
per_frame (one column per algorithm / metric / series), curves, bookmarks, metrics (and beside
with --beside). CSV: values, per_frame, curves, bookmarks. Text cells a spreadsheet
would run as a formula get a leading ' .

--beside OTHER adds another evaluated run of the same log or situation next to RUN: above all
an open-loop run of a `redrive synth` log beside a closed-loop run of its scenario (same name,
seed, duration; either way round). The page gets a section with both runs' values (— where a
run has none), which is open and which closed loop, and whether the pipelines differ; the
workbook a sheet `beside`; and beside.csv. The pairing is `redrive compare`'s.

A batch (evaluated with `redrive evaluate BATCH`):
  redrive report batches/ab                       into batches/ab/report/ (+ each cell's report)
  redrive report batches/ab --no-cell-reports     the fleet page and workbook only
The fleet report: the pooled values per pipeline, the per-log distribution of each headline
(quartiles and a box plot), the worst logs and the worst frames of all cells, and every cell
linked to its own report. report.xlsx: pooled, cells, worst_logs, worst_frames, cells_left_out.
"""


def _run(args: argparse.Namespace) -> int:
    from redrive.batch.manifest import BATCH_MANIFEST
    from redrive.evaluation.report import write_report

    if (args.run / BATCH_MANIFEST).is_file():
        from redrive.batch.report import write_batch_report

        fleet = write_batch_report(
            args.run, out=args.output, cell_reports=not args.no_cell_reports, worst=args.worst
        )
        print(fleet.html)
        print(fleet.xlsx)
        print(f"{len(fleet.cell_reports)} cell reports (RUN/report/ of each cell)")
        return 0

    files = write_report(
        args.run, out=args.output, worst=args.worst, beside=args.beside, rank_by=args.rank_by
    )
    for path in files.paths():
        print(path)
    return 0


def _count(text: str) -> int:
    value = int(text)
    if value < 0:
        msg = f"expected 0 or more, got {value}"
        raise argparse.ArgumentTypeError(msg)
    return value


#: = redrive.evaluation.report.DEFAULT_WORST (not imported here: it loads matplotlib, and every
#: ``redrive`` command registers its parser).
DEFAULT_WORST = 6


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "report",
        help="write an evaluated run's (or batch's) HTML report, Excel workbook and CSV files",
        description=(
            "Write one self-contained HTML page (run facts, headline values per algorithm, "
            "precision/recall curves, per-frame metric timelines, latency histograms, "
            "bird's-eye views of the worst frames, bookmarks), an Excel workbook and CSV files "
            "of a run evaluated with `redrive evaluate`. Prints the files written."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "run", type=Path, metavar="RUN", help="an evaluated run (or batch) directory"
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        default=None,
        metavar="DIR",
        help="directory to write into (created; default: RUN/report/)",
    )
    parser.add_argument(
        "--worst",
        type=_count,
        default=DEFAULT_WORST,
        metavar="N",
        help=f"bird's-eye snapshots of the N worst frames (default {DEFAULT_WORST})",
    )
    parser.add_argument(
        "--beside",
        type=Path,
        default=None,
        metavar="OTHER",
        help=(
            "another evaluated run of the same log or scenario (e.g. the open-loop run beside "
            "a closed-loop RUN) shown side by side in the page, the workbook and beside.csv"
        ),
    )
    parser.add_argument(
        "--rank-by",
        metavar="METRIC.SERIES",
        help="rank the worst frames by this stored per-frame series (e.g. "
        "nuscenes_detection.missed, clear_mot.switches, latency.frame_ms; larger is worse, "
        "'tp'-like series the other way) instead of the default score: missed objects + false "
        "positives (the detection metric's, at 2 m) + identity switches, per algorithm",
    )
    parser.add_argument(
        "--no-cell-reports",
        action="store_true",
        help="a batch: do not write each cell's own report (the fleet report links those there)",
    )
    parser.set_defaults(func=_run)
