"""Time series beside the views: IMU, ego speed, yaw rate and a per-frame metric, with a cursor at
the current frame (x = seconds since the start of the log)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pyqtgraph as pg
from PySide6 import QtWidgets

from redrive.gui.session import RunData, Series

__all__ = ["PlotsPanel"]

_AXES = ((255, 90, 90), (90, 220, 90), (90, 150, 255))


class PlotsPanel(QtWidgets.QWidget):
    """Four linked-x plots (IMU acceleration x/y/z, speed, yaw rate, a metric); a metric dropdown picks the per-frame metric series of the run."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        bar = QtWidgets.QHBoxLayout()
        bar.addWidget(QtWidgets.QLabel("Metric"))
        self.metric_box = QtWidgets.QComboBox()
        self.metric_box.setMinimumContentsLength(28)
        self.metric_box.currentIndexChanged.connect(self._show_metric)
        bar.addWidget(self.metric_box, 1)
        layout.addLayout(bar)
        self.widget = pg.GraphicsLayoutWidget()
        layout.addWidget(self.widget, 1)
        self.plots: dict[str, pg.PlotItem] = {}
        for name, unit in (
            ("IMU accel", "m/s²"),
            ("speed", "m/s"),
            ("yaw rate", "rad/s"),
            ("metric", ""),
        ):
            plot = self.widget.addPlot()
            plot.setLabel("left", name, units=unit)
            plot.showGrid(x=True, y=True, alpha=0.2)
            plot.setMouseEnabled(y=False)
            if self.plots:
                plot.setXLink(next(iter(self.plots.values())))
            self.plots[name] = plot
            self.widget.nextRow()
        self.cursors = {
            name: plot.addLine(x=0, pen=pg.mkPen((255, 255, 0), width=1))
            for name, plot in self.plots.items()
        }
        self.start_ns = 0
        self.run: RunData | None = None

    def _t(self, stamps: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
        return (stamps - self.start_ns).astype(np.float64) / 1e9

    def set_start(self, start_ns: int) -> None:
        """The log's start (x = 0); clears the log's series, re-draws the metric."""
        self.start_ns = start_ns
        for name in ("IMU accel", "speed", "yaw rate"):
            self.plots[name].clear()
            self.plots[name].addItem(self.cursors[name])
        self._show_metric()

    def set_series(self, series: Series, *, start_ns: int) -> None:
        self.start_ns = start_ns
        plot = self.plots["IMU accel"]
        plot.clear()
        plot.addItem(self.cursors["IMU accel"])
        if series.imu_accel is not None:
            t = self._t(series.imu_accel[0])
            for axis in range(3):
                plot.plot(t, series.imu_accel[1][:, axis], pen=pg.mkPen(_AXES[axis]))
        for name, data in (("speed", series.speed_mps), ("yaw rate", series.yaw_rate_rad_s)):
            plot = self.plots[name]
            plot.clear()
            plot.addItem(self.cursors[name])
            if data is not None:
                plot.plot(self._t(data[0]), data[1], pen=pg.mkPen((220, 220, 220)))

    def set_run(self, run: RunData | None) -> None:
        self.run = run
        self.metric_box.blockSignals(True)
        self.metric_box.clear()
        if run is not None:
            for key in sorted(run.per_frame):
                self.metric_box.addItem(" / ".join(key), key)
        self.metric_box.blockSignals(False)
        self._show_metric()

    def _show_metric(self) -> None:
        plot = self.plots["metric"]
        plot.clear()
        plot.addItem(self.cursors["metric"])
        key = self.metric_box.currentData()
        if self.run is None or key is None:
            plot.setLabel("left", "metric (evaluate a run)")
            return
        stamps, values = self.run.per_frame[tuple(key)]
        plot.setLabel("left", key[2])
        plot.plot(self._t(stamps), values, pen=pg.mkPen((255, 140, 0)), symbol="o", symbolSize=3)
        plot.enableAutoRange()

    def set_cursor(self, stamp_ns: int) -> None:
        t = (stamp_ns - self.start_ns) / 1e9
        for cursor in self.cursors.values():
            cursor.setValue(t)
