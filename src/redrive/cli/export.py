"""``redrive export RUN --format csv|xlsx|parquet|mcap`` — a run's tables as files for other
tools, or (``mcap``) the run over its log as one MCAP for Foxglove and RViz."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive export runs/urban --format xlsx          one workbook in runs/urban/export/
  redrive export runs/urban --format csv -o out/   one CSV per table plus summary.csv
  redrive export runs/urban --format parquet       each table merged into one Parquet file
  redrive export runs/urban --format mcap          runs/urban/export/urban.mcap: open it in
                                                   Foxglove (layout: docs/foxglove_layout.json)

Only tables with rows are written. In CSV and Excel, text cells that a spreadsheet would run as a
formula (starting with = + - @, tab or CR) get a leading ' ; Excel cells are cut at 32,767
characters and a table longer than 1,048,576 rows continues on sheets "name (2)", "name (3)" ….

mcap (needs `pip install 'redrive[foxglove]'`): the log's own channels as they are (Foxglove and
Lichtblick draw sensor_msgs/PointCloud2, Image and CompressedImage themselves; an MCAP log's
chunks are copied without decoding them) and the run's results at each frame — ground truth,
every perception algorithm's boxes (ids, velocity arrows), planned paths, the ego (and, closed
loop, the logged ego as a ghost), the evaluation's bookmarks — as foxglove.SceneUpdate on
/redrive/… and visualization_msgs/MarkerArray on /redrive/markers/…, placed by
foxglove.FrameTransforms on /redrive/transforms (an open-loop run keeps the log's /tf, a
closed-loop run's ego replaces it).  --sensor-copies adds every LiDAR cloud and camera image
again as foxglove.PointCloud / foxglove.CompressedImage on /foxglove/<topic> (several times
slower, a larger file).  Results sit at the log time of the sample their frame was made from
(a bag's header stamps can be far from its log times; the messages keep the stamps), and a
sensor frame the log does not connect to base_link is placed as the run placed it (--sensor-map
gives the run's sensor map file; without a location: at base_link, with a warning).  See
docs/foxglove.md.
"""


def _export_mcap(args: argparse.Namespace, out: Path) -> int:
    from redrive.interop import require_foxglove

    require_foxglove()
    from redrive.interop.mcap_export import export_mcap

    overrides = None
    if args.sensor_map is not None:
        from redrive.assembly.sensor_map import load_sensor_map_overrides

        overrides = load_sensor_map_overrides(args.sensor_map)
    print(export_mcap(args.run, out=out, sensor_copies=args.sensor_copies, sensor_map=overrides))
    return 0


def _run(args: argparse.Namespace) -> int:
    from redrive.results import export_run, open_run

    run = open_run(args.run)
    out = args.output if args.output is not None else run.path / "export"
    if args.format == "mcap":
        return _export_mcap(args, out)
    if args.sensor_copies or args.sensor_map is not None:
        flag = "--sensor-copies" if args.sensor_copies else "--sensor-map"
        print(f"redrive export: {flag} goes with --format mcap only", file=sys.stderr)
        return 2
    for path in export_run(run, fmt=args.format, out=out):
        print(path)
    return 0


def register(sub: Any) -> None:
    from redrive.results import EXPORT_FORMATS

    parser = sub.add_parser(
        "export",
        help="export a run's tables to CSV, Excel or Parquet, or the run over its log to MCAP",
        description=(
            "Write the tables of a run directory (frames, steps, detections, ground truth, ego, "
            "paths, commands, resources) and the per-algorithm summary as CSV files, one Excel "
            "workbook (a summary sheet with the run's facts, then a sheet per table) or one "
            "Parquet file per table; or, with --format mcap, the run's log and results as one "
            "MCAP that Foxglove and RViz draw. Prints the files written."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("run", type=Path, help="a run directory (the --out of a run)")
    parser.add_argument(
        "--format",
        required=True,
        choices=(*EXPORT_FORMATS, "mcap"),
        help="the file format to write",
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        default=None,
        help="directory to write into (created; default: RUN/export/)",
    )
    parser.add_argument(
        "--sensor-copies",
        action="store_true",
        help=(
            "mcap: also write every LiDAR cloud as foxglove.PointCloud and every camera image as "
            "a JPEG foxglove.CompressedImage on /foxglove/<topic>, for viewers that read only "
            "Foxglove schemas (Foxglove and Lichtblick draw the log's own ROS sensor messages; "
            "the copies make the export several times slower and the file larger)"
        ),
    )
    parser.add_argument(
        "--sensor-map",
        type=Path,
        metavar="TOML",
        help=(
            "mcap: the sensor map file the run was given (`redrive run --sensor-map`): its "
            "driver puts the results at their samples' log times, its sensor locations place "
            "the sensor frames the log does not connect to base_link"
        ),
    )
    parser.set_defaults(func=_run)
