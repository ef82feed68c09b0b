"""``python -m benchmarks eval`` — nuScenes detection evaluation, vectorised against a Python loop."""

from __future__ import annotations

import argparse
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner, verdict

__all__ = ["add_eval_parser"]

_DESCRIPTION = """\
Evaluate a synthetic, seeded data set (FRAMES frames x about BOXES ground-truth objects, as many
detections: noisy copies and false positives, tied confidences) under the nuScenes detection
definition twice in the same run: redrive's vectorised implementation and a straightforward
per-frame Python implementation (loops over detections and ground truth). Both must give the same
values; prints seconds per 10k frames and the ratio (target >= 10x).
"""


def _run_eval(args: argparse.Namespace) -> int:
    from benchmarks.eval import TARGET_RATIO, bench_eval

    with spinner() as progress:
        result = bench_eval(
            args.frames, args.boxes, seed=args.seed, repeats=args.repeat, progress=progress
        )
    same = result.max_abs_diff <= 1e-9
    if args.json:
        print_json(result.to_json())
        return 0 if same else 1
    console = report_console()
    console.print(
        f"[bold]data[/] {result.frames:,} frames, {result.gt_objects:,} ground-truth objects, "
        f"{result.detections:,} detections (seed {args.seed}); mAP {result.mean_ap:.4f}"
    )
    console.print(
        f"vectorised {result.vectorised_s:.3f} s (median of {result.repeats}) = "
        f"{result.vectorised_s_per_10k_frames:.3f} s per 10k frames | baseline "
        f"{result.baseline_s:.3f} s = {result.baseline_s_per_10k_frames:.3f} s per 10k frames"
    )
    console.print(
        f"ratio {result.ratio:.1f}x {verdict(result.ratio >= TARGET_RATIO)} {TARGET_RATIO:g}x; "
        f"{result.values_compared} values, largest difference {result.max_abs_diff:.1e} "
        + ("[green]same numbers[/]" if same else "[red]DIFFERENT numbers[/]")
    )
    return 0 if same else 1


def add_eval_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "eval",
        help="detection evaluation (nuScenes): vectorised against a per-frame Python loop",
        description=_DESCRIPTION,
        epilog="examples:\n  python -m benchmarks eval\n  python -m benchmarks eval --frames 1000 --json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--frames", type=int, default=10_000, metavar="N", help="frames (default 10000)"
    )
    parser.add_argument(
        "--boxes", type=int, default=30, metavar="N", help="objects per frame (default 30)"
    )
    parser.add_argument("--seed", type=int, default=0, help="data set seed (default 0)")
    parser.add_argument(
        "--repeat", type=int, default=3, metavar="N", help="vectorised passes (default 3)"
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=_run_eval)
