"""The Re-simulation panel's parts: the worker that runs an algorithm test, which of a run's
algorithms are shown, and the top-down views.

:class:`RunThread` runs the engine over a log, evaluates the run and reads it back
(:class:`~redrive.gui.session.RunData`, the GUI's one run model, read once into per-frame dicts,
so moving the frame slider only looks frames up), off the GUI thread.

A :class:`TopDownView` shows one frame of one run: x (forward) up the screen, y (left) to the
left, metres, the ego outline at the origin (the rear-axle centre).  It draws the shown
algorithms' results — detections as oriented box outlines with a heading tick, a planned path as a
polyline, control commands as text — and, when it is a result-over-ground-truth view, the
ground-truth boxes in another colour.  Each layer is ONE ``PlotCurveItem`` (``connect="pairs"``)
whatever the number of boxes, so a frame with hundreds of objects redraws fast.
"""

from __future__ import annotations

import logging
import math
import os
import tempfile
import threading
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pyqtgraph as pg
from PySide6 import QtCore

from redrive.geometry.boxes import BOX_CORNER_SIGNS
from redrive.gui.session import RunData
from redrive.results import RunSetup, RunStatus
from redrive.types import ControlCommands, DetectedObject, ObjectColumns, PlannedPath

if TYPE_CHECKING:
    from redrive.config import PipelineConfig

__all__ = [
    "CATEGORIES",
    "EGO_LENGTH_M",
    "EGO_REAR_OVERHANG_M",
    "EGO_WIDTH_M",
    "REFERENCE_DETECTOR",
    "REFERENCE_PLANNER",
    "REFERENCE_TRACKER",
    "RunOutcome",
    "RunThread",
    "SummaryRow",
    "TopDownView",
    "algorithm_test_pipeline",
    "box_outline_segments",
    "default_run_dir",
    "describe_error",
    "shown_algorithms",
    "stored_summary_rows",
]

logger = logging.getLogger(__name__)

#: the ego outline drawn at the origin (the rear-axle centre), as the reference planner assumes.
EGO_LENGTH_M = 4.7
EGO_WIDTH_M = 1.9
EGO_REAR_OVERHANG_M = 0.95

RESULT_PEN = pg.mkPen((255, 140, 0), width=2)
GT_PEN = pg.mkPen((40, 200, 90), width=2)
PATH_PEN = pg.mkPen((60, 160, 255), width=2)
EGO_PEN = pg.mkPen((170, 170, 170), width=1)

_EMPTY = np.zeros(0, dtype=np.float64)
#: bottom-face corners (front-left, rear-left, rear-right, front-right) as (length, width) signs.
_FACE = BOX_CORNER_SIGNS[:4, :2]
#: the 5 segments drawn per box: the 4 edges of the bottom face, then centre → front edge.
_EDGE_FROM = np.array([0, 1, 2, 3], dtype=np.intp)
_EDGE_TO = np.array([1, 2, 3, 0], dtype=np.intp)


