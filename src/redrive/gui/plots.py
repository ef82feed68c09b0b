"""Time series beside the views: IMU, ego speed, yaw rate and a per-frame metric, with a cursor at
the current frame (x = seconds since the start of the log).

Each plot names its series in a small title (rotated axis labels of four stacked plots overlap);
the y axes show plain values (no SI-prefix rescaling), and a constant series gets a ±1 range
around its value instead of an autoscaled sliver.  Speed and yaw rate come from the log's ego
state or, when the log has none (an object-level closed-loop run), from the run's ``ego`` table.
The metric shown first is a headline one of the run (:data:`PREFERRED_METRICS`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pyqtgraph as pg
from PySide6 import QtWidgets

from redrive.gui.session import RunData, Series

__all__ = ["PREFERRED_METRICS", "PlotsPanel", "first_metric", "metric_label"]

_AXES = ((255, 90, 90), (90, 220, 90), (90, 150, 255))

#: (metric, value) the dropdown starts on, the first the run has; else the first in order.
PREFERRED_METRICS = (
    ("planning", "ADE/3s"),
    ("ego_progress", "progress_m"),
    ("nuscenes_detection", "missed"),
    ("kitti_detection", "missed"),
    ("object_attributes", "position_rmse_m"),
    ("latency", "frame_ms"),
)


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
        self._titles: dict[str, str] = {}
        for name, unit in (
            ("IMU accel", "m/s²"),
            ("speed", "m/s"),
            ("yaw rate", "rad/s"),
            ("metric", ""),
        ):
            plot = self.widget.addPlot()
            self._titles[name] = f"{name} ({unit})" if unit else name
            plot.setTitle(self._titles[name], size="8pt")
            plot.getAxis("left").enableAutoSIPrefix(False)
            plot.getAxis("left").setWidth(48)  # the four plots' x axes line up
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
        self._log_series = Series()

    def _t(self, stamps: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
        return (stamps - self.start_ns).astype(np.float64) / 1e9

    def set_start(self, start_ns: int) -> None:
        """The log's start (x = 0); clears the log's series, re-draws the metric."""
        self.start_ns = start_ns
        self._log_series = Series()
        self.plots["IMU accel"].clear()
        self.plots["IMU accel"].addItem(self.cursors["IMU accel"])
        self._draw_ego()  # the run's ego, until the log's series comes
        self._show_metric()

    def set_series(self, series: Series, *, start_ns: int) -> None:
        self.start_ns = start_ns
        self._log_series = series
        plot = self.plots["IMU accel"]
        plot.clear()
        plot.addItem(self.cursors["IMU accel"])
        self._title("IMU accel", series.imu_accel is not None, "no IMU in this log")
        if series.imu_accel is not None:
            t = self._t(series.imu_accel[0])
            for axis in range(3):
                plot.plot(t, series.imu_accel[1][:, axis], pen=pg.mkPen(_AXES[axis]))
            _fit_y(plot, series.imu_accel[1])
        self._draw_ego()

    def _draw_ego(self) -> None:
        """Speed and yaw rate: the log's, else the run's ``ego`` table's."""
        series = self._log_series
        run_series = _run_ego_series(self.run)
        for name, data, fallback in (
            ("speed", series.speed_mps, run_series.speed_mps),
            ("yaw rate", series.yaw_rate_rad_s, run_series.yaw_rate_rad_s),
        ):
            plot = self.plots[name]
            plot.clear()
            plot.addItem(self.cursors[name])
            shown = data if data is not None else fallback
            self._title(name, shown is not None, "no ego state in the log or the run")
            if shown is not None:
                plot.plot(self._t(shown[0]), shown[1], pen=pg.mkPen((220, 220, 220)))
                _fit_y(plot, shown[1])

    def _title(self, name: str, has_data: bool, missing: str) -> None:
        """The plot's title, or what it lacks: an empty plot says why it is empty."""
        text = self._titles[name] if has_data else f"{name}: {missing}"
        self.plots[name].setTitle(text, size="8pt")

    def set_run(self, run: RunData | None) -> None:
        self.run = run
        self.metric_box.blockSignals(True)
        self.metric_box.clear()
        if run is not None:
            keys: list[tuple[str, ...]] = sorted(run.per_frame)
            for key in keys:
                self.metric_box.addItem(metric_label(key), key)
            if keys:
                self.metric_box.setCurrentIndex(keys.index(first_metric(keys)))
        self.metric_box.blockSignals(False)
        self._show_metric()
        self._draw_ego()

    def _show_metric(self) -> None:
        plot = self.plots["metric"]
        plot.clear()
        plot.addItem(self.cursors["metric"])
        key = self.metric_box.currentData()
        if self.run is None or key is None:
            plot.setTitle("metric (evaluate a run)", size="8pt")
            return
        stamps, values = self.run.per_frame[tuple(key)]
        plot.setTitle(metric_label(tuple(key)), size="8pt")
        plot.plot(self._t(stamps), values, pen=pg.mkPen((255, 140, 0)), symbol="o", symbolSize=3)
        plot.enableAutoRange(axis="x")
        _fit_y(plot, values)

    def set_cursor(self, stamp_ns: int) -> None:
        t = (stamp_ns - self.start_ns) / 1e9
        for cursor in self.cursors.values():
            cursor.setValue(t)


def metric_label(key: Sequence[str]) -> str:
    """A per-frame series (metric, algorithm, value) as the dropdown shows it; a run-level
    metric has no algorithm (``latency / frame_ms``, not ``latency /  / frame_ms``)."""
    return " / ".join(part for part in key if part)


def first_metric(keys: Sequence[tuple[str, ...]]) -> tuple[str, ...]:
    """The per-frame series (metric, algorithm, value) the dropdown starts on: the first of
    :data:`PREFERRED_METRICS` the run has, else the first key."""
    for want in PREFERRED_METRICS:
        for key in keys:
            if (key[0], key[2]) == want:
                return key
    return keys[0]


def _fit_y(plot: pg.PlotItem, values: npt.ArrayLike) -> None:
    """Autoscale y to the finite values; a constant series gets ±1 around its value (pyqtgraph
    would show a sliver of ±1e-3 around it, labelled as a 1000-fold scale)."""
    finite = np.asarray(values, dtype=np.float64)
    finite = finite[np.isfinite(finite)]
    if finite.size == 0:
        return
    lo, hi = float(finite.min()), float(finite.max())
    if hi - lo < 1e-9 * max(1.0, abs(lo)):
        plot.setYRange(lo - 1.0, hi + 1.0, padding=0)
    else:
        plot.enableAutoRange(axis="y")


def _run_ego_series(run: RunData | None) -> Series:
    """The run's ``ego`` table as speed and yaw-rate series (empty without one)."""
    if run is None or not run.ego:
        return Series()
    frames = sorted(run.ego)
    stamps = np.array([run.ego[i].stamp_ns for i in frames], dtype=np.int64)
    speed = np.array([run.ego[i].speed_mps for i in frames], dtype=np.float64)
    yaw = np.array([run.ego[i].yaw_rate_rad_s for i in frames], dtype=np.float64)
    return Series(speed_mps=(stamps, speed), yaw_rate_rad_s=(stamps, yaw))
