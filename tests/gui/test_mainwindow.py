"""The main window on real logs: open, play, pause, step, scrub; what the planview draws; runs with
bookmarks; corrupt logs; the remembered layout."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyqtgraph")

from PySide6 import QtCore, QtWidgets

from redrive.gui.loader import GT_COLOR
from redrive.gui.mainwindow import MainWindow
from redrive.gui.session import LogSession

_WAIT_MS = 20_000


def qimage_to_array(image: Any) -> np.ndarray:
    image = image.convertToFormat(image.Format.Format_RGB888)
    width, height, stride = image.width(), image.height(), image.bytesPerLine()
    buf = np.frombuffer(image.constBits(), dtype=np.uint8, count=stride * height)
    return buf.reshape(height, stride)[:, : width * 3].reshape(height, width, 3).copy()


def _open(qtbot: Any, win: MainWindow, path: Path) -> None:
    with qtbot.waitSignal(win.frame_shown, timeout=_WAIT_MS):
        win.open_path(path)


def _show(qtbot: Any, win: MainWindow, index: int) -> None:
    with qtbot.waitSignal(win.frame_shown, timeout=_WAIT_MS, check_params_cb=lambda i: i == index):
        win.go_to(index)


def test_open_play_pause_step_scrub(qtbot: Any, window: MainWindow, demo_log: Path) -> None:
    _open(qtbot, window, demo_log)
    assert window.scene is not None
    assert window.scene.index == 0
    assert window.scene.point_count > 10_000
    qtbot.waitUntil(lambda: window.frame_count == 100, timeout=_WAIT_MS)  # indexed: 10 s × 10 Hz

    # Scrub: the slider asks for frame 30 and the views show that frame's data.
    with qtbot.waitSignal(window.frame_shown, timeout=_WAIT_MS, check_params_cb=lambda i: i == 30):
        window.timeline.slider.setValue(30)
    ref = LogSession(demo_log)
    list(ref.index())
    frame30 = ref.frame(30)
    ref.close()
    assert window.scene.stamp_ns == frame30.stamp_ns
    assert "frame 31 / 100" in window.timeline.frame_label.text()  # 1-based, of 100 frames

    # Step over / step back.
    with qtbot.waitSignal(window.frame_shown, timeout=_WAIT_MS, check_params_cb=lambda i: i == 31):
        qtbot.mouseClick(window.timeline.step_over, QtCore.Qt.MouseButton.LeftButton)
    with qtbot.waitSignal(window.frame_shown, timeout=_WAIT_MS, check_params_cb=lambda i: i == 30):
        qtbot.mouseClick(window.timeline.step_back, QtCore.Qt.MouseButton.LeftButton)

    # Play at 2×: frames advance; pause: they stop.
    window.timeline.speed_box.setCurrentIndex(3)
    qtbot.mouseClick(window.timeline.play_button, QtCore.Qt.MouseButton.LeftButton)
    assert window.timeline.playing
    qtbot.waitUntil(lambda: window.scene is not None and window.scene.index >= 40, timeout=_WAIT_MS)
    qtbot.mouseClick(window.timeline.play_button, QtCore.Qt.MouseButton.LeftButton)
    assert not window.timeline.playing
    # the frame asked for before the pause may still be on its way: wait for the loader to be
    # idle and its scene shown (no fixed sleep: a loaded machine is slow), then nothing more
    # may come however long one waits
    qtbot.waitUntil(lambda: not window.loader.busy, timeout=_WAIT_MS)
    qtbot.wait(100)
    stopped_at = window.scene.index
    qtbot.wait(500)
    assert window.scene.index == stopped_at
    assert not window.loader.busy


def _rendered(widget_image: Any) -> np.ndarray:
    return qimage_to_array(widget_image)


def test_planview_draws_the_frame(qtbot: Any, window: MainWindow, demo_log: Path) -> None:
    """3D: the GL framebuffer is not blank; 2D: ground-truth box edges are drawn in their colour
    where the box corners map to on screen."""
    _open(qtbot, window, demo_log)
    _show(qtbot, window, 20)
    qtbot.wait(200)
    img3d = _rendered(window.planview.grab_view())
    background = np.array([16, 16, 20])
    lit = np.any(np.abs(img3d.astype(int) - background) > 30, axis=2)
    assert lit.mean() > 0.02, "the 3D planview is (nearly) blank"

    qtbot.mouseClick(window.planview.convert_button, QtCore.Qt.MouseButton.LeftButton)
    assert window.planview.is_2d
    qtbot.waitUntil(lambda: window.scene.raster is not None, timeout=_WAIT_MS)
    scene = window.scene
    assert scene is not None
    assert scene.raster is not None
    gt = next(layer for layer in scene.layers if layer.name == "ground truth")
    assert len(gt.segments) > 0
    qtbot.wait(200)
    view = window.planview.view2d
    img2d = _rendered(view.grab().toImage())
    vb = view.getPlotItem().getViewBox()
    hits = 0
    tested = 0
    for x, y in gt.segments[0::2, :2]:
        if not (-15 < x < 45 and -25 < y < 25):  # inside the default view
            continue
        tested += 1
        pos = view.mapFromScene(vb.mapViewToScene(QtCore.QPointF(y, x)))
        r, c = pos.y(), pos.x()
        patch = img2d[max(0, r - 2) : r + 3, max(0, c - 2) : c + 3].reshape(-1, 3).astype(int)
        if np.any(np.abs(patch - np.array(GT_COLOR)).sum(axis=1) < 60):
            hits += 1
    assert tested > 0
    assert hits / tested > 0.8, f"GT box corners drawn at {hits} of {tested} projected places"
    # Points too: the raster has coloured cells.
    assert np.count_nonzero(np.any(scene.raster != 24, axis=2)) > 1000


def test_object_visible_layers(qtbot: Any, window: MainWindow, demo_log: Path) -> None:
    from redrive.gui.scene import Layer

    _open(qtbot, window, demo_log)
    assert any(layer.name == "ground truth" for layer in window.scene.layers)
    window.layer_actions[Layer.GROUND_TRUTH].setChecked(False)
    qtbot.waitUntil(
        lambda: all(layer.name != "ground truth" for layer in window.scene.layers),
        timeout=_WAIT_MS,
    )
    assert len(window.scene.points) > 0
    window.layer_actions[Layer.POINTS].setChecked(False)
    qtbot.waitUntil(lambda: len(window.scene.points) == 0, timeout=_WAIT_MS)


@pytest.fixture(scope="module")
def evaluated_run(demo_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from redrive.cli.main import main

    out = tmp_path_factory.mktemp("gui_run") / "run"
    shutil.copytree(demo_run, out)
    assert main(["evaluate", str(out), "--metric", "clear_mot"]) == 0
    return out


def test_run_outputs_and_bookmarks(qtbot: Any, window: MainWindow, evaluated_run: Path) -> None:
    _open(qtbot, window, evaluated_run)
    assert window.run is not None
    names = {layer.name for layer in window.scene.layers}
    assert {"clusters", "tracker", "ground truth", "ego"} <= names
    marks = window.timeline.bookmark_frames
    assert marks, "the evaluation found no failure frame to bookmark"
    qtbot.waitUntil(lambda: window.frame_count == 100, timeout=_WAIT_MS)
    with qtbot.waitSignal(
        window.frame_shown, timeout=_WAIT_MS, check_params_cb=lambda i: i == marks[0]
    ):
        qtbot.mouseClick(window.timeline.next_bookmark, QtCore.Qt.MouseButton.LeftButton)
    assert window.plots.metric_box.count() > 0
    assert window.scene.path is not None  # the planner's path of that frame


def test_corrupt_log_shows_an_error_and_the_window_stays_usable(
    qtbot: Any, window: MainWindow, demo_log: Path, tmp_path: Path
) -> None:
    bad = tmp_path / "broken.bag"
    bad.write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 4)
    window.open_path(bad)
    qtbot.waitUntil(lambda: bool(getattr(window, "last_error", "")), timeout=_WAIT_MS)
    assert "broken.bag" in window.last_error
    dialog = window.findChild(QtWidgets.QMessageBox, "error-dialog")
    assert dialog is not None
    assert dialog.isVisible()
    dialog.close()
    _open(qtbot, window, demo_log)
    assert window.scene is not None


def test_layout_is_remembered(qtbot: Any, tmp_path: Path) -> None:
    ini = str(tmp_path / "layout.ini")
    settings = QtCore.QSettings(ini, QtCore.QSettings.Format.IniFormat)
    first = MainWindow(settings=settings)
    qtbot.addWidget(first)
    first.show()
    first.docks["Plots"].hide()
    first.close()
    settings.sync()
    second = MainWindow(settings=QtCore.QSettings(ini, QtCore.QSettings.Format.IniFormat))
    qtbot.addWidget(second)
    second.show()
    assert not second.docks["Plots"].isVisible()
    assert second.docks["Camera"].isVisible()


def test_camera_shows_boxes_where_their_projection_says(
    qtbot: Any, window: MainWindow, demo_log: Path
) -> None:
    """The camera panel draws each ground-truth box corner at the pixel the log's calibration
    (camera_info + tf_static, read independently here) projects it to."""
    from redrive.assembly.calibration import camera_calibrations
    from redrive.geometry.boxes import box_corners
    from redrive.geometry.projection import project_points
    from redrive.io import open_log

    _open(qtbot, window, demo_log)
    assert window.camera.camera == "camera_front_image_raw"
    _show(qtbot, window, 25)
    qtbot.wait(200)
    shown = window.camera.scene
    assert shown is not None
    assert shown.calibrated
    with open_log(demo_log) as log:
        calib = camera_calibrations(log)["/camera_front/image_raw"]
    ref = LogSession(demo_log)
    frame = ref.frame(0)
    for _ in range(25):
        frame = ref.frame(frame.index + 1)
    ref.close()
    assert frame.stamp_ns == window.scene.stamp_ns
    h, w = shown.image.shape[:2]
    expected = []
    for obj in frame.ground_truth or ():
        uv, depth = project_points(calib.image_from_base(), box_corners(obj.box))
        if np.all(depth > 1.0) and np.all((uv >= 5) & (uv < [w - 5, h - 5])):
            expected.extend(uv.tolist())
    assert expected, "no ground-truth box is fully in view at this frame"
    img = qimage_to_array(window.camera.widget.grab().toImage())
    vb = window.camera.view
    hits = 0
    for u, v in expected:
        pos = window.camera.widget.mapFromScene(vb.mapViewToScene(QtCore.QPointF(u, v)))
        r, c = pos.y(), pos.x()
        patch = img[max(0, r - 2) : r + 3, max(0, c - 2) : c + 3].reshape(-1, 3).astype(int)
        if np.any(np.abs(patch - np.array(GT_COLOR)).sum(axis=1) < 60):
            hits += 1
    assert hits / len(expected) > 0.8, f"{hits} of {len(expected)} projected corners drawn"


def test_topic_picker_on_the_open_log(qtbot: Any, window: MainWindow, demo_log: Path) -> None:
    """File → Topics: the topics moved to "shown" are the sensors drawn."""
    _open(qtbot, window, demo_log)
    picker = window.pick_topics()
    assert picker is not None
    assert "/lidar_top" in picker.shown_topics()
    assert "/camera_front/image_raw" in picker.shown_topics()
    qtbot.mouseClick(picker.clear_button, QtCore.Qt.MouseButton.LeftButton)
    picker.show_topics(["/camera_front/image_raw"])
    qtbot.mouseClick(picker.run_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: window.scene.point_count == 0, timeout=_WAIT_MS)
    assert window.camera.camera == "camera_front_image_raw"
    assert window.camera.scene is not None

    picker = window.pick_topics()
    assert picker.shown_topics() == ["/camera_front/image_raw"]
    qtbot.mouseClick(picker.clear_button, QtCore.Qt.MouseButton.LeftButton)
    picker.show_topics(["/lidar_top"])
    qtbot.mouseClick(picker.run_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: window.scene.point_count > 10_000, timeout=_WAIT_MS)
    assert window.camera.camera is None
    assert window.camera.camera_box.count() == 0


def test_follow_ego_off_keeps_the_world_still(
    qtbot: Any, window: MainWindow, demo_log: Path
) -> None:
    """Following (default): the ego stays at the origin; not following: the world stays put
    and the ego box moves by what the log's ego state says it drove."""
    _open(qtbot, window, demo_log)
    qtbot.mouseClick(window.planview.convert_button, QtCore.Qt.MouseButton.LeftButton)
    _show(qtbot, window, 10)
    qtbot.waitUntil(lambda: window.scene.raster is not None, timeout=_WAIT_MS)
    ego = window.planview.view2d.curves["ego"]
    assert ego.transform().map(QtCore.QPointF(0, 0)) == QtCore.QPointF(0, 0)
    start = window.scene.pose
    assert start is not None
    window.planview.follow_box.setChecked(False)
    _show(qtbot, window, 40)
    end = window.scene.pose
    assert end is not None
    moved = ego.transform().map(QtCore.QPointF(0, 0))  # plot (u, v) = (y, x)
    driven = float(np.hypot(end[0] - start[0], end[1] - start[1]))
    assert driven > 5.0
    assert np.hypot(moved.x(), moved.y()) == pytest.approx(driven, rel=1e-6)
    window.planview.follow_box.setChecked(True)
    qtbot.waitUntil(
        lambda: ego.transform().map(QtCore.QPointF(0, 0)) == QtCore.QPointF(0, 0), timeout=5000
    )


