"""evaluate_run: metrics on the algorithms of their role, stored with the run, skips explained."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.cli.main import main
from redrive.errors import ConfigError
from redrive.evaluation import Bookmark, EvalData, Metric, MetricResult
from redrive.evaluation.evaluator import evaluate_run
from redrive.evaluation.store import read_evaluation
from redrive.results import RunWriter, open_run
from tests.results._records import MANIFEST, frame


class ObjectCount(Metric):
    """Objects per frame; bookmarks frames with none."""

    name = "object_count"
    role = "perception"
    needs = frozenset({"detections"})
    unit = "objects"
    defaults: Mapping[str, Any] = {"scale": 1.0}

    def evaluate(self, data: EvalData) -> MetricResult:
        per = data.detections()
        frames = np.array(sorted(per), dtype=np.int64)
        counts = np.array([len(per[int(i)]) for i in frames], dtype=np.float64)
        counts *= self.params["scale"]
        marks = [
            Bookmark(frame_index=int(i), kind="empty")
            for i, c in zip(frames, counts, strict=True)
            if c == 0
        ]
        return MetricResult(
            values={
                "mean": float(counts.mean()) if counts.size else float("nan"),
                "frames": len(frames),
            },
            units={"frames": "frames"},
            per_frame={"objects": (frames, counts)},
            curves={"cumulative": (frames.astype(np.float64), np.cumsum(counts))},
            bookmarks=marks,
        )


class NeedsTruth(Metric):
    """Needs ground truth."""

    name = "needs_truth"
    role = "run"
    needs = frozenset({"ground_truth"})

    def evaluate(self, data: EvalData) -> MetricResult:
        return MetricResult(values={"gt_frames": len(data.ground_truth())})


class Refuses(Metric):
    """Always refuses (like a tracking metric on a detector without ids)."""

    name = "refuses"
    role = "planning"

    def evaluate(self, data: EvalData) -> MetricResult:
        raise ConfigError(f"{data.algorithm} has no track ids")


@pytest.fixture
def run_dir(tmp_path: Path) -> Path:
    path = tmp_path / "run"
    with RunWriter(path, manifest=MANIFEST) as writer:
        for i in range(6):
            writer.write_frame(frame(i))
    return path


def test_metrics_are_stored_with_the_run(run_dir: Path) -> None:
    summary = evaluate_run(run_dir, metrics=[ObjectCount(scale=2.0), NeedsTruth(), Refuses()])
    assert [(s.metric.name, s.algorithm) for s in summary.scored] == [
        ("object_count", "det"),
        ("object_count", "bad_det"),
        ("needs_truth", ""),
    ]
    assert [(s.metric, s.algorithm, s.reason) for s in summary.skipped] == [
        ("refuses", "planner", "planner has no track ids")
    ]
    ev = read_evaluation(open_run(run_dir))
    det = summary.scored[0].result
    assert ev.value("object_count", "mean", algorithm="det") == pytest.approx(det.values["mean"])
    rows = [r for r in ev.per_frame.to_pylist() if r["algorithm"] == "det"]
    assert [r["value"] for r in rows] == list(det.per_frame["objects"][1])
    assert ev.curves.num_rows == sum(
        len(s.result.curves.get("cumulative", ((), ()))[0]) for s in summary.scored
    )
    units = {(r["key"], r["unit"]) for r in ev.values.to_pylist() if r["metric"] == "object_count"}
    assert units == {("mean", "objects"), ("frames", "frames")}
    manifest = json.loads((run_dir / "manifest.json").read_text())
    described = {m["name"]: m for m in manifest["evaluation"]["metrics"]}
    assert described["object_count"]["params"] == {"scale": 2.0}
    assert described["object_count"]["algorithms"] == ["det", "bad_det"]
    assert len(described["object_count"]["params_hash"]) == 64


def test_evaluating_again_replaces_the_evaluation(run_dir: Path) -> None:
    evaluate_run(run_dir, metrics=[ObjectCount()])
    evaluate_run(run_dir, metrics=[NeedsTruth()])
    ev = read_evaluation(open_run(run_dir))
    assert set(ev.values.column("metric").to_pylist()) == {"needs_truth"}
    assert ev.per_frame.num_rows == 0


def test_unknown_parameters_and_algorithms_are_refused(run_dir: Path) -> None:
    with pytest.raises(ConfigError, match=r"unknown parameter.*colour"):
        ObjectCount(colour=1)
    with pytest.raises(ConfigError, match="no algorithm nope"):
        evaluate_run(run_dir, metrics=[ObjectCount()], algorithms=["nope"])


def test_an_unevaluated_run_says_what_to_do(run_dir: Path) -> None:
    with pytest.raises(ConfigError, match="redrive evaluate"):
        read_evaluation(open_run(run_dir))


def test_cli_evaluate_with_a_module_metric(
    run_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    status = main(
        ["evaluate", str(run_dir), "--metric", "tests.evaluation.test_evaluator:ObjectCount"]
    )
    assert status == 0
    out = capsys.readouterr().out
    assert "object_count" in out
    assert "bookmarked" in out


def test_metric_plugins_by_entry_point_or_module() -> None:
    from redrive.errors import PluginError
    from redrive.evaluation.registry import installed_metrics, load_metric_class

    installed = installed_metrics()
    assert {
        "nuscenes_detection",
        "kitti_detection",
        "object_attributes",
        "clear_mot",
        "hota",
        "planning",
        "control",
        "latency",
    } <= set(installed)
    for name, cls in installed.items():
        assert cls.name == name  # the entry-point name is the metric's own
    assert load_metric_class("hota") is installed["hota"]
    assert load_metric_class("tests.evaluation.test_evaluator:ObjectCount") is ObjectCount
    with pytest.raises(PluginError, match="no metric named 'nope'"):
        load_metric_class("nope")
    with pytest.raises(PluginError, match=r"not a redrive\.evaluation\.Metric"):
        load_metric_class("tests.evaluation.test_evaluator:MANIFEST")
    with pytest.raises(PluginError, match="cannot import"):
        load_metric_class("no.such.module:X")


def test_metric_from_a_file(tmp_path: Path) -> None:
    from redrive.errors import PluginError
    from redrive.evaluation.registry import load_metric_class

    source = tmp_path / "my_metrics.py"
    source.write_text(
        "from redrive.evaluation import Metric, MetricResult\n"
        "class Frames(Metric):\n"
        "    name = 'frames'\n"
        "    role = 'run'\n"
        "    def evaluate(self, data):\n"
        "        return MetricResult(values={'n': data.frames().num_rows})\n",
        encoding="utf-8",
    )
    cls = load_metric_class(f"{source}:Frames")
    assert cls.name == "frames"
    assert load_metric_class(f"{source}:Frames") is cls  # imported once
    with pytest.raises(PluginError, match="no file"):
        load_metric_class(f"{tmp_path / 'nope.py'}:Frames")
    broken = tmp_path / "broken.py"
    broken.write_text("raise RuntimeError('half-written')\n", encoding="utf-8")
    with pytest.raises(PluginError, match="RuntimeError: half-written"):
        load_metric_class(f"{broken}:X")
