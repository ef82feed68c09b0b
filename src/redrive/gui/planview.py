"""The planview: the point cloud in 3D (OpenGL) or as a top-down raster (2D), with boxes, track
ids, the ego vehicle and the planned path.

The 3D view is pyqtgraph's GL view (orbit: left drag, pan: middle drag or ctrl+left, zoom:
wheel) as a ``QOpenGLWindow`` in a window container, not a ``QOpenGLWidget``: a window holding a
``QOpenGLWidget`` composites *everything* through GL, which under llvmpipe made every repaint of
the 1600×1000 window cost 28–42 ms (``python -m benchmarks gui``); the native GL window keeps the rest on
Qt's raster backing store.  The 2D view is an ``ImageItem`` raster plus line items in a ``PlotWidget`` (pan:
drag, zoom: wheel) — fast on software GL, where the 3D view is not (NOTES.md: 13–17 FPS at 120k
points under llvmpipe against 25–36 for the raster).  Both are in base_link: x forward, y left.
"""

from __future__ import annotations

import html
from collections.abc import Sequence

import numpy as np
import pyqtgraph as pg
import pyqtgraph.opengl as gl
import shiboken6
from pyqtgraph.opengl.GLViewWidget import GLViewMixin
from PySide6 import QtCore, QtGui, QtOpenGL, QtWidgets

from redrive.gui.map_layers import MAP_PREFIX
from redrive.gui.scene import ColorMode, LayerLines, RasterSpec, Scene

__all__ = ["Planview"]

_MAX_LABELS = 60


def _rgba(color: tuple[int, int, int], alpha: float = 1.0) -> tuple[float, float, float, float]:
    return (color[0] / 255, color[1] / 255, color[2] / 255, alpha)


class _GlView(GLViewMixin, QtOpenGL.QOpenGLWindow):
    """pyqtgraph's GL view as a ``QOpenGLWindow`` (embed it with ``createWindowContainer``)."""

    def __init__(self) -> None:
        super().__init__()
        self.setBackgroundColor((16, 16, 20))
        self.grid = gl.GLGridItem(size=QtGui.QVector3D(120, 120, 1))
        self.grid.setSpacing(10, 10, 1)
        self.grid.setColor((70, 70, 70, 120))
        self.addItem(self.grid)
        self.scatter = gl.GLScatterPlotItem(pos=np.zeros((1, 3)), size=2.0, pxMode=True)
        self.scatter.setGLOptions("opaque")
        self.addItem(self.scatter)
        self.lines: dict[str, gl.GLLinePlotItem] = {}
        self.path = gl.GLLinePlotItem(pos=np.zeros((2, 3)), width=3.0, mode="line_strip")
        self.addItem(self.path)
        self.labels: list[gl.GLTextItem] = []
        self._matrix = QtGui.QMatrix4x4()
        self.reset_camera()

    def release_gl(self) -> None:
        """Destroy the items' GL buffers with this window's context current.  Left to the
        garbage collector, a buffer is destroyed whenever it runs — possibly inside another
        view's paint with another context current, where Mesa can block (seen as a hang of the
        GUI test suite)."""
        if self.context() is None or not self.isExposed():
            return
        self.makeCurrent()
        try:
            for item in list(self.items):
                for value in vars(item).values():
                    if isinstance(value, QtOpenGL.QOpenGLBuffer) and value.isCreated():
                        value.destroy()
            if self.default_vao.isCreated():
                self.default_vao.destroy()
        finally:
            self.doneCurrent()
        for item in list(self.items):
            self.removeItem(item)

    def rect(self) -> QtCore.QRect:
        """What GLTextItem asks of its view (a QWidget method a QWindow lacks)."""
        return QtCore.QRect(0, 0, self.width(), self.height())

    def reset_camera(self) -> None:
        self.setCameraPosition(pos=QtGui.QVector3D(8, 0, 0), distance=55, elevation=35, azimuth=180)

    def show_scene(self, scene: Scene, world: tuple[float, float, float] | None = None) -> None:
        """``world``: (x, y, heading) of the ego relative to the view's origin — the items are
        placed there (a world-fixed view); None: base_link at the origin (follow ego)."""
        matrix = QtGui.QMatrix4x4()
        if world is not None:
            matrix.translate(world[0], world[1], 0.0)
            matrix.rotate(float(np.degrees(world[2])), 0.0, 0.0, 1.0)
        for item in (self.scatter, self.path, *self.lines.values(), *self.labels):
            item.setTransform(matrix)
        self._matrix = matrix
        if len(scene.points):
            self.scatter.setData(pos=scene.points, color=scene.colors)
            self.scatter.setVisible(True)
        else:
            self.scatter.setVisible(False)
        seen = set()
        for layer in scene.layers:
            seen.add(layer.name)
            item = self.lines.get(layer.name)
            if item is None:
                item = gl.GLLinePlotItem(mode="lines", width=2.0, antialias=False)
                item.setTransform(self._matrix)
                self.addItem(item)
                self.lines[layer.name] = item
            if layer.alpha < 1.0:
                item.setGLOptions("translucent")
            if len(layer.segments):
                item.setData(pos=layer.segments, color=_rgba(layer.color, layer.alpha))
                item.setVisible(True)
            else:
                item.setVisible(False)
        for name, item in self.lines.items():
            if name not in seen:
                item.setVisible(False)
        if scene.path is not None and len(scene.path) > 1:
            self.path.setData(pos=scene.path, color=_rgba((255, 200, 40)))
            self.path.setVisible(True)
        else:
            self.path.setVisible(False)
        texts = [t for layer in scene.layers for t in layer.labels][:_MAX_LABELS]
        while len(self.labels) < len(texts):
            item = gl.GLTextItem(color=(255, 255, 255, 255))
            item.setTransform(self._matrix)
            self.addItem(item)
            self.labels.append(item)
        for item, (text, x, y, z) in zip(self.labels, texts, strict=False):
            item.setData(pos=(x, y, z + 0.3), text=text)
            item.setVisible(True)
        for item in self.labels[len(texts) :]:
            item.setVisible(False)