def test_a_sensor_level_closed_loop_run_opens_over_its_rendered_sensors(
    qtbot: Any, window: MainWindow, tmp_path: Path
) -> None:
    from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
    from redrive.config import pipeline_from_plugins

    out = tmp_path / "closed"
    pipeline = pipeline_from_plugins(planning=["idm-planner"])
    run_closed_loop(
        ClosedLoopRequest(
            scenario="cut_in", pipeline=pipeline, out=out, duration_s=1.0, level="sensor"
        )
    )
    _open(qtbot, window, out)
    assert window.summary is not None
    assert window.summary.path == out / "sensors.mcap"
    assert window.run is not None
    assert window.scene is not None
    assert window.scene.point_count > 10_000  # the sweep rendered from the driven ego
    # The run's first frame (0.1 s: after the first sweep) saw the sweep that *ended* then —
    # the recording's first sweep, stamped at its start (0.0 s).  The GUI draws that sweep
    # with that frame's outputs (not the next sweep, which starts at the frame's stamp).
    first = window.run.frames[0]
    path = next(iter(window.run.paths.values()))[first]
    _show(qtbot, window, 0)
    assert window.scene.stamp_ns == window.run.stamps_ns[first] - 100_000_000
    assert window.scene.path is not None
    assert np.array_equal(window.scene.path, path.waypoints[:, :3])  # frame 0's path
    ref = LogSession(out / "sensors.mcap")
    sweep0 = ref.frame(0).sensors["lidar_top"].data
    ref.close()
    assert window.scene.point_count == len(sweep0.xyz)  # the recording's first sweep
    assert {"ground truth", "ego", "logged ego"} <= {layer.name for layer in window.scene.layers}
    # Recording frame k shows run frame k: the next frame's path is the next frame's.
    second = window.run.frames[1]
    _show(qtbot, window, 1)
    assert window.scene.stamp_ns == window.run.stamps_ns[second] - 100_000_000
    assert np.array_equal(
        window.scene.path, next(iter(window.run.paths.values()))[second].waypoints[:, :3]
    )


