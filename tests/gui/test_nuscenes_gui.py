"""The main window on the real nuScenes keyframe: its sweep, six cameras (calibrated) and boxes."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyqtgraph")

from redrive.gui.mainwindow import MainWindow

pytestmark = pytest.mark.shared_data

_WAIT_MS = 20_000


def test_nuscenes_keyframe_opens(qtbot: Any, window: MainWindow, shared_data: Path) -> None:
    path = shared_data / "nuscenes_mmdet3d_demo"
    if not any(path.glob("*.pkl")):
        pytest.skip("nuscenes_mmdet3d_demo is not in ../shared/data")
    with qtbot.waitSignal(window.frame_shown, timeout=_WAIT_MS):
        window.open_path(path)
    scene = window.scene
    assert scene is not None
    assert scene.point_count == 34_688
    layers = {layer.name: layer for layer in scene.layers}
    assert len(layers["ground truth"].segments) == 69 * 28  # BOX_EDGES: 12 edges + the front cross
    qtbot.waitUntil(lambda: window.camera.scene is not None, timeout=_WAIT_MS)
    shown = window.camera.scene
    assert shown.calibrated
    assert shown.image.shape[:2] == (900, 1600)
    assert sum(len(seg) for _, seg in shown.segments.values()) > 0  # boxes projected
    assert not getattr(window, "last_error", "")
