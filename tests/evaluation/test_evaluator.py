"""evaluate_run: metrics on the algorithms of their role, stored with the run, skips explained."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.cli.main import main
from redrive.errors import ConfigError, PluginError
from redrive.evaluation import Bookmark, EvalData, Metric, MetricResult, MetricSkipped
from redrive.evaluation.evaluator import evaluate_run
from redrive.evaluation.store import read_evaluation
from redrive.results import RunWriter, open_run
from redrive.types import Role
from tests.results._records import SETUP, frame


class ObjectCount(Metric):
    """Objects per frame; bookmarks frames with none."""

    name = "object_count"
    role = Role.PERCEPTION
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
    role = None
    needs = frozenset({"ground_truth"})

    def evaluate(self, data: EvalData) -> MetricResult:
        return MetricResult(values={"gt_frames": len(data.ground_truth())})


class Refuses(Metric):
    """Always refuses (like a tracking metric on a detector without ids)."""

    name = "refuses"
    role = Role.PLANNING

    def evaluate(self, data: EvalData) -> MetricResult:
        raise MetricSkipped(f"{data.algorithm} has no track ids")


class Buggy(Metric):
    """A metric with a bug: a ValueError from deep inside (issue 14.2: it was taken as a skip
    and `redrive evaluate` exited 0)."""

    name = "buggy"
    role = Role.PERCEPTION
    needs = frozenset({"detections"})

    def evaluate(self, data: EvalData) -> MetricResult:
        return MetricResult(values={"x": float(np.array([1.0, 2.0]).reshape(3))})


@pytest.fixture
def run_dir(tmp_path: Path) -> Path:
    path = tmp_path / "run"
    with RunWriter(path, setup=SETUP) as writer:
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
    described = {m["name"]: m for m in ev.metrics}
    assert described["object_count"]["params"] == {"scale": 2.0}
    assert described["object_count"]["algorithms"] == ["det", "bad_det"]
    assert len(described["object_count"]["params_hash"]) == 64


def test_adding_a_metric_keeps_the_stored_ones(run_dir: Path) -> None:
    # issue 14.3: `evaluate --metric x.py:M` replaced the whole stored evaluation
    evaluate_run(run_dir, metrics=[ObjectCount()])
    before = read_evaluation(open_run(run_dir))
    evaluate_run(run_dir, metrics=[NeedsTruth()])
    ev = read_evaluation(open_run(run_dir))
    assert set(ev.values.column("metric").to_pylist()) == {"object_count", "needs_truth"}
    kept = [r for r in ev.values.to_pylist() if r["metric"] == "object_count"]
    assert kept == before.values.to_pylist()
    assert ev.per_frame.to_pylist() == before.per_frame.to_pylist()
    assert {m["name"] for m in ev.metrics} == {"object_count", "needs_truth"}


def test_evaluating_a_metric_again_replaces_only_its_rows(run_dir: Path) -> None:
    evaluate_run(run_dir, metrics=[ObjectCount(), NeedsTruth()])
    truth_rows = [
        r for r in read_evaluation(open_run(run_dir)).values.to_pylist()
        if r["metric"] == "needs_truth"
    ]  # fmt: skip
    evaluate_run(run_dir, metrics=[ObjectCount(scale=3.0)])
    ev = read_evaluation(open_run(run_dir))
    assert [r for r in ev.values.to_pylist() if r["metric"] == "needs_truth"] == truth_rows
    counts = [r for r in ev.values.to_pylist() if r["metric"] == "object_count"]
    assert len(counts) == 4  # mean and frames for det and bad_det: not doubled
    assert {m["name"]: m["params"] for m in ev.metrics}["object_count"] == {"scale": 3.0}
    folders = [p for p in (run_dir / "metrics").iterdir() if p.is_dir()]
    assert len(folders) == 2  # the superseded folder is gone


def test_a_store_that_died_half_way_leaves_the_previous_evaluation(
    run_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    evaluate_run(run_dir, metrics=[ObjectCount()])
    before = read_evaluation(open_run(run_dir)).values.to_pylist()
    import redrive.results.evaluation as stored

    def killed(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt  # the process dies while writing the index

    monkeypatch.setattr(stored, "write_json_atomic", killed)
    with pytest.raises(KeyboardInterrupt):
        evaluate_run(run_dir, metrics=[ObjectCount(scale=5.0)])
    monkeypatch.undo()
    assert read_evaluation(open_run(run_dir)).values.to_pylist() == before
    # the next store removes the orphaned folder
    evaluate_run(run_dir, metrics=[NeedsTruth()])
    folders = [p for p in (run_dir / "metrics").iterdir() if p.is_dir()]
    assert len(folders) == 2


def test_a_metric_that_raises_is_an_error_not_a_skip(run_dir: Path) -> None:
    summary = evaluate_run(run_dir, metrics=[Buggy(), ObjectCount()])
    assert summary.skipped == ()
    assert [(f.metric, f.algorithm) for f in summary.failed] == [
        ("buggy", "det"),
        ("buggy", "bad_det"),
    ]
    assert "ValueError" in summary.failed[0].reason
    ev = read_evaluation(open_run(run_dir))
    assert {r["metric"] for r in ev.values.to_pylist()} == {"object_count"}
    failed = {m["name"]: m["failed"] for m in ev.metrics}["buggy"]
    assert [f["algorithm"] for f in failed] == ["det", "bad_det"]


def test_cli_exits_non_zero_when_a_metric_raises(
    run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plugin = tmp_path / "buggy_metric.py"
    plugin.write_text(
        "import numpy as np\n"
        "from redrive.evaluation import Metric, MetricResult\n"
        "from redrive.types import Role\n"
        "class Buggy(Metric):\n"
        "    name = 'buggy'\n"
        "    role = Role.PERCEPTION\n"
        "    def evaluate(self, data):\n"
        "        raise ValueError('index out of range in my metric')\n"
        "class Skips(Metric):\n"
        "    name = 'skips'\n"
        "    role = Role.PERCEPTION\n"
        "    def evaluate(self, data):\n"
        "        from redrive.evaluation import MetricSkipped\n"
        "        raise MetricSkipped('needs lane labels')\n"
    )
    status = main(["evaluate", str(run_dir), "--metric", f"{plugin}:Skips"])
    out = capsys.readouterr().out
    assert status == 0
    assert "skipped skips on det: needs lane labels" in out
    status = main(["evaluate", str(run_dir), "--metric", f"{plugin}:Buggy"])
    out = capsys.readouterr().out
    assert status == 3
    assert "metric buggy on det raised ValueError: index out of range in my metric" in out
    assert "Traceback" not in out


def test_a_missing_need_is_skipped_with_what_provides_it(run_dir: Path) -> None:
    class NeedsPaths(Metric):
        name = "needs_paths"
        role = Role.PERCEPTION
        needs = frozenset({"paths"})

        def evaluate(self, data: EvalData) -> MetricResult:
            raise AssertionError("not called: the need is checked first")

    summary = evaluate_run(run_dir, metrics=[NeedsPaths()])
    assert summary.failed == ()
    reasons = {s.algorithm: s.reason for s in summary.skipped}
    assert "a planning algorithm with at least one successful step" in reasons["det"]


def test_an_unknown_need_is_refused_when_the_class_is_defined() -> None:
    with pytest.raises(PluginError, match="needs lanes not known"):

        class NeedsLanes(Metric):
            name = "lanes"
            role = None
            needs = frozenset({"lanes"})

            def evaluate(self, data: EvalData) -> MetricResult:
                return MetricResult(values={})


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
    with pytest.raises(PluginError, match="no installed metric is named 'nope'"):
        load_metric_class("nope")
    with pytest.raises(
        PluginError,
        match=r"SETUP in module tests.evaluation.test_evaluator is a \w+, not a class",
    ):
        load_metric_class("tests.evaluation.test_evaluator:SETUP")
    with pytest.raises(PluginError, match="module no not found"):
        load_metric_class("no.such.module:X")
    with pytest.raises(PluginError, match="is not a Metric subclass"):
        load_metric_class("tests.evaluation.test_evaluator:Path")


def test_metric_from_a_file(tmp_path: Path) -> None:
    from redrive.errors import PluginError
    from redrive.evaluation.registry import load_metric_class

    source = tmp_path / "my_metrics.py"
    source.write_text(
        "from redrive.evaluation import Metric, MetricResult\n"
        "class Frames(Metric):\n"
        "    name = 'frames'\n"
        "    role = None\n"
        "    def evaluate(self, data):\n"
        "        return MetricResult(values={'n': data.frames().num_rows})\n",
        encoding="utf-8",
    )
    cls = load_metric_class(f"{source}:Frames")
    assert cls.name == "frames"
    assert load_metric_class(f"{source}:Frames") is cls  # imported once
    with pytest.raises(PluginError, match="not found"):
        load_metric_class(f"{tmp_path / 'nope.py'}:Frames")
    broken = tmp_path / "broken.py"
    broken.write_text("raise RuntimeError('half-written')\n", encoding="utf-8")
    with pytest.raises(PluginError, match="RuntimeError: half-written"):
        load_metric_class(f"{broken}:X")
    assert load_metric_class(str(source)) is cls  # a file alone: its one metric class


def test_a_metric_role_is_the_enum_or_none(tmp_path: Path) -> None:
    from redrive.errors import PluginError
    from redrive.evaluation.registry import load_metric_class

    source = tmp_path / "string_role.py"
    source.write_text(
        "from redrive.evaluation import Metric, MetricResult\n"
        "class Old(Metric):\n"
        "    name = 'old'\n"
        "    role = 'perception'\n"
        "    def evaluate(self, data):\n"
        "        return MetricResult(values={})\n",
        encoding="utf-8",
    )
    with pytest.raises(PluginError, match=r"has role 'perception'; use the enum: role = Role"):
        load_metric_class(f"{source}:Old")