def box_outline_segments(
    objects: Sequence[DetectedObject],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Plot coordinates of the outlines of ``objects`` (base_link boxes) as segment pairs.

    Returns ``(h, v)``: ``h`` = base_link y (plotted on an inverted axis, so left is left), ``v``
    = base_link x (up the screen); ``10 * len(objects)`` points, consecutive pairs are segments
    (``connect="pairs"``): the bottom face's 4 edges (corners as
    :func:`~redrive.geometry.boxes.box_corners`), then a heading tick from the centre to the front
    edge.
    """
    n = len(objects)
    if n == 0:
        return _EMPTY, _EMPTY
    columns = ObjectColumns.from_objects(objects)
    centers = columns.center_m[:, :2]  # (n, 2)
    half = columns.size_m[:, :2] * 0.5  # (n, 2)
    yaw = columns.yaw_rad
    cos, sin = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    local = _FACE[None, :, :] * half[:, None, :]  # (n, 4, 2) in the box frame
    corners = np.empty_like(local)
    corners[..., 0] = local[..., 0] * cos - local[..., 1] * sin + centers[:, None, 0]
    corners[..., 1] = local[..., 0] * sin + local[..., 1] * cos + centers[:, None, 1]
    front = centers + half[:, :1] * np.hstack([cos, sin])  # (n, 2) middle of the front edge
    points = np.empty((n, 5, 2, 2), dtype=np.float64)  # box, segment, end, xy
    points[:, :4, 0] = corners[:, _EDGE_FROM]
    points[:, :4, 1] = corners[:, _EDGE_TO]
    points[:, 4, 0] = centers
    points[:, 4, 1] = front
    flat = points.reshape(-1, 2)
    return np.ascontiguousarray(flat[:, 1]), np.ascontiguousarray(flat[:, 0])


def _ego_outline() -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    rear, front, half_w = -EGO_REAR_OVERHANG_M, EGO_LENGTH_M - EGO_REAR_OVERHANG_M, EGO_WIDTH_M / 2
    # the closed outline, then a nose pointing forward: one connected line
    x = np.array([front, rear, rear, front, front, front + 0.6, front])
    y = np.array([half_w, half_w, -half_w, -half_w, half_w, 0.0, -half_w])
    return y, x


def shown_algorithms(setup: RunSetup, prefer: Iterable[str] = ()) -> dict[str, str]:
    """role (``perception`` …) → the algorithm of a run whose results are drawn.

    The ``prefer`` names found in the run (the algorithm under test) and nothing else; when none
    is found, the last algorithm of each role (the reference pipeline: tracker, planner,
    controller).
    """
    roles = [(a.name, a.role.value) for a in setup.algorithms]
    wanted = set(prefer)
    chosen = {role: name for name, role in roles if name in wanted}
    if chosen:
        return chosen
    return {role: name for name, role in roles}  # later entries win: the last of each role


@dataclass(frozen=True, slots=True, kw_only=True)
class SummaryRow:
    """One line of the evaluation summary: a metric's headline value (or why it was skipped)."""

    algorithm: str
    metric: str
    key: str
    value: float
    unit: str
    note: str = ""


def stored_summary_rows(run_dir: Path, shown: set[str]) -> tuple[SummaryRow, ...]:
    """The headline values of a run's stored evaluation (first value of each metric and
    algorithm) for the ``shown`` algorithms and the run itself; empty when not evaluated."""
    from redrive.errors import ConfigError
    from redrive.results.evaluation import read_evaluation

    try:
        values = read_evaluation(run_dir).values.to_pylist()
    except ConfigError:
        return ()
    rows: dict[tuple[str, str], SummaryRow] = {}
    for v in values:
        algo = str(v["algorithm"])
        if (algo in shown or not algo) and (v["metric"], algo) not in rows:
            rows[(v["metric"], algo)] = SummaryRow(
                algorithm=algo, metric=v["metric"], key=v["key"], value=v["value"], unit=v["unit"]
            )
    return tuple(rows.values())


# -- the worker ------------------------------------------------------------------------------------


#: the Algorithm Category choices: the roles of :class:`redrive.algorithms.Role`.
CATEGORIES = ("perception", "planning", "control")

#: the reference algorithms put upstream of an algorithm under test (``redrive run``'s defaults).
REFERENCE_DETECTOR = "cluster-detector"
REFERENCE_TRACKER = "kalman-tracker"
REFERENCE_PLANNER = "idm-planner"