class _RasterView(pg.PlotWidget):
    """x (forward) up the screen, y (left) to the left: plot axes are (y, x), x axis inverted."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent, background=(16, 16, 20))
        self.setAspectLocked(True)
        # No plot grid: the raster carries a 10 m grid (the plot's grid is redrawn on every
        # repaint and made the view ~5× slower to paint than a bare ImageItem).
        self.getPlotItem().invertX(True)
        self.setLabel("bottom", "y (left)", units="m")
        self.setLabel("left", "x (forward)", units="m")
        self.image = pg.ImageItem(axisOrder="row-major")
        self.addItem(self.image)
        self.curves: dict[str, pg.PlotCurveItem] = {}
        self.path = pg.PlotCurveItem(pen=pg.mkPen((255, 200, 40), width=3))
        self.addItem(self.path)
        self.labels: list[pg.TextItem] = []
        self._spec: RasterSpec | None = None
        self._raster_transform = QtGui.QTransform()
        self._pose = QtGui.QTransform()

    def _place(self, spec: RasterSpec) -> None:
        if spec == self._spec:
            return
        h, cell = spec.half_extent_m, spec.cell_m
        # Row 0 is +x (top), column 0 is +y (left): plot x = y = h − col·cell (drawn on the
        # left: the axis is inverted) and plot y = x = h − row·cell.
        self._raster_transform = QtGui.QTransform(-cell, 0, 0, -cell, h, h)
        self._spec = spec

    def show_scene(
        self, scene: Scene, spec: RasterSpec, world: tuple[float, float, float] | None = None
    ) -> None:
        """``world`` as for the 3D view.  Plot coordinates are (u, v) = (y, x); the pose maps
        (u, v) to (U, V) = (Y, X) with X = cos·x − sin·y + tx, Y = sin·x + cos·y + ty."""
        pose = QtGui.QTransform()
        if world is not None:
            tx, ty, h = world
            c, s = float(np.cos(h)), float(np.sin(h))
            pose = QtGui.QTransform(c, -s, s, c, ty, tx)
        for item in (self.path, *self.curves.values(), *self.labels):
            item.setTransform(pose)
        self._pose = pose
        if scene.raster is not None:
            self._place(spec)
            self.image.setTransform(self._raster_transform * pose)
            self.image.setImage(scene.raster, autoLevels=False, levels=(0, 255))
        seen = set()
        for layer in scene.layers:
            seen.add(layer.name)
            curve = self.curves.get(layer.name)
            if curve is None:
                pen = pg.mkPen((*layer.color, round(255 * layer.alpha)), width=2)
                if layer.alpha < 1.0:  # a ghost: translucent and dashed
                    pen.setStyle(QtCore.Qt.PenStyle.DashLine)
                curve = pg.PlotCurveItem(connect="pairs", pen=pen)
                curve.setTransform(self._pose)
                self.addItem(curve)
                self.curves[layer.name] = curve
            seg = layer.segments
            curve.setData(x=seg[:, 1], y=seg[:, 0], connect="pairs")
            curve.setVisible(True)
        for name, curve in self.curves.items():
            if name not in seen:
                curve.setVisible(False)
        if scene.path is not None:
            self.path.setData(x=scene.path[:, 1], y=scene.path[:, 0])
            self.path.setVisible(True)
        else:
            self.path.setVisible(False)
        texts = [t for layer in scene.layers for t in layer.labels][:_MAX_LABELS]
        while len(self.labels) < len(texts):
            item = pg.TextItem(color=(255, 255, 255), anchor=(0.5, 1.0))
            item.setTransform(self._pose)
            self.addItem(item)
            self.labels.append(item)
        for item, (text, x, y, _z) in zip(self.labels, texts, strict=False):
            item.setText(text)
            item.setPos(y, x)
            item.setVisible(True)
        for item in self.labels[len(texts) :]:
            item.setVisible(False)

    def reset_view(self) -> None:
        self.setRange(xRange=(-30, 30), yRange=(-20, 50), padding=0)


class Planview(QtWidgets.QWidget):
    """The centre panel: a toolbar (colour by, Convert 2D Planview, reset view) over the view."""

    options_changed = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        bar = QtWidgets.QHBoxLayout()
        bar.addWidget(QtWidgets.QLabel("Colour by"))
        self.color_box = QtWidgets.QComboBox()
        for mode in ColorMode:
            self.color_box.addItem(mode.value, mode)
        self.color_box.currentIndexChanged.connect(lambda _i: self.options_changed.emit())
        bar.addWidget(self.color_box)
        self.convert_button = QtWidgets.QPushButton("Convert 2D Planview")
        self.convert_button.setCheckable(True)
        self.convert_button.setToolTip("Switch between the 3D point cloud and a top-down raster")
        self.convert_button.toggled.connect(self._toggle_2d)
        bar.addWidget(self.convert_button)
        self.follow_box = QtWidgets.QCheckBox("Follow ego")
        self.follow_box.setChecked(True)
        self.follow_box.setToolTip(
            "On: the view moves with the ego vehicle (base_link at the centre). Off: the view "
            "stays fixed in the world and the ego drives through it (needs the log's ego state)."
        )
        self.follow_box.toggled.connect(self._follow_toggled)
        bar.addWidget(self.follow_box)
        self.reset_button = QtWidgets.QPushButton("Reset view")
        self.reset_button.clicked.connect(self.reset_view)
        bar.addWidget(self.reset_button)
        bar.addStretch(1)
        # what each box colour is: one swatch per layer the frame draws
        self.legend = QtWidgets.QLabel("")
        self.legend.setObjectName("legend")
        self.legend.setTextFormat(QtCore.Qt.TextFormat.RichText)
        bar.addWidget(self.legend)
        self.status = QtWidgets.QLabel("")
        bar.addWidget(self.status)
        layout.addLayout(bar)
        self.stack = QtWidgets.QStackedWidget()
        self.view3d = _GlView()
        self.container3d = QtWidgets.QWidget.createWindowContainer(self.view3d, self)
        self.container3d.setMinimumSize(200, 150)
        self.view2d = _RasterView()
        self.stack.addWidget(self.container3d)
        self.stack.addWidget(self.view2d)
        layout.addWidget(self.stack, 1)
        self.raster_spec = RasterSpec()
        self.scene: Scene | None = None
        self.world_origin: tuple[float, float, float] | None = None
        self.view2d.reset_view()

    @property
    def is_2d(self) -> bool:
        return self.convert_button.isChecked()

    @property
    def color_mode(self) -> ColorMode:
        mode = self.color_box.currentData()
        return mode if isinstance(mode, ColorMode) else ColorMode.DISTANCE

    def _toggle_2d(self, on: bool) -> None:
        self.stack.setCurrentIndex(1 if on else 0)
        self.convert_button.setText("Convert 3D Planview" if on else "Convert 2D Planview")
        self.options_changed.emit()

    def reset_view(self) -> None:
        self.view3d.reset_camera()
        self.view2d.reset_view()
        self.world_origin = None
        if self.scene is not None:
            self.show_scene(self.scene)

    def _follow_toggled(self, _on: bool) -> None:
        self.world_origin = None
        if self.scene is not None:
            self.show_scene(self.scene)

    def _world(self, scene: Scene) -> tuple[float, float, float] | None:
        """The ego pose relative to the world origin of a fixed view (the pose where following
        was switched off: map coordinates are too large for GL's float32)."""
        if self.follow_box.isChecked() or scene.pose is None:
            return None
        if self.world_origin is None:
            self.world_origin = scene.pose
        x0, y0, h0 = self.world_origin
        x, y, h = scene.pose
        c, s = np.cos(-h0), np.sin(-h0)
        dx, dy = x - x0, y - y0
        return (float(c * dx - s * dy), float(s * dx + c * dy), float(h - h0))

    def show_scene(self, scene: Scene) -> None:
        self.scene = scene
        world = self._world(scene)
        if self.is_2d:
            self.view2d.show_scene(scene, self.raster_spec, world)
        else:
            self.view3d.show_scene(scene, world)
        boxes = sum(
            len(layer.segments) // 28
            for layer in scene.layers
            if layer.name not in ("ego", "logged ego") and not layer.name.startswith(MAP_PREFIX)
        )
        self.status.setText(f"{scene.point_count:,} points · {boxes} boxes")
        self.legend.setText(legend_html(scene.layers))

    def grab_view(self) -> QtGui.QImage:
        """The current view as an image (the GL framebuffer in 3D)."""
        if self.is_2d:
            return self.view2d.grab().toImage()
        return self.view3d.grabFramebuffer()

    def shutdown(self) -> None:
        """Delete the GL window's container (and with it the window) now.  Left to Qt, a window
        container whose widget tree was deleted later crashes QApplication's destructor
        (QWindowContainer::toplevelAboutToBeDestroyed on a dead window; PySide6 6.11)."""
        if not shiboken6.isValid(self.container3d):
            return
        self.view3d.release_gl()
        self.stack.removeWidget(self.container3d)
        shiboken6.delete(self.container3d)

    def paint_gl_into(self, image: QtGui.QImage, window: QtWidgets.QWidget) -> None:
        """Draw the 3D view into ``image``, a grab of ``window`` (a native GL window is not part
        of a widget grab)."""
        if (
            self.is_2d
            or not shiboken6.isValid(self.container3d)
            or not self.container3d.isVisible()
        ):
            return
        top_left = self.container3d.mapTo(window, QtCore.QPoint(0, 0))
        painter = QtGui.QPainter(image)
        painter.drawImage(top_left, self.view3d.grabFramebuffer())
        painter.end()


def legend_html(layers: Sequence[LayerLines]) -> str:
    """A colour swatch and the name of each drawn layer (ground truth, each algorithm, the ego …),
    in drawing order, as rich text for the view's legend."""
    items = []
    seen: set[str] = set()
    for layer in layers:
        if layer.name in seen or not len(layer.segments):
            continue
        seen.add(layer.name)
        r, g, b = layer.color[:3]
        name = html.escape(layer.name)
        items.append(f'<span style="color:rgb({r},{g},{b})">&#9632;</span>&nbsp;{name}')
    return " &nbsp; ".join(items)
