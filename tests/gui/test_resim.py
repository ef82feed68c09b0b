"""The Re-simulation panel on the synthetic demo log: run, cancel, errors, views, A/B, exports."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyqtgraph")

import numpy as np
import openpyxl
import pyarrow.csv as pacsv

from redrive.engine import RunRequest, run_log
from redrive.evaluation.evaluator import evaluate_run
from redrive.geometry.boxes import box_corners
from redrive.gui.resim import ResimPanel
from redrive.gui.resim_views import (
    TopDownView,
    algorithm_test_pipeline,
    box_outline_segments,
    shown_algorithms,
)
from redrive.results import AlgorithmEntry, RunSetup, RunStatus, SourceLog, open_run
from redrive.types import Box3D, DetectedObject, ObjectClass, Role

RUN_TIMEOUT_MS = 60_000

SLOW = '''
import time
from redrive.algorithms import Algorithm, Role
from redrive.types import SensorType

class SlowDetector(Algorithm):
    """Finds nothing, slowly."""
    role = Role.PERCEPTION
    inputs = (SensorType.LIDAR,)

    def step(self, frame, upstream):
        time.sleep(0.05)
        return []

class CrashingDetector(Algorithm):
    """Raises on every frame."""
    role = Role.PERCEPTION
    inputs = (SensorType.LIDAR,)

    def step(self, frame, upstream):
        raise RuntimeError(f"planned crash on frame {frame.index}")
'''


@pytest.fixture(scope="module")
def plugins(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("plugins") / "gui_plugins.py"
    path.write_text(SLOW)
    return path


@pytest.fixture(scope="module")
def two_runs(demo_log: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A: the reference detector over the whole log, evaluated; B: the noisy oracle over frames
    0–49 only (so frames 50–99 are missing from B)."""
    base = tmp_path_factory.mktemp("ab")
    runs = []
    for spec, stop in (("cluster-detector", None), ("noisy-oracle", 50)):
        pipeline, _ = algorithm_test_pipeline("perception", spec)
        out = base / spec
        run_log(RunRequest(log=demo_log, pipeline=pipeline, out=out, stop_frame=stop))
        runs.append(out)
    evaluate_run(runs[0])
    return runs[0], runs[1]


@pytest.fixture
def panel(qtbot: Any) -> Any:
    widget = ResimPanel()
    qtbot.addWidget(widget)
    widget.resize(1400, 800)
    widget.show()
    qtbot.waitExposed(widget)
    yield widget
    widget.shutdown()


def _points(view: TopDownView, layer: str) -> int:
    x, _ = getattr(view, layer).getData()
    return 0 if x is None else len(x)


def _detections(panel: Any, run: str = "a") -> Any:
    """frame index → the objects of the perception algorithm shown for run ``a`` or ``b``."""
    data, shown = getattr(panel, f"run_{run}"), getattr(panel, f"shown_{run}")
    return data.detections[shown["perception"]]


def _frame_with_both(panel: Any) -> int:
    data, detections = panel.run_a, _detections(panel)
    return next(i for i in data.frames if detections.get(i) and data.ground_truth.get(i))


# -- a whole algorithm test -------------------------------------------------------------------