def algorithm_test_pipeline(category: str, spec: str) -> tuple[PipelineConfig, str]:
    """The pipeline that tests algorithm ``spec`` of role ``category``, and its name in the run.

    As ``redrive run --perception SPEC`` (… ``--planning`` / ``--control``), with what the
    algorithm needs upstream taken from the reference pipeline, and nothing downstream:

    - perception: ``SPEC`` alone; an algorithm that reads no sensor (a tracker, fed by the
      detections upstream) gets the reference detector before it;
    - planning: reference detector → tracker → ``SPEC`` (a planner plans around the objects
      perception found);
    - control: reference detector → tracker → planner → ``SPEC`` (a controller follows a path).

    Raises:
        ConfigError, PluginError: ``category`` is not a role, ``spec`` cannot be loaded.
    """
    from redrive.algorithms.discovery import load_algorithm_class
    from redrive.config import pipeline_from_plugins
    from redrive.errors import ConfigError

    perception: list[str] = [REFERENCE_DETECTOR, REFERENCE_TRACKER]
    if category == "perception":
        reads_sensors = bool(load_algorithm_class(spec).inputs)
        perception = [spec] if reads_sensors else [REFERENCE_DETECTOR, spec]
        pipeline = pipeline_from_plugins(perception=perception)
    elif category == "planning":
        pipeline = pipeline_from_plugins(perception=perception, planning=[spec])
    elif category == "control":
        pipeline = pipeline_from_plugins(
            perception=perception, planning=[REFERENCE_PLANNER], control=[spec]
        )
    else:
        msg = f"algorithm category {category!r} is not one of {', '.join(CATEGORIES)}"
        raise ConfigError(msg)
    return pipeline, pipeline.stages[-1].algorithms[0].name


def default_run_dir(log: Path, algorithm: str) -> Path:
    """A new run directory ``runs/LOG-ALGORITHM-TIME`` beside the log (in the temp directory
    when the log's directory is not writable); never an existing one."""
    base = log.parent / "runs"
    if not os.access(log.parent, os.W_OK) or (base.exists() and not os.access(base, os.W_OK)):
        base = Path(tempfile.gettempdir()) / "redrive-runs"
    stem = log.name.removesuffix(".bag").removesuffix(".mcap") or "run"
    safe_algo = "".join(c if c.isalnum() or c in "-_." else "_" for c in algorithm)
    name = f"{stem}-{safe_algo}-{time.strftime('%Y%m%d-%H%M%S')}"
    out, n = base / name, 1
    while out.exists():
        n += 1
        out = base / f"{name}-{n}"
    return out


@dataclass(frozen=True, slots=True, kw_only=True)
class RunOutcome:
    """What the worker hands back: the run, its status, what it says, its data to draw and the
    algorithms shown (role → name, :func:`shown_algorithms`)."""

    out: Path
    status: RunStatus
    message: str
    data: RunData
    shown: Mapping[str, str]
    rows: tuple[SummaryRow, ...] = field(default_factory=tuple)


def describe_error(err: BaseException) -> str:
    """``Type: message`` — redrive's messages already say what, where and what to do."""
    return f"{type(err).__name__}: {err}"


def _report_message(report: Any, out: Path) -> str:
    text = f"{report.frames} frames in {report.wall_s:.1f} s ({report.frames_per_s:.0f} frames/s)"
    errors = [a for a in report.algorithms if a.error or a.timeout]
    for a in errors:
        text += f"; {a.name}: {a.error + a.timeout} failed steps, first at {a.first_error}"
    return f"{text} → {out}"


