"""The Re-simulation panel (the paper's Figure 9): run one algorithm over a log, evaluate it,
look at its result beside the ground truth, export it, compare it with another run (A/B).

>>> panel = ResimPanel()                                    # doctest: +SKIP
>>> panel.load_log("drive.mcap"); panel.set_algorithm("perception", "cluster-detector")
>>> panel.start()              # → run_finished(Path) once the run is written and evaluated

The engine, the evaluation and the reading of the run happen in a worker thread
(:class:`~redrive.gui.resim_views.RunThread`); the GUI thread only draws.  What runs is the
pipeline ``redrive run --perception/--planning/--control NAME`` builds, with the reference
algorithms upstream where the algorithm needs an earlier stage's output
(:func:`~redrive.gui.resim_views.algorithm_test_pipeline`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtWidgets

from redrive.gui.resim_views import (
    CATEGORIES,
    REFERENCE_DETECTOR,
    RunOutcome,
    RunThread,
    SummaryRow,
    TopDownView,
    default_run_dir,
    describe_error,
    shown_algorithms,
    stored_summary_rows,
)
from redrive.gui.session import RunData
from redrive.results import RunStatus

__all__ = ["ResimPanel"]

logger = logging.getLogger(__name__)


class ResimPanel(QtWidgets.QWidget):
    """Load a log, pick an algorithm, run it (Algorithm Test), see and export its results.

    Signals: ``run_finished(Path)`` (a test run completed and was evaluated), ``run_cancelled(Path)``
    (closed as ``interrupted``), ``run_failed(str)`` (the error, also shown in a message box).

    Attributes for the main window and tests: ``status_label``, ``progress``, ``result_view``
    (A's result), ``overlay_view`` (A's result over ground truth), ``overlay_view_b`` (B's),
    ``summary_table``, ``frame_slider``, ``frame_label``, ``error_box`` (the last message box),
    ``run_a`` / ``run_b`` (the :class:`~redrive.gui.session.RunData` shown), ``shown_a`` /
    ``shown_b`` (role → the algorithm of that run drawn).
    """

    run_finished = QtCore.Signal(object)
    run_cancelled = QtCore.Signal(object)
    run_failed = QtCore.Signal(str)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.log_path: Path | None = None
        self.run_a: RunData | None = None
        self.run_b: RunData | None = None
        self.shown_a: Mapping[str, str] = {}
        self.shown_b: Mapping[str, str] = {}
        self.error_box: QtWidgets.QMessageBox | None = None
        self._thread: RunThread | None = None
        self._auto_out = True
        self._ranged = False
        self._algorithms: dict[str, list[str]] = {c: [] for c in CATEGORIES}
        self._build()
        self.reload_algorithms()
        self._set_running(False)

    # -- layout ------------------------------------------------------------------------------

    def _build(self) -> None:
        w = QtWidgets
        self.log_button = w.QPushButton("Load log…")
        self.log_edit = w.QLineEdit(readOnly=True, placeholderText="no log loaded")
        self.category_combo = w.QComboBox()
        self.category_combo.addItems(list(CATEGORIES))
        self.algorithm_combo = w.QComboBox(editable=True)  # also takes module:Class, file.py:Class
        self.algorithm_combo.setMinimumContentsLength(20)
        self.out_edit = w.QLineEdit(placeholderText="output directory (automatic)")
        self.out_button = w.QPushButton("…")
        self.test_button = w.QPushButton("Algorithm Test")
        self.cancel_button = w.QPushButton("Cancel")
        self.progress = w.QProgressBar(minimum=0, maximum=100, value=0)
        self.status_label = w.QLabel("Load a log to start.", wordWrap=True)
        self.status_label.setTextInteractionFlags(
            QtCore.Qt.TextInteractionFlag.TextSelectableByMouse
        )
        self.result_view = TopDownView("A: result", with_ground_truth=False)
        self.overlay_view = TopDownView("A: result over ground truth", with_ground_truth=True)
        self.overlay_view_b = TopDownView("B: result over ground truth", with_ground_truth=True)
        self.overlay_view_b.hide()
        for view in (self.overlay_view, self.overlay_view_b):
            view.follow(self.result_view)  # same zoom and pan
        self.summary_table = w.QTableWidget(0, 5)
        self.summary_table.setHorizontalHeaderLabels(
            ["metric", "key", "value", "unit", "algorithm"]
        )
        self.summary_table.setEditTriggers(w.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.summary_table.horizontalHeader().setStretchLastSection(True)
        self.frame_slider = w.QSlider(QtCore.Qt.Orientation.Horizontal)
        self.frame_slider.setEnabled(False)
        self.frame_label = w.QLabel("no run")
        self.export_csv_button = w.QPushButton("Export CSV…")
        self.export_xlsx_button = w.QPushButton("Export Excel…")
        self.open_run_button = w.QPushButton("Open run…")
        self.open_run_b_button = w.QPushButton("Open run B…")

        self._splitter = views = w.QSplitter(QtCore.Qt.Orientation.Horizontal)
        for view in (self.result_view, self.overlay_view, self.overlay_view_b):
            views.addWidget(view)
            views.setStretchFactor(views.count() - 1, 3)
        views.addWidget(self.summary_table)
        views.setStretchFactor(views.count() - 1, 2)
        self.frame_label.setMinimumWidth(380)
        layout = w.QVBoxLayout(self)
        layout.addLayout(_hbox(self.log_button, self.log_edit))
        layout.addLayout(
            _hbox("Algorithm Category", self.category_combo, "Test Algorithm",
                  self.algorithm_combo, "Output", self.out_edit, self.out_button,
                  stretch=self.out_edit)
        )  # fmt: skip
        layout.addLayout(_hbox(self.test_button, self.cancel_button, self.progress))
        layout.addWidget(self.status_label)
        layout.addWidget(views, 1)
        layout.addLayout(_hbox(self.frame_slider, self.frame_label, stretch=self.frame_slider))
        bottom = _hbox(self.export_csv_button, self.export_xlsx_button, self.open_run_button,
                       self.open_run_b_button)  # fmt: skip
        bottom.addStretch(1)
        layout.addLayout(bottom)

        self.log_button.clicked.connect(self._choose_log)
        self.category_combo.currentTextChanged.connect(self._fill_algorithms)
        self.out_edit.textEdited.connect(self._out_edited)
        self.out_button.clicked.connect(self._choose_out)
        self.test_button.clicked.connect(self.start)
        self.cancel_button.clicked.connect(self.cancel)
        self.frame_slider.valueChanged.connect(self._show_frame)
        self.export_csv_button.clicked.connect(lambda: self.export("csv"))
        self.export_xlsx_button.clicked.connect(lambda: self.export("xlsx"))
        self.open_run_button.clicked.connect(lambda: self._choose_run(b=False))
        self.open_run_b_button.clicked.connect(lambda: self._choose_run(b=True))

    # -- algorithms ------------------------------------------------------------------------------

    def reload_algorithms(self) -> None:
        """Fill the Test Algorithm choices from the installed plugins (``redrive algorithms``)."""
        from redrive.algorithms.discovery import installed_algorithms

        registry = installed_algorithms()
        self._algorithms = {c: [] for c in CATEGORIES}
        for name, cls in registry.items():
            self._algorithms[cls.role.value].append(name)
        if registry.broken:
            broken = ", ".join(f"{b.name} ({b.error})" for b in registry.broken.values())
            self._status(f"Some algorithm plugins cannot be loaded: {broken}", error=True)
        self._fill_algorithms(self.category_combo.currentText())

    def _fill_algorithms(self, category: str) -> None:
        self.algorithm_combo.clear()
        names = self._algorithms.get(category, [])
        self.algorithm_combo.addItems(names)
        if category == "perception" and REFERENCE_DETECTOR in names:
            self.algorithm_combo.setCurrentText(REFERENCE_DETECTOR)

    def set_algorithm(self, category: str, name: str) -> None:
        """Choose the algorithm to test: an installed name, ``module:Class`` or ``file.py:Class``.

        Raises:
            ValueError: ``category`` is not one of :data:`CATEGORIES`.
        """
        if category not in CATEGORIES:
            msg = f"algorithm category {category!r} is not one of {', '.join(CATEGORIES)}"
            raise ValueError(msg)
        self.category_combo.setCurrentText(category)
        self.algorithm_combo.setCurrentText(name)

    # -- log and output ---------------------------------------------------------------------------

    def _choose_log(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, "Load log", "", "Logs (*.mcap *.bag *.db3);;All files (*)"
        )
        if path:
            self.load_log(Path(path))

    def load_log(self, path: str | Path) -> bool:
        """Check that ``path`` is a log redrive reads (its index only) and make it the log to
        test on; on failure the error is shown and the previous log is dropped."""
        from redrive.io import open_log

        path = Path(path)
        self.log_edit.setText(str(path))
        try:
            with open_log(path) as log:
                topics, fmt = len(log.topics), log.format
                span_s = (log.end_ns - log.start_ns) / 1e9 if topics else 0.0
        except Exception as err:  # the GUI's top level: a bad file is reported, never fatal
            self.log_path = None
            self._set_running(False)
            self._error(f"Cannot load log {path}: {describe_error(err)}")
            return False
        self.log_path = path
        if self._auto_out:
            self.out_edit.clear()
        where = default_run_dir(path, "ALGORITHM").parent
        self.out_edit.setPlaceholderText(f"automatic: a new directory in {where}")
        self._set_running(False)
        self._status(f"Loaded {path.name}: {fmt}, {topics} topics, {span_s:.1f} s.")
        return True

    def _out_edited(self, text: str) -> None:
        self._auto_out = not text.strip()

    def set_output_dir(self, path: str | Path | None) -> None:
        """The run directory of the next test; None for an automatic new one."""
        self.out_edit.setText("" if path is None else str(path))
        self._auto_out = path is None

    def _choose_out(self) -> None:
        path = QtWidgets.QFileDialog.getExistingDirectory(self, "Output directory")
        if path:
            self.set_output_dir(path)

    # -- running ----------------------------------------------------------------------------------

    def is_running(self) -> bool:
        return self._thread is not None

    def start(self) -> bool:
        """Run the chosen algorithm over every frame of the log in a worker thread, then evaluate
        it; ``run_finished``, ``run_cancelled`` or ``run_failed`` says how it ended."""
        if self._thread is not None:
            return False
        spec = self.algorithm_combo.currentText().strip()
        if self.log_path is None or not spec:
            self._error("Load a log and choose an algorithm first.")
            return False
        category = self.category_combo.currentText()
        if self._auto_out or not self.out_edit.text().strip():
            out = default_run_dir(self.log_path, spec.rsplit(":", 1)[-1].rsplit("/", 1)[-1])
            self.out_edit.setText(str(out))
            self._auto_out = True
        out = Path(self.out_edit.text().strip())
        thread = RunThread(log=self.log_path, out=out, category=category, spec=spec)
        thread.total.connect(self._on_total)
        thread.progressed.connect(self.progress.setValue)
        thread.succeeded.connect(self._on_succeeded)
        thread.failed.connect(self._on_failed)
        self._thread = thread
        self.progress.setRange(0, 100)
        self.progress.setValue(0)
        self._set_running(True)
        self._status(f"Running {spec} ({category}) on {self.log_path.name} → {out} …")
        thread.start()
        return True

    def cancel(self) -> None:
        """Stop the running test after the frames in flight; its run is closed as interrupted."""
        if self._thread is not None:
            self._thread.cancel_event.set()
            self.cancel_button.setEnabled(False)
            self._status("Cancelling …")

    def shutdown(self, timeout_ms: int = 30_000) -> None:
        """Cancel a running test and wait for its thread (before the widget goes away)."""
        thread = self._thread
        if thread is not None:
            thread.cancel_event.set()
            thread.wait(timeout_ms)

    def showEvent(self, event: Any) -> None:
        super().showEvent(event)
        if not self._ranged:  # the locked aspect needs the views' real size
            self._ranged = True
            QtCore.QTimer.singleShot(0, self.result_view.reset_range)

    def closeEvent(self, event: Any) -> None:
        self.shutdown()
        super().closeEvent(event)

    def _on_total(self, total: int | None) -> None:
        if total is None:
            self.progress.setRange(0, 0)  # busy: the log does not say how many frames

    def _finish_thread(self) -> None:
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.wait()  # it has emitted its last signal and is returning
            thread.deleteLater()
        self._set_running(False)

    def _on_succeeded(self, outcome: RunOutcome) -> None:
        self._finish_thread()
        self._show_run_a(outcome.data, outcome.shown, outcome.rows)
        if outcome.status is RunStatus.COMPLETE:
            self.progress.setRange(0, 100)
            self.progress.setValue(100)
            self._status(f"Done: {outcome.message}")
            self.run_finished.emit(outcome.out)
        else:
            self._status(f"Cancelled: {outcome.message} (closed as {outcome.status})")
            self.run_cancelled.emit(outcome.out)

    def _on_failed(self, message: str) -> None:
        self._finish_thread()
        self.progress.setRange(0, 100)
        self._error(message)
        self.run_failed.emit(message)

    def _set_running(self, running: bool) -> None:
        self.test_button.setEnabled(not running and self.log_path is not None)
        self.cancel_button.setEnabled(running)
        for item in (self.log_button, self.category_combo, self.algorithm_combo, self.out_edit,
                     self.out_button, self.open_run_button):  # fmt: skip
            item.setEnabled(not running)
        has_run = self.run_a is not None and not running
        self.export_csv_button.setEnabled(has_run)
        self.export_xlsx_button.setEnabled(has_run)
        self.open_run_b_button.setEnabled(has_run)

    # -- runs -------------------------------------------------------------------------------------

    def _choose_run(self, *, b: bool) -> None:
        path = QtWidgets.QFileDialog.getExistingDirectory(self, "Open run B" if b else "Open run")
        if path:
            (self.open_run_b if b else self.open_run)(Path(path))

    def open_run(self, path: str | Path) -> bool:
        """Show an existing run directory as run A (its stored evaluation in the summary)."""
        try:
            data = RunData.load(Path(path))
            shown = shown_algorithms(data.manifest)
            rows = stored_summary_rows(Path(path), set(shown.values()))
        except Exception as err:  # the GUI's top level
            self._error(f"Cannot open run {path}: {describe_error(err)}")
            return False
        self._show_run_a(data, shown, rows)
        self._status(f"Run A: {_label(data, shown)}, {len(data.frames)} frames, {data.status}.")
        return True

    def open_run_b(self, path: str | Path) -> bool:
        """Show a second run's result over ground truth beside A's, on the same frame slider."""
        prefer = self.shown_a.values() if self.run_a is not None else ()
        try:
            data = RunData.load(Path(path))
            shown = shown_algorithms(data.manifest, prefer)
        except Exception as err:  # the GUI's top level
            self._error(f"Cannot open run B {path}: {describe_error(err)}")
            return False
        self.run_b, self.shown_b = data, shown
        self.overlay_view_b.setTitle(f"B: {_names(shown)} over ground truth")
        self.overlay_view_b.setToolTip(str(data.path))
        if self.overlay_view_b.isHidden():
            self.overlay_view_b.show()
            width = sum(self._splitter.sizes())
            self._splitter.setSizes([width * 3 // 11] * 3 + [width * 2 // 11])
        self._update_slider()
        self._status(f"Run B: {_label(data, shown)}, {len(data.frames)} frames, {data.status}.")
        return True

    def _show_run_a(
        self, data: RunData, shown: Mapping[str, str], rows: tuple[SummaryRow, ...]
    ) -> None:
        self.run_a, self.shown_a = data, shown
        self.result_view.setTitle(f"A: {_names(shown)}")
        self.overlay_view.setTitle(f"A: {_names(shown)} over ground truth")
        for view in (self.result_view, self.overlay_view):
            view.setToolTip(str(data.path))
        self._fill_summary(rows)
        self._update_slider()
        self._set_running(self._thread is not None)

    def _fill_summary(self, rows: tuple[SummaryRow, ...]) -> None:
        table = self.summary_table
        table.setRowCount(len(rows))
        for i, row in enumerate(rows):
            value = "" if math.isnan(row.value) else f"{row.value:.4g}"
            cells = (row.metric, row.key, value, row.unit, row.algorithm or "(run)")
            for j, text in enumerate(cells):
                item = QtWidgets.QTableWidgetItem(text)
                if row.note:
                    item.setToolTip(row.note)
                    item.setForeground(QtCore.Qt.GlobalColor.gray)
                table.setItem(i, j, item)
        table.resizeColumnsToContents()

    # -- frames -----------------------------------------------------------------------------------

    def _frames(self) -> list[int]:
        runs = [r for r in (self.run_a, self.run_b) if r is not None]
        return sorted({i for r in runs for i in r.frames})

    def _update_slider(self) -> None:
        frames = self._frames()
        slider = self.frame_slider
        slider.blockSignals(True)
        if frames:
            slider.setRange(frames[0], frames[-1])
            slider.setEnabled(True)
        else:
            slider.setRange(0, 0)
            slider.setEnabled(False)
        slider.blockSignals(False)
        self._show_frame(slider.value())

    def set_frame(self, index: int) -> None:
        """Show frame ``index`` (the log's frame index) in every view; a run without that frame
        shows nothing."""
        self.frame_slider.setValue(index)
        self._show_frame(self.frame_slider.value())

    def _show_frame(self, index: int) -> None:
        a, b = self.run_a, self.run_b
        n_a = self.result_view.show_frame(a, index, shown=self.shown_a)
        self.overlay_view.show_frame(a, index, shown=self.shown_a)
        n_b = self.overlay_view_b.show_frame(b, index, shown=self.shown_b)
        if a is None and b is None:
            self.frame_label.setText("no run")
            return
        parts = [f"frame {index}"]
        first = a or b
        assert first is not None
        stamp = first.stamps_ns.get(index)
        if stamp is not None and first.frames:
            parts.append(f"t = {(stamp - first.stamps_ns[first.frames[0]]) / 1e9:.2f} s")
        for tag, run, n in (("A", a, n_a), ("B", b, n_b)):
            if run is not None:
                have = index in run.stamps_ns
                gt = len(run.ground_truth.get(index, ()))
                parts.append(f"{tag}: {n} objects, {gt} GT" if have else f"{tag}: no frame")
        self.frame_label.setText("   ".join(parts))

    # -- export -----------------------------------------------------------------------------------

    def export(self, fmt: str, directory: str | Path | None = None) -> list[Path]:
        """Export run A as ``csv`` (a file per table) or ``xlsx`` (one workbook) into
        ``directory`` (asked for when None); returns the files written."""
        from redrive.results import export_run, open_run

        if self.run_a is None:
            self._error("Nothing to export: run a test or open a run first.")
            return []
        if directory is None:
            start = str(self.run_a.path / "export")
            chosen = QtWidgets.QFileDialog.getExistingDirectory(self, f"Export {fmt} into", start)
            if not chosen:
                return []
            directory = chosen
        QtWidgets.QApplication.setOverrideCursor(QtCore.Qt.CursorShape.WaitCursor)
        try:
            files = export_run(open_run(self.run_a.path), fmt=fmt, out=Path(directory))
        except Exception as err:  # the GUI's top level
            self._error(f"Export of {self.run_a.path} as {fmt} failed: {describe_error(err)}")
            return []
        finally:
            QtWidgets.QApplication.restoreOverrideCursor()
        self._status(f"Exported {len(files)} {fmt} file(s) into {directory}.")
        return files

    # -- messages ---------------------------------------------------------------------------------

    def _status(self, text: str, *, error: bool = False) -> None:
        self.status_label.setText(text)
        self.status_label.setStyleSheet("color: #d33;" if error else "")

    def _error(self, text: str) -> None:
        """Show ``text`` in the status line and in a (non-blocking) message box."""
        logger.warning("%s", text)
        self._status(text, error=True)
        if self.error_box is not None:
            self.error_box.close()
        box = QtWidgets.QMessageBox(
            QtWidgets.QMessageBox.Icon.Warning, "redrive — Re-simulation", text, parent=self
        )
        box.setAttribute(QtCore.Qt.WidgetAttribute.WA_DeleteOnClose, False)
        box.open()
        self.error_box = box


def _names(shown: Mapping[str, str]) -> str:
    """The shown algorithms, comma-separated."""
    return ", ".join(shown.values()) or "no algorithm"


def _label(data: RunData, shown: Mapping[str, str]) -> str:
    """``run-dir-name (algorithm, …)``."""
    return f"{data.path.name} ({_names(shown)})"


def _hbox(
    *items: QtWidgets.QWidget | str, stretch: QtWidgets.QWidget | None = None
) -> QtWidgets.QHBoxLayout:
    """A row of widgets (a str is a label); ``stretch`` takes the spare width."""
    row = QtWidgets.QHBoxLayout()
    for item in items:
        widget = QtWidgets.QLabel(item) if isinstance(item, str) else item
        row.addWidget(widget, 1 if item is stretch else 0)
    return row
