"""``redrive report RUN`` — an evaluated run as a self-contained HTML page, Excel and CSV."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive evaluate runs/first && redrive report runs/first     into runs/first/report/
  redrive report runs/first -o out/ --worst 12                 12 bird's-eye snapshots

report.html needs no network (plots are inline PNG images, no JavaScript): open it from disk or
mail it. report.xlsx: sheets summary, per_frame (one column per algorithm / metric / series),
curves, bookmarks, metrics. CSV: values, per_frame, curves, bookmarks. Text cells a spreadsheet
would run as a formula get a leading ' .
"""


def _run(args: argparse.Namespace) -> int:
    from redrive.evaluation.report import write_report

    files = write_report(args.run, out=args.output, worst=args.worst, rank_by=args.rank_by)
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
        help="write an evaluated run's HTML report, Excel workbook and CSV files",
        description=(
            "Write one self-contained HTML page (run facts, headline values per algorithm, "
            "precision/recall curves, per-frame metric timelines, latency histograms, "
            "bird's-eye views of the worst frames, bookmarks), an Excel workbook and CSV files "
            "of a run evaluated with `redrive evaluate`. Prints the files written."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("run", type=Path, metavar="RUN", help="an evaluated run directory")
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
        "--rank-by",
        metavar="METRIC.SERIES",
        help="rank the worst frames by this stored per-frame series (e.g. "
        "nuscenes_detection.missed, clear_mot.switches, latency.frame_ms; larger is worse, "
        "'tp'-like series the other way) instead of the default score: missed objects + false "
        "positives (the detection metric's, at 2 m) + identity switches, per algorithm",
    )
    parser.set_defaults(func=_run)
