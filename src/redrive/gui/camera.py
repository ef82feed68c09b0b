"""The camera window: one camera (dropdown) with ground-truth and detected boxes projected through
the log's calibration, and optionally the LiDAR points burnt in, coloured by depth."""

from __future__ import annotations

from collections.abc import Sequence

import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from redrive.gui.scene import CameraScene

__all__ = ["CameraView"]


class CameraView(QtWidgets.QWidget):
    """A camera dropdown over an image view (row-major ``ImageItem``, y down like the image)."""

    camera_changed = QtCore.Signal(str)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        bar = QtWidgets.QHBoxLayout()
        bar.addWidget(QtWidgets.QLabel("Camera"))
        self.camera_box = QtWidgets.QComboBox()
        self.camera_box.setMinimumContentsLength(18)
        self.camera_box.currentTextChanged.connect(self._changed)
        bar.addWidget(self.camera_box, 1)
        self.note = QtWidgets.QLabel("")
        bar.addWidget(self.note)
        layout.addLayout(bar)
        self.widget = pg.GraphicsLayoutWidget()
        self.widget.setBackground((16, 16, 20))
        self.view = self.widget.addViewBox(lockAspect=True, invertY=True)
        self.image = pg.ImageItem(axisOrder="row-major")
        self.view.addItem(self.image)
        self.curves: dict[str, pg.PlotCurveItem] = {}
        layout.addWidget(self.widget, 1)
        self._shape: tuple[int, int] | None = None
        self.scene: CameraScene | None = None

    @property
    def camera(self) -> str | None:
        return self.camera_box.currentText() or None

    def set_cameras(self, cameras: Sequence[str]) -> None:
        current = self.camera
        self.camera_box.blockSignals(True)
        self.camera_box.clear()
        self.camera_box.addItems(list(cameras))
        if current is not None and current in cameras:
            self.camera_box.setCurrentText(current)
        self.camera_box.blockSignals(False)
        self.note.setText("" if cameras else "this log has no camera")
        if self.camera != current:
            self._changed(self.camera or "")

    def _changed(self, name: str) -> None:
        self._shape = None
        self.camera_changed.emit(name)

    def show_camera(self, scene: CameraScene | None) -> None:
        self.scene = scene
        if scene is None:
            self.image.clear()
            for curve in self.curves.values():
                curve.setVisible(False)
            return
        self.image.setImage(scene.image, autoLevels=False, levels=(0, 255))
        shape = scene.image.shape[:2]
        if shape != self._shape:
            self.view.setRange(xRange=(0, shape[1]), yRange=(0, shape[0]), padding=0)
            self._shape = (int(shape[0]), int(shape[1]))
        self.note.setText("" if scene.calibrated else "no calibration: boxes not projected")
        for name, (color, uv) in scene.segments.items():
            curve = self.curves.get(name)
            if curve is None:
                curve = pg.PlotCurveItem(pen=pg.mkPen(color, width=2), connect="pairs")
                self.view.addItem(curve)
                self.curves[name] = curve
            curve.setData(x=uv[:, 0], y=uv[:, 1], connect="pairs")
            curve.setVisible(True)
        for name, curve in self.curves.items():
            if name not in scene.segments:
                curve.setVisible(False)