class RunThread(QtCore.QThread):
    """Runs, evaluates and reads one algorithm test off the GUI thread.

    Signals: ``total(object)`` (frames expected or None), ``progressed(int)`` (percent, or frames
    done when the total is unknown), ``succeeded(RunOutcome)`` (complete or cancelled),
    ``failed(str)`` (the error, naming what failed).
    """

    total = QtCore.Signal(object)
    progressed = QtCore.Signal(int)
    succeeded = QtCore.Signal(object)
    failed = QtCore.Signal(str)

    def __init__(self, *, log: Path, out: Path, category: str, spec: str) -> None:
        super().__init__()
        self.log, self.out, self.category, self.spec = log, out, category, spec
        self.cancel_event = threading.Event()
        self._total: int | None = None
        self._last = -1

    def run(self) -> None:  # the thread's body
        try:
            outcome = self._work()
        except Exception as err:  # the GUI's top level: every error is shown, none kills it
            logger.exception("algorithm test of %s on %s failed", self.spec, self.log)
            self.failed.emit(
                f"algorithm test of {self.spec} on {self.log} failed: {describe_error(err)}"
            )
            return
        self.succeeded.emit(outcome)

    def _on_start(self, total: int | None) -> None:
        self._total = total
        self.total.emit(total)

    def _on_progress(self, done: int) -> None:
        value = done if not self._total else min(100, math.floor(100 * done / self._total))
        if value != self._last and (self._total or done % 10 == 0):  # few signals on long logs
            self._last = value
            self.progressed.emit(value)

    def _work(self) -> RunOutcome:
        from redrive.engine import RunRequest, run_log
        from redrive.evaluation.evaluator import evaluate_run, headline

        pipeline, name = algorithm_test_pipeline(self.category, self.spec)
        request = RunRequest(log=self.log, pipeline=pipeline, out=self.out, strict=False)
        report = run_log(
            request, on_start=self._on_start, progress=self._on_progress, cancel=self.cancel_event
        )
        message = _report_message(report, self.out)
        if report.status is not RunStatus.COMPLETE:  # cancelled (fail-fast is off: never "failed")
            return self._outcome(report.status, message, name)
        try:
            summary = evaluate_run(self.out, algorithms=[name])
        except Exception as err:  # the run is complete and shown all the same
            logger.exception("evaluating %s failed", self.out)
            message += f"; evaluation failed: {describe_error(err)}"
            return self._outcome(RunStatus.COMPLETE, message, name)
        rows = [
            SummaryRow(algorithm=s.algorithm, metric=s.metric.name, key=k, value=v, unit=u)
            for s in summary.scored
            for k, v, u in [headline(s)]
        ]
        rows += [
            SummaryRow(
                algorithm=s.algorithm, metric=s.metric, key="", value=math.nan, unit="",
                note=f"{'error' if s.error else 'skipped'}: {s.reason}",
            )
            for s in (*summary.failed, *summary.skipped)
        ]  # fmt: skip
        return self._outcome(RunStatus.COMPLETE, message, name, rows)

    def _outcome(
        self, status: RunStatus, message: str, name: str, rows: Sequence[SummaryRow] = ()
    ) -> RunOutcome:
        """The run as the views draw it, the algorithm under test ``name`` shown."""
        data = RunData.load(self.out)
        shown = shown_algorithms(data.manifest, [name])
        return RunOutcome(
            out=self.out, status=status, message=message, data=data, shown=shown, rows=tuple(rows)
        )


# -- the views -------------------------------------------------------------------------------------