def test_a_damaged_log_opens_with_its_intact_part(
    qtbot: Any, window: MainWindow, demo_log: Path, tmp_path: Path
) -> None:
    data = demo_log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 3 // 5])  # a recording killed part-way
    _open(qtbot, window, cut)
    assert window.scene is not None
    assert "damaged" in window.damage_label.text()
    assert window.summary is not None
    assert window.summary.damage  # what was skipped, for the Log panel


def test_plots_start_on_a_headline_metric_and_show_constant_series_plainly(
    qtbot: Any, window: MainWindow, evaluated_run: Path
) -> None:
    # issue 35 item 10: the dropdown started on `clear_mot/…/fp`; a constant-zero series was
    # autoscaled to ±1e-3 and labelled "(x0.001)"; rotated y labels of the stacked plots overlapped
    from redrive.gui.plots import first_metric

    keys = [
        ("clear_mot", "tracker", "fp"),
        ("latency", "", "frame_ms"),
        ("planning", "p", "ADE/3s"),
    ]
    assert first_metric(keys) == ("planning", "p", "ADE/3s")
    assert first_metric(keys[:2]) == ("latency", "", "frame_ms")
    assert first_metric(keys[:1]) == ("clear_mot", "tracker", "fp")
    _open(qtbot, window, evaluated_run)
    key = window.plots.metric_box.currentData()
    assert key is not None
    assert window.run is not None
    assert tuple(key) == first_metric(sorted(window.run.per_frame))
    for plot in window.plots.plots.values():
        assert plot.getAxis("left").autoSIPrefix is False
        assert not plot.getAxis("left").labelText  # named by a title instead
        assert plot.titleLabel.text
    # a constant series is shown as ±1 around its value, a varying one autoscaled
    from redrive.gui.plots import _fit_y

    plot = window.plots.plots["metric"]
    plot.clear()
    plot.plot([0.0, 1.0, 2.0], [0.0, 0.0, 0.0])
    _fit_y(plot, [0.0, 0.0, 0.0])
    assert plot.viewRange()[1] == pytest.approx([-1.0, 1.0])
    plot.clear()
    plot.plot([0.0, 1.0, 2.0], [3.0, 5.0, 4.0])
    _fit_y(plot, [3.0, 5.0, 4.0])
    qtbot.waitUntil(lambda: 2.5 < plot.viewRange()[1][0] <= 3.0, timeout=_WAIT_MS)
    assert 5.0 <= plot.viewRange()[1][1] < 5.5


