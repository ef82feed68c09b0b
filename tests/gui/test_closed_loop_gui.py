"""Closed-loop runs in the main window: an object-level run plays its own frames (driven ego,
ground truth, road map), the logged ego is drawn as a ghost where it was, the timeline's strip
plots the deviation and bookmarks the evaluation's collisions and the threshold crossings, and a
click on a bookmark seeks there."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyqtgraph")

from PySide6 import QtCore

from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.config import load_pipeline
from redrive.evaluation.closedloop import AtFaultCollisions
from redrive.evaluation.evaluator import evaluate_run
from redrive.gui.mainwindow import MainWindow
from redrive.gui.scene import box_edge_segments
from redrive.results import RunStatus, open_run

_WAIT_MS = 20_000


@pytest.fixture(scope="module")
def blind_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A planner blind to the braking lead (25 m/s straight ahead) rear-ends it, at fault; its
    deviation from the scenario's driver passes the threshold; evaluated for collisions."""
    tmp = tmp_path_factory.mktemp("blind")
    toml = tmp / "blind.toml"
    toml.write_text(
        '[[stage]]\nname = "planning"\n[[stage.algorithm]]\nname = "blind"\n'
        'plugin = "tests.closedloop.plugins:Straight"\nconfig = { speed_mps = 25.0 }\n'
    )
    out = tmp / "run"
    request = ClosedLoopRequest(
        scenario="lead_vehicle_hard_brake", pipeline=load_pipeline(toml), out=out, duration_s=8.0
    )
    assert run_closed_loop(request).status is RunStatus.COMPLETE
    summary = evaluate_run(out, metrics=[AtFaultCollisions()])
    assert not summary.failed
    return out


def _open(qtbot: Any, win: MainWindow, path: Path) -> None:
    with qtbot.waitSignal(win.frame_shown, timeout=_WAIT_MS):
        win.open_path(path)


def _show(qtbot: Any, win: MainWindow, index: int) -> None:
    with qtbot.waitSignal(win.frame_shown, timeout=_WAIT_MS, check_params_cb=lambda i: i == index):
        win.go_to(index)


def _layer(win: MainWindow, name: str) -> Any:
    assert win.scene is not None
    found = [layer for layer in win.scene.layers if layer.name == name]
    assert found, f"no layer {name!r} in {[layer.name for layer in win.scene.layers]}"
    return found[0]


def test_an_object_level_run_plays_its_frames_with_the_logged_ego_as_a_ghost(
    qtbot: Any, window: MainWindow, blind_run: Path
) -> None:
    run = open_run(blind_run)
    driven, logged, truth = run.ego(), run.logged_ego(), run.ground_truth()
    _open(qtbot, window, blind_run)
    assert window.summary is not None
    assert window.summary.format == "run"
    assert window.frame_count == len(driven) == 80
    k = 50  # 5 s in: the driven ego is far from the logged one
    _show(qtbot, window, k)
    scene = window.scene
    assert scene is not None
    assert scene.stamp_ns == int(run.table("frames").column("stamp_ns")[k].as_py())
    # The ego drawn is the driven one: the view's pose is its pose.
    d = driven[k]
    assert scene.pose == pytest.approx((d.position[0], d.position[1], d.heading_rad))
    # The ground truth of the frame, in the driven ego's base_link.
    assert np.allclose(_layer(window, "ground truth").segments, box_edge_segments(truth[k]))
    # The ghost: the ego box at the logged pose, seen from the driven ego — its centre at the logged rear axle + 1.4 m ahead along the logged heading.
    ghost = _layer(window, "logged ego")
    assert ghost.alpha < 1.0
    lg = logged[k]
    c, s = math.cos(-d.heading_rad), math.sin(-d.heading_rad)
    dx, dy = lg.position[0] - d.position[0], lg.position[1] - d.position[1]
    dh = lg.heading_rad - d.heading_rad
    expect = np.array([c * dx - s * dy + 1.4 * math.cos(dh), s * dx + c * dy + 1.4 * math.sin(dh)])
    assert np.linalg.norm(expect) > 2.0  # the ghost is visibly elsewhere
    # (the 12 edges: every corner 3 times; the front face's cross comes after them)
    assert ghost.segments[:24, :2].mean(axis=0) == pytest.approx(expect, abs=1e-6)
    # The road map around the driven ego: lane lines at z = 0, within the view's radius.
    road = _layer(window, "map: lane lines")
    assert len(road.segments) > 0
    assert np.all(road.segments[:, 2] == 0.0)
    # Nothing of a sensor: no points; the boxes counted are the scene's (not ghost, map, ego).
    assert scene.point_count == 0
    assert window.planview.status.text() == f"0 points · {len(truth[k])} boxes"