def test_algorithm_test_runs_evaluates_shows_and_exports(
    panel: Any, qtbot: Any, demo_log: Path, tmp_path: Path
) -> None:
    assert panel.load_log(demo_log)
    assert "urban.mcap" in panel.status_label.text()
    panel.set_algorithm("perception", "cluster-detector")
    out = tmp_path / "run"
    panel.set_output_dir(out)
    with qtbot.waitSignal(panel.run_finished, timeout=RUN_TIMEOUT_MS) as blocker:
        assert panel.start()
        assert panel.is_running()
        assert not panel.test_button.isEnabled()
    assert blocker.args == [out]
    assert panel.progress.value() == 100
    assert not panel.is_running()
    assert panel.test_button.isEnabled()
    assert open_run(out).manifest.status is RunStatus.COMPLETE
    from redrive.results.evaluation import stored_metric_names

    assert stored_metric_names(out)

    # the result and the result over ground truth, for one frame
    index = _frame_with_both(panel)
    panel.set_frame(index)
    n_det = len(_detections(panel)[index])
    n_gt = len(panel.run_a.ground_truth[index])
    assert _points(panel.result_view, "result_boxes") == 10 * n_det  # 5 segments per box
    assert _points(panel.result_view, "gt_boxes") == 0  # the left view: the result only
    assert _points(panel.overlay_view, "result_boxes") == 10 * n_det
    assert _points(panel.overlay_view, "gt_boxes") == 10 * n_gt
    assert f"frame {index}" in panel.frame_label.text()

    # the evaluation summary: headline values of the detector's metrics
    table = panel.summary_table
    rows = [[table.item(r, c).text() for c in range(table.columnCount())] for r in range(table.rowCount())]  # fmt: skip
    metrics = {row[0]: row for row in rows}
    assert "nuscenes_detection" in metrics
    assert metrics["nuscenes_detection"][1] == "mAP"
    assert 0.0 <= float(metrics["nuscenes_detection"][2]) <= 1.0
    assert "latency" in metrics  # the run-level metric

    # exports into a directory given programmatically
    csv_files = panel.export("csv", tmp_path / "csv")
    assert {p.name for p in csv_files} >= {"detections.csv", "ground_truth.csv", "summary.csv"}
    detections = pacsv.read_csv(tmp_path / "csv" / "detections.csv")
    assert detections.num_rows > 0
    [xlsx] = panel.export("xlsx", tmp_path / "xlsx")
    book = openpyxl.load_workbook(xlsx, read_only=True)
    assert "detections" in book.sheetnames
    assert sum(1 for _ in book["detections"].iter_rows()) > 1  # a header and rows
    book.close()


def test_the_two_views_keep_the_same_zoom_and_pan(panel: Any, two_runs: tuple[Path, Path]) -> None:
    assert panel.open_run(two_runs[0])
    left, right = panel.result_view, panel.overlay_view
    left.setRange(xRange=(-5.0, 15.0), yRange=(10.0, 30.0), padding=0.0)

    def centre_and_scale(view: TopDownView) -> tuple[float, float, float]:
        (x0, x1), (y0, y1) = view.viewRange()
        return (x0 + x1) / 2, (y0 + y1) / 2, (y1 - y0) / view.getViewBox().height()

    assert centre_and_scale(right) == pytest.approx(centre_and_scale(left), rel=1e-6)
    right.getViewBox().translateBy(x=4.0)  # a pan in the right view …
    right.getViewBox().sigRangeChangedManually.emit([True, True])  # … as the mouse does
    assert centre_and_scale(left) == pytest.approx(centre_and_scale(right), rel=1e-6)


# -- cancel and errors --------------------------------------------------------------------------


def test_cancel_closes_the_run_as_interrupted_and_the_panel_runs_again(
    panel: Any, qtbot: Any, demo_log: Path, plugins: Path
) -> None:
    panel.load_log(demo_log)
    panel.set_algorithm("perception", f"{plugins}:SlowDetector")  # 100 frames × 50 ms
    panel.start()
    first_out = Path(panel.out_edit.text())
    qtbot.waitUntil(lambda: panel.progress.value() >= 2, timeout=RUN_TIMEOUT_MS)
    with qtbot.waitSignal(panel.run_cancelled, timeout=RUN_TIMEOUT_MS) as blocker:
        panel.cancel()
    assert blocker.args == [first_out]
    manifest = json.loads((first_out / "manifest.json").read_text())
    assert manifest["status"] == "interrupted"
    assert 0 < manifest["frames_done"] < 100
    assert "Cancelled" in panel.status_label.text()
    assert not panel.is_running()
    assert panel.test_button.isEnabled()

    panel.set_algorithm("perception", "noisy-oracle")
    with qtbot.waitSignal(panel.run_finished, timeout=RUN_TIMEOUT_MS) as blocker:
        panel.start()
    assert blocker.args[0] != first_out  # a new automatic run directory
    assert blocker.args[0].parent == demo_log.parent / "runs"
    assert open_run(blocker.args[0]).manifest.status is RunStatus.COMPLETE