class TopDownView(pg.PlotWidget):
    """One frame of one run, top-down in base_link.

    Args:
        title: shown above the plot.
        with_ground_truth: also draw the ground-truth boxes (the result-over-GT view).

    Attributes (one item per layer; tests read their data):
        result_boxes: the shown perception algorithm's boxes.
        gt_boxes: the ground-truth boxes (empty unless ``with_ground_truth``).
        path_curve: the shown planning algorithm's path.
        command_text: the shown control algorithm's commands.
    """

    def __init__(self, title: str, *, with_ground_truth: bool, parent: Any = None) -> None:
        super().__init__(parent=parent)
        self.with_ground_truth = with_ground_truth
        self.setTitle(title)
        self.setAspectLocked(True)
        self.showGrid(x=True, y=True, alpha=0.2)
        item = self.getPlotItem()
        item.setLabel("bottom", "y (left)", units="m")
        item.setLabel("left", "x (forward)", units="m")
        item.getViewBox().invertX(True)  # y is left: positive y plotted to the left
        self.ego = pg.PlotCurveItem(*_ego_outline(), pen=EGO_PEN)
        self.gt_boxes = pg.PlotCurveItem(pen=GT_PEN, connect="pairs")
        self.result_boxes = pg.PlotCurveItem(pen=RESULT_PEN, connect="pairs")
        self.path_curve = pg.PlotCurveItem(pen=PATH_PEN)
        self.command_text = pg.TextItem(color=(230, 230, 230), anchor=(0.5, 0.0))
        self.command_text.setPos(0.0, -EGO_REAR_OVERHANG_M - 0.5)
        for layer in (self.ego, self.gt_boxes, self.result_boxes, self.path_curve):
            self.addItem(layer)
        self.addItem(self.command_text)
        self.reset_range()

    def reset_range(self) -> None:
        """30 m to each side, 20 m behind and 60 m ahead of the ego."""
        self.setRange(xRange=(-30.0, 30.0), yRange=(-20.0, 60.0), padding=0.0)
        self.disableAutoRange()

    def follow(self, leader: TopDownView) -> None:
        """Keep this view at ``leader``'s centre and scale (metres per pixel); panning or
        zooming this view moves ``leader`` (and so every view following it).

        Not ``setXLink``/``setYLink``: those copy the x range and line up the y range per pixel,
        which with locked aspect ratios and views of different widths makes each view re-expand
        the other's range until they are kilometres wide.  Centre and scale are what "the same
        zoom and pan" means for views of different sizes.
        """
        leader.getViewBox().sigRangeChanged.connect(lambda *_: self.match(leader))
        self.getViewBox().sigRangeChangedManually.connect(lambda *_: leader.match(self))
        self.getViewBox().sigResized.connect(lambda *_: self.match(leader))
        self.match(leader)

    def match(self, other: TopDownView) -> None:
        """Show ``other``'s centre at ``other``'s scale (metres per pixel) in this view's size."""
        mine, theirs = self.getViewBox(), other.getViewBox()
        w, h, ow, oh = mine.width(), mine.height(), theirs.width(), theirs.height()
        if min(w, h, ow, oh) < 2:  # hidden, or not laid out yet
            return
        (x0, x1), (y0, y1) = other.viewRange()
        m_per_px = max((x1 - x0) / ow, (y1 - y0) / oh)
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        half_w, half_h = m_per_px * w / 2, m_per_px * h / 2
        self.setRange(
            xRange=(cx - half_w, cx + half_w), yRange=(cy - half_h, cy + half_h), padding=0.0
        )

    def show_frame(
        self, data: RunData | None, frame_index: int | None, *, shown: Mapping[str, str]
    ) -> int:
        """Draw ``frame_index`` of ``data``: the outputs of the ``shown`` algorithms (role →
        name, :func:`shown_algorithms`) — nothing when either is None or the run does not have
        that frame; returns the number of result objects drawn."""
        if data is None or frame_index is None:
            self._draw((), (), None, None)
            return 0

        def output(outputs: Mapping[str, Mapping[int, Any]], role: str) -> Any:
            return outputs.get(shown.get(role, ""), {}).get(frame_index)

        detections = output(data.detections, "perception") or ()
        truth = data.ground_truth.get(frame_index, ()) if self.with_ground_truth else ()
        self._draw(
            detections, truth, output(data.paths, "planning"), output(data.commands, "control")
        )
        return len(detections)

    def _draw(
        self,
        detections: Sequence[DetectedObject],
        truth: Sequence[DetectedObject],
        path: PlannedPath | None,
        commands: ControlCommands | None,
    ) -> None:
        self.result_boxes.setData(*box_outline_segments(detections), connect="pairs")
        self.gt_boxes.setData(*box_outline_segments(truth), connect="pairs")
        if path is not None and len(path.waypoints):
            self.path_curve.setData(path.waypoints[:, 1], path.waypoints[:, 0])
        else:
            self.path_curve.setData(_EMPTY, _EMPTY)
        self.command_text.setText(_commands_text(commands))


def _commands_text(commands: ControlCommands | None) -> str:
    if commands is None:
        return ""
    steer_deg = math.degrees(commands.steering_angle_rad)
    return (
        f"throttle {commands.throttle:.2f}   brake {commands.brake:.2f}\n"
        f"steering {commands.steering_angle_rad:+.3f} rad ({steer_deg:+.1f}°)"
    )