def test_the_timeline_plots_the_deviation_and_bookmarks_collisions_and_crossings(
    qtbot: Any, window: MainWindow, blind_run: Path
) -> None:
    run = open_run(blind_run)
    rows = run.table("closed_loop").to_pylist()
    _open(qtbot, window, blind_run)
    strip = window.timeline.deviation
    assert strip.isVisible()
    t0 = rows[0]["stamp_ns"]
    # One point per frame: the stored deviation (m) and heading difference (°), on seconds.
    xs, ys = strip.distance.getData()
    assert xs == pytest.approx([(r["stamp_ns"] - t0) / 1e9 for r in rows])
    assert ys == pytest.approx([r["deviation_m"] for r in rows])
    _, headings = strip.heading.getData()
    assert headings == pytest.approx([math.degrees(r["deviation_yaw_rad"]) for r in rows])
    assert strip.limit_m.value() == pytest.approx(2.0)
    assert strip.limit_deg.value() == pytest.approx(10.0)
    # Bookmarks: the stored evaluation's collisions, and where `deviated` turns on.
    collisions = [
        r
        for r in pa_rows(blind_run)
        if r["metric"] == "at_fault_collisions" and r["kind"] == "collision"
    ]
    assert collisions, "the blind planner's collision is in the stored evaluation"
    crossings = [
        r["frame_index"]
        for prev, r in zip([None, *rows[:-1]], rows, strict=True)
        if r["deviated"] and not (prev and prev["deviated"])
    ]
    assert crossings
    marks = {(b.kind, b.frame) for b in strip.bookmarks}
    assert marks == {("collision", r["frame_index"]) for r in collisions} | {
        ("deviation", f) for f in crossings
    }
    for b in strip.bookmarks:
        stamp = rows[b.frame]["stamp_ns"]
        assert b.t_s == pytest.approx((stamp - t0) / 1e9)
    # The slider carries them too (the deviation crossings beside the evaluation's bookmarks).
    assert set(crossings) <= set(window.timeline.bookmark_frames)

    # A click on the collision marker seeks to its frame, and the cursor follows.
    hit = next(b for b in strip.bookmarks if b.kind == "collision")
    spot = next(p for p in strip.markers.points() if p.data() == hit.frame)
    vb = strip.getPlotItem().getViewBox()
    where = strip.mapFromScene(vb.mapViewToScene(spot.pos()))
    with qtbot.waitSignal(
        window.frame_shown, timeout=_WAIT_MS, check_params_cb=lambda i: i == hit.frame
    ):
        qtbot.mouseClick(strip.viewport(), QtCore.Qt.MouseButton.LeftButton, pos=where)
    assert window.current == hit.frame
    assert strip.cursor.value() == pytest.approx(hit.t_s)
    # A click on the curve elsewhere seeks to the nearest frame.
    cross = crossings[0]
    t = (rows[cross]["stamp_ns"] - t0) / 1e9
    where = strip.mapFromScene(vb.mapViewToScene(QtCore.QPointF(t, 0.3)))
    with qtbot.waitSignal(
        window.frame_shown, timeout=_WAIT_MS, check_params_cb=lambda i: i == cross
    ):
        qtbot.mouseClick(strip.viewport(), QtCore.Qt.MouseButton.LeftButton, pos=where)


def pa_rows(run_dir: Path) -> list[dict[str, Any]]:
    from redrive.results.evaluation import read_evaluation

    rows: list[dict[str, Any]] = read_evaluation(run_dir).bookmarks.to_pylist()
    return rows


def test_an_object_level_run_plots_the_run_s_ego_and_names_its_box_colours(
    qtbot: Any, window: MainWindow, blind_run: Path
) -> None:
    # issue 35 item 10: an object-level closed-loop run has no log to read speed and yaw rate
    # from, but its `ego` table has them; the legend says what each box colour is
    run = open_run(blind_run)
    driven = run.ego()
    _open(qtbot, window, blind_run)
    qtbot.waitUntil(lambda: window.frame_count == 80, timeout=_WAIT_MS)
    speed_plot = window.plots.plots["speed"]
    curves = [item for item in speed_plot.listDataItems() if item.yData is not None]
    assert curves, "no speed series"
    drawn = np.asarray(curves[0].yData)
    assert len(drawn) == len(driven)
    assert drawn == pytest.approx([driven[i].speed_mps for i in sorted(driven)])
    assert max(drawn) > 20.0  # the blind planner drives at 25 m/s
    assert window.plots.plots["yaw rate"].listDataItems()
    legend = window.planview.legend.text()
    for name in ("ground truth", "ego", "logged ego"):
        assert f"&nbsp;{name}" in legend
    assert "rgb(60,220,90)" in legend  # ground truth's green