def test_track_ids_label_only_boxes_with_an_id(
    qtbot: Any, window: MainWindow, evaluated_run: Path
) -> None:
    """h-tour: an untracked box (object_id -1, a detector's) carried the label "-1"."""
    import dataclasses

    from redrive.gui.loader import ViewOptions, build_scene
    from redrive.types import Box3D, DetectedObject, Frame

    _open(qtbot, window, evaluated_run)
    run = window.run
    assert run is not None
    at = run.frames[0]
    box = Box3D(center=np.array([5.0, 0.0, 0.8]), size=np.array([4.0, 2.0, 1.6]))
    objects = (DetectedObject(object_id=-1, box=box), DetectedObject(object_id=7, box=box))
    fake = dataclasses.replace(run, detections={"clusters": {at: objects}})
    scene = build_scene(Frame(stamp_ns=run.stamps_ns[at], index=0), ViewOptions(), run=fake)
    labels = [t[0] for layer in scene.layers for t in layer.labels]
    assert labels == ["7"]


def test_an_empty_plot_says_what_it_lacks_and_run_metrics_have_no_empty_segment(
    qtbot: Any,
) -> None:
    """h-tour: plots were drawn empty on logs without the data; the metric picker showed
    "latency /  / frame_ms" for a run-level metric."""
    from redrive.gui.plots import PlotsPanel, metric_label
    from redrive.gui.session import Series

    assert metric_label(("latency", "", "frame_ms")) == "latency / frame_ms"
    assert metric_label(("clear_mot", "tracker", "fp")) == "clear_mot / tracker / fp"
    panel = PlotsPanel()
    qtbot.addWidget(panel)
    panel.set_series(Series(), start_ns=0)
    assert panel.plots["IMU accel"].titleLabel.text == "IMU accel: no IMU in this log"
    assert panel.plots["speed"].titleLabel.text == "speed: no ego state in the log or the run"
    stamps = np.arange(3, dtype=np.int64) * 100_000_000
    panel.set_series(
        Series(speed_mps=(stamps, np.ones(3)), imu_accel=(stamps, np.zeros((3, 3)))), start_ns=0
    )
    assert panel.plots["IMU accel"].titleLabel.text == "IMU accel (m/s²)"
    assert panel.plots["speed"].titleLabel.text == "speed (m/s)"
