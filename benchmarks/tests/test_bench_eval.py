"""python -m benchmarks eval: both implementations agree on a tiny data set; the CLI module prints."""

from __future__ import annotations

import argparse
import json
import math

import pytest

from benchmarks.cli.eval import add_eval_parser
from benchmarks.eval import baseline_nuscenes, bench_eval, synthetic_detections
from redrive.evaluation.detection import evaluate_nuscenes
from redrive.evaluation.detection.classes import NUSCENES_CLASS_RANGE_M, NUSCENES_CLASSES


def test_same_numbers_on_a_small_set() -> None:
    gt, pred = synthetic_detections(60, 12, seed=3)
    fast = evaluate_nuscenes(
        gt, pred, class_map=NUSCENES_CLASSES, class_range_m=NUSCENES_CLASS_RANGE_M
    ).values
    slow = baseline_nuscenes(gt, pred)
    assert len(slow) > 50
    for key, ref in slow.items():
        if math.isnan(ref):
            assert math.isnan(fast[key]), key
        else:
            assert fast[key] == pytest.approx(ref, abs=1e-12), key
    assert 0.2 < fast["mAP"] < 0.9  # a non-trivial data set


def test_bench_result() -> None:
    r = bench_eval(40, 10, repeats=1)
    assert r.max_abs_diff <= 1e-12
    assert r.frames == 40
    assert r.vectorised_s > 0
    assert r.baseline_s > 0
    assert set(r.to_json()) >= {"ratio", "vectorised_s_per_10k_frames", "max_abs_diff"}


def test_cli(capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser()
    add_eval_parser(parser.add_subparsers())
    args = parser.parse_args(["eval", "--frames", "30", "--boxes", "8", "--repeat", "1", "--json"])
    assert args.func(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frames"] == 30
    assert out["max_abs_diff"] <= 1e-12
    args = parser.parse_args(["eval", "--frames", "30", "--boxes", "8", "--repeat", "1"])
    assert args.func(args) == 0
    assert "ratio" in capsys.readouterr().out