def test_a_corrupt_log_is_reported_naming_the_file(
    panel: Any, qtbot: Any, demo_log: Path, tmp_path: Path
) -> None:
    bad = tmp_path / "bad.bag"
    bad.write_bytes(b"\x00garbage\xff" * 100)
    assert not panel.load_log(bad)
    assert str(bad) in panel.status_label.text()
    assert panel.error_box is not None
    assert str(bad) in panel.error_box.text()
    assert not panel.test_button.isEnabled()
    assert not panel.start()  # no log: refused, said
    panel.error_box.close()
    assert panel.load_log(demo_log)  # still usable
    assert panel.test_button.isEnabled()


def test_an_algorithm_that_cannot_be_loaded_fails_the_test_and_says_why(
    panel: Any, qtbot: Any, demo_log: Path, tmp_path: Path
) -> None:
    panel.load_log(demo_log)
    panel.set_algorithm("perception", f"{tmp_path}/missing.py:Nope")
    with qtbot.waitSignal(panel.run_failed, timeout=RUN_TIMEOUT_MS) as blocker:
        panel.start()
    assert "missing.py" in blocker.args[0]
    assert "missing.py" in panel.status_label.text()
    assert panel.error_box is not None
    assert "missing.py" in panel.error_box.text()
    assert not panel.is_running()
    assert panel.test_button.isEnabled()


def test_an_algorithm_that_crashes_on_every_frame_is_reported(
    panel: Any, qtbot: Any, demo_log: Path, plugins: Path
) -> None:
    panel.load_log(demo_log)
    panel.set_algorithm("perception", f"{plugins}:CrashingDetector")
    with qtbot.waitSignal(panel.run_finished, timeout=RUN_TIMEOUT_MS):
        panel.start()  # the engine records every failed step and goes on
    assert "CrashingDetector: 100 failed steps" in panel.status_label.text()
    panel.set_frame(10)
    assert _points(panel.result_view, "result_boxes") == 0


# -- planning and control ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "case", [("planning", "idm-planner", "path_curve"), ("control", "pure-pursuit-pid", None)]
)
def test_planning_and_control_run_behind_the_reference_perception(
    panel: Any, qtbot: Any, demo_log: Path, case: tuple[str, str, str | None]
) -> None:
    category, spec, layer = case
    panel.load_log(demo_log)
    panel.set_algorithm(category, spec)
    with qtbot.waitSignal(panel.run_finished, timeout=RUN_TIMEOUT_MS) as blocker:
        panel.start()
    names = open_run(blocker.args[0]).manifest.names()
    assert names[:2] == ["cluster-detector", "kalman-tracker"]
    assert names[-1] == spec
    assert panel.shown_a == {category: spec}
    panel.set_frame(20)
    if layer is not None:
        assert _points(panel.result_view, layer) > 1
        assert _points(panel.overlay_view, "gt_boxes") > 0
    else:
        assert "throttle" in panel.result_view.command_text.toPlainText()
    assert _points(panel.result_view, "result_boxes") == 0  # only the algorithm under test


# -- A/B ------------------------------------------------------------------------------------------


def test_a_b_views_follow_one_frame_slider(panel: Any, two_runs: tuple[Path, Path]) -> None:
    run_a, run_b = two_runs
    assert panel.open_run(run_a)
    assert panel.summary_table.rowCount() > 0  # A's stored evaluation
    assert panel.overlay_view_b.isHidden()
    assert panel.open_run_b(run_b)
    assert not panel.overlay_view_b.isHidden()
    assert (panel.frame_slider.minimum(), panel.frame_slider.maximum()) == (0, 99)

    seen = []
    for index in (5, 30):
        panel.frame_slider.setValue(index)  # as the user drags it
        a = _points(panel.overlay_view, "result_boxes")
        b = _points(panel.overlay_view_b, "result_boxes")
        assert a == 10 * len(_detections(panel, "a")[index])
        assert b == 10 * len(_detections(panel, "b")[index]) > 0
        assert _points(panel.overlay_view_b, "gt_boxes") > 0
        seen.append((a, b, _points(panel.overlay_view_b, "gt_boxes")))
    assert seen[0] != seen[1]  # both views moved with the slider

    panel.set_frame(70)  # B stops at frame 49: its view is empty
    assert _points(panel.overlay_view, "gt_boxes") > 0
    assert _points(panel.overlay_view_b, "result_boxes") == 0
    assert _points(panel.overlay_view_b, "gt_boxes") == 0
    assert "B: no frame" in panel.frame_label.text()


def test_opening_something_that_is_not_a_run_is_reported(panel: Any, tmp_path: Path) -> None:
    assert not panel.open_run(tmp_path / "nowhere")
    assert "nowhere" in panel.status_label.text()
    assert panel.export("csv", tmp_path / "x") == []  # nothing to export yet


# -- the pieces ---------------------------------------------------------------------------------


def test_box_outlines_are_the_bottom_faces_of_box_corners() -> None:
    objects = [
        DetectedObject(
            object_id=i,
            object_class=ObjectClass.VEHICLE,
            box=Box3D(center=np.array([x, y, 0.5]), size=np.array([4.0, 2.0, 1.5]), yaw_rad=yaw),
        )
        for i, (x, y, yaw) in enumerate([(10.0, 2.0, 0.3), (-5.0, -3.0, -2.0)])
    ]
    h, v = box_outline_segments(objects)
    assert h.shape == v.shape == (20,)
    for k, obj in enumerate(objects):
        corners = box_corners(obj.box)[:4]
        seg = np.column_stack([v, h])[10 * k : 10 * k + 8]  # 4 edges, base_link (x, y)
        for j in range(4):
            assert seg[2 * j] == pytest.approx(corners[j, :2])
            assert seg[2 * j + 1] == pytest.approx(corners[(j + 1) % 4, :2])
        tip = np.array([v[10 * k + 9], h[10 * k + 9]])
        heading = np.array([math.cos(obj.box.yaw_rad), math.sin(obj.box.yaw_rad)])
        assert tip == pytest.approx(obj.box.center[:2] + 2.0 * heading)
    assert [len(a) for a in box_outline_segments([])] == [0, 0]


def test_the_pipelines_put_the_reference_algorithms_upstream() -> None:
    def plugins(category: str, spec: str) -> list[str]:
        pipeline, name = algorithm_test_pipeline(category, spec)
        assert name == pipeline.stages[-1].algorithms[0].name
        return [a.plugin for s in pipeline.stages for a in s.algorithms]

    assert plugins("perception", "cluster-detector") == ["cluster-detector"]
    assert plugins("perception", "kalman-tracker") == ["cluster-detector", "kalman-tracker"]
    assert plugins("planning", "idm-planner") == [
        "cluster-detector", "kalman-tracker", "idm-planner",
    ]  # fmt: skip
    assert plugins("control", "pure-pursuit-pid")[-2:] == ["idm-planner", "pure-pursuit-pid"]

    def entry(name: str, role: Role) -> AlgorithmEntry:
        return AlgorithmEntry(name=name, role=role, version="1", config_hash="h")

    setup = RunSetup(
        log=SourceLog(path="x.mcap", format="mcap", sha256="s"),
        algorithms=(entry("d", Role.PERCEPTION), entry("t", Role.PERCEPTION),
                    entry("p", Role.PLANNING)),
    )  # fmt: skip
    assert shown_algorithms(setup) == {"perception": "t", "planning": "p"}
    assert shown_algorithms(setup, ["d"]) == {"perception": "d"}
