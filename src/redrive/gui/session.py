"""An open log (and optionally a run over it) as the GUI sees it — no Qt here.

:class:`LogSession` streams: opening reads the log's index only; frame *k* is assembled by the
Sensor Dispatcher (:class:`~redrive.assembly.frames.FrameAssembler`) starting at the log time of the
*k*-th driver sample, so a 1 GB log shows its first frame as fast as a small one.  The list of
driver samples (the timeline) is built by :meth:`LogSession.index` in the background, from a
second reader, while the first frames are already shown.

:class:`RunData` is a run directory read for display — the one run model of the GUI (main
window and Re-simulation panel): outputs per algorithm, ground truth and ego states by frame
index, and the stored evaluation's bookmarks and per-frame metrics.
"""

from __future__ import annotations

import bisect
import logging
import threading
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.assembly.frames import FrameAssembler
from redrive.errors import LogError, UnsupportedMessageError
from redrive.gui.closedloop import Deviation, read_deviation
from redrive.gui.map_layers import MapLines, map_lines
from redrive.io import LogReader, open_log
from redrive.results import Run, RunManifest, RunStatus, open_run
from redrive.types import (
    ControlCommands,
    DetectedObject,
    Frame,
    LightState,
    PlannedPath,
    VehicleState,
)

__all__ = [
    "Bookmark",
    "LogSession",
    "PerFrameSeries",
    "RunData",
    "Series",
    "find_run_log",
    "series_from_log",
]

logger = logging.getLogger(__name__)


#: how many frames ahead :meth:`LogSession.frame` reads through instead of seeking.
_READ_THROUGH = 4


class LogSession:
    """A log opened for viewing.

    Args:
        path: any log :func:`redrive.io.open_log` reads.

    Raises:
        LogError / ConfigError: the log cannot be opened or has no sensor to drive frames.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        # a damaged log is read past its damage (listed in the reader's damage_report)
        self.log: LogReader = open_log(self.path, strict=False)
        try:
            self.assembler = FrameAssembler(self.log)
        except BaseException:
            self.log.close()
            raise
        smap = self.assembler.sensor_map
        # a log without a sensor (recorded traffic) makes a frame per ground-truth message
        self.driver_topic = (
            smap.sensor(smap.driver).topic
            if smap.driver is not None
            else str(smap.ground_truth_topic)
        )
        #: log times of the driver samples seen so far (the timeline); grows while indexing.
        self.driver_times_ns: list[int] = []
        self.indexed = False
        self._index_changed = threading.Condition()
        self._frames: Iterator[Frame] | None = None
        self._next_index = 0

    @property
    def expected_frames(self) -> int:
        """Driver samples in the log's index (exact for indexed logs)."""
        info = self.log.topics.get(self.driver_topic)
        return info.count if info is not None else 0

    def index(self, *, chunk: int = 256, stop: threading.Event | None = None) -> Iterator[int]:
        """Fill :attr:`driver_times_ns` from a second reader; yields the count every ``chunk``
        samples (run it in a worker thread; :meth:`frame` waits for it when it seeks past what
        is indexed)."""
        times: list[int] = []
        with open_log(self.path, strict=False) as log:
            for message in log.messages(topics=[self.driver_topic]):
                if stop is not None and stop.is_set():
                    return
                times.append(message.log_time_ns)
                if len(times) % chunk == 0:
                    with self._index_changed:
                        self.driver_times_ns = list(times)
                        self._index_changed.notify_all()
                    yield len(times)
        with self._index_changed:
            self.driver_times_ns = times
            self.indexed = True
            self._index_changed.notify_all()
        yield len(times)

    def wait_indexed(self, index: int, *, timeout_s: float = 30.0) -> bool:
        """Wait until the timeline knows sample ``index`` (or indexing ended); whether it does."""
        with self._index_changed:
            self._index_changed.wait_for(
                lambda: self.indexed or index < len(self.driver_times_ns), timeout=timeout_s
            )
            return index < len(self.driver_times_ns)

    def frame(self, index: int) -> Frame:
        """Frame ``index`` (0-based over the driver samples); the frame's own ``index`` is set
        to it.  The next frame after the last one read comes from the same stream (cheap);
        any other index seeks.

        Raises:
            IndexError: past the end of the log (or not indexed that far yet).
            LogError: the log is damaged there.
        """
        if index < 0:
            raise IndexError(index)
        ahead = index - self._next_index
        if self._frames is not None and 0 < ahead <= _READ_THROUGH:
            # A few frames ahead (playback faster than decoding): reading through them costs
            # less than a seek, which re-reads the tolerance window before the frame.
            for _ in range(ahead):
                if next(self._frames, None) is None:
                    self._frames = None
                    raise IndexError(index)
            self._next_index = index
        if self._frames is None or index != self._next_index:
            if index == 0:
                start = None
            elif self.wait_indexed(index):
                start = self.driver_times_ns[index]
            else:
                raise IndexError(index)
            self._frames = self.assembler.frames(start_ns=start)
            self._next_index = index
        try:
            frame = next(self._frames)
        except StopIteration:
            self._frames = None
            raise IndexError(index) from None
        self._next_index = index + 1
        return replace(frame, index=index)

    def close(self) -> None:
        self._frames = None
        self.log.close()


@dataclass(frozen=True, slots=True, kw_only=True)
class Bookmark:
    """A failure frame found by evaluation (read through :mod:`redrive.results.evaluation`)."""

    frame_index: int
    stamp_ns: int
    kind: str
    metric: str
    algorithm: str
    detail: str
    severity: float


#: (metric, algorithm, series) → (stamps_ns, values): a run's per-frame metric series
PerFrameSeries = dict[tuple[str, str, str], tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]]


@dataclass(frozen=True, slots=True, kw_only=True)
class RunData:
    """A run directory read once for display — by the main window (over its log's frames) and
    by the Re-simulation panel (its views and A/B) alike.

    Everything is keyed by the run's frame index; :meth:`frame_at` finds the index of a log
    frame by its stamp.

    Attributes:
        path: the run directory.
        manifest: its manifest.
        status: the manifest's status (``complete``, ``interrupted`` …).
        algorithms: ``(name, role)`` of each algorithm, in pipeline order.
        frames: the frame indices of the run, ascending.
        stamps_ns: frame index → stamp (ns).
        detections: perception algorithm (pipeline order) → frame index → objects.
        paths: planning algorithm → frame index → planned path.
        commands: control algorithm → frame index → commands.
        ground_truth: frame index → ground-truth objects (base_link).
        ego: frame index → ego state.
        bookmarks: the failure frames of the stored evaluation, by frame.
        per_frame: the stored evaluation's per-frame series, on stamps (the plots' time axis).
        logged_ego: closed loop: frame index → the logged ego state (the ghost).
        deviation: closed loop: the deviation series and threshold crossings.
        road_map: the run's road map (``RUN/map.json``) by element (:mod:`.map_layers`: lane
            lines, road edges,
            centrelines, crosswalks, stop lines, lights); lights: frame index → light id → state.
    """

    path: Path
    manifest: RunManifest
    status: RunStatus = RunStatus.RUNNING
    algorithms: tuple[tuple[str, str], ...] = ()
    frames: tuple[int, ...] = ()
    stamps_ns: Mapping[int, int] = field(default_factory=dict)
    detections: Mapping[str, Mapping[int, tuple[DetectedObject, ...]]] = field(default_factory=dict)
    paths: Mapping[str, Mapping[int, PlannedPath]] = field(default_factory=dict)
    commands: Mapping[str, Mapping[int, ControlCommands]] = field(default_factory=dict)
    ground_truth: Mapping[int, tuple[DetectedObject, ...]] = field(default_factory=dict)
    ego: Mapping[int, VehicleState] = field(default_factory=dict)
    bookmarks: tuple[Bookmark, ...] = ()
    per_frame: PerFrameSeries = field(default_factory=dict)
    logged_ego: Mapping[int, VehicleState] = field(default_factory=dict)
    deviation: Deviation | None = None
    road_map: MapLines | None = None
    lights: Mapping[int, Mapping[str, LightState]] = field(default_factory=dict)
    _index_of_stamp: dict[int, int] = field(init=False, repr=False, compare=False)
    _sorted_stamps: list[int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "_index_of_stamp", {stamp: i for i, stamp in self.stamps_ns.items()}
        )
        object.__setattr__(self, "_sorted_stamps", sorted(self._index_of_stamp))

    def frame_at(self, stamp_ns: int) -> int | None:
        """The index of the run's frame stamped ``stamp_ns`` (None: the run has no such frame)."""
        return self._index_of_stamp.get(stamp_ns)

    def frame_after(self, stamp_ns: int, *, within_ns: int | None = None) -> int | None:
        """The index of the run's first frame stamped after ``stamp_ns`` (and at most
        ``within_ns`` after it); None when there is none."""
        stamps = self._sorted_stamps
        i = bisect.bisect_right(stamps, stamp_ns)
        if i == len(stamps) or (within_ns is not None and stamps[i] - stamp_ns > within_ns):
            return None
        return self._index_of_stamp[stamps[i]]

    @property
    def closed_loop(self) -> bool:
        """A closed-loop run: the ego drawn is the driven one."""
        return self.manifest.pipeline.mode_manager == "closed_loop"

    @property
    def closed_loop_level(self) -> str:
        """``object``, ``sensor`` (a scenario's closed loop) or ``log`` (on a recorded log);
        "" for an open-loop run."""
        entry = self.manifest.closed_loop
        if not self.closed_loop:
            return ""
        if entry.get("backend") == "log":
            return "log"
        return "sensor" if entry.get("level") == "sensor" else "object"

    @classmethod
    def load(cls, path: str | Path) -> RunData:
        """Read a run directory (and its evaluation, when it has one).  An algorithm that never
        ran a step (a run cancelled before its first frame) has no outputs.

        Raises:
            ConfigError: ``path`` is not a readable run directory.
        """
        run = open_run(path)
        frames = run.table("frames").to_pydict()
        by_index = {
            int(i): int(s) for i, s in zip(frames["frame_index"], frames["stamp_ns"], strict=True)
        }
        algorithms = tuple(_algorithms(run))
        outputs: dict[str, dict[str, Mapping[int, Any]]] = {
            "perception": {},
            "planning": {},
            "control": {},
        }
        readers: dict[str, Callable[[str], Mapping[int, Any]]] = {
            "perception": run.detections,
            "planning": run.paths,
            "control": run.commands,
        }
        for algorithm, role in algorithms:
            if role in readers:
                outputs[role][algorithm] = _outputs(readers[role], algorithm)
        bookmarks, per_frame = _evaluation(run, by_index)
        road_map = run.road_map()
        return cls(
            path=Path(path),
            manifest=run.manifest,
            status=run.manifest.status,
            algorithms=algorithms,
            frames=tuple(sorted(by_index)),
            stamps_ns=by_index,
            detections=outputs["perception"],
            paths=outputs["planning"],
            commands=outputs["control"],
            ground_truth=run.ground_truth(),
            ego=run.ego(),
            bookmarks=bookmarks,
            per_frame=per_frame,
            logged_ego=run.logged_ego(),
            deviation=read_deviation(run),
            road_map=None if road_map is None else map_lines(road_map),
            lights={
                f: {t.id: t.state for t in lights} for f, lights in run.traffic_lights().items()
            },
        )


_BOOKMARK_FIELDS = ("frame_index", "stamp_ns", "kind", "metric", "algorithm", "detail", "severity")


def _algorithms(run: Run) -> list[tuple[str, str]]:
    return [(entry.name, entry.role.value) for entry in run.manifest.algorithms]


def _outputs(read: Callable[[str], Mapping[int, Any]], algorithm: str) -> Mapping[int, Any]:
    try:
        return read(algorithm)
    except ValueError:  # no step at all (Run.detections/paths/commands raise for it)
        return {}


def _evaluation(
    run: Run, by_index: Mapping[int, int]
) -> tuple[tuple[Bookmark, ...], PerFrameSeries]:
    """The stored evaluation's bookmarks and per-frame series (none when not evaluated)."""
    from redrive.results.evaluation import read_evaluation, stored_metric_names

    if not stored_metric_names(run.path):
        return (), {}
    evaluation = read_evaluation(run.path)
    bookmarks = sorted(
        (Bookmark(**{k: r[k] for k in _BOOKMARK_FIELDS}) for r in evaluation.bookmarks.to_pylist()),
        key=lambda b: (b.frame_index, b.kind),
    )
    table = evaluation.per_frame.to_pydict()
    groups: dict[tuple[str, str, str], tuple[list[int], list[float]]] = {}
    for m, a, s, i, v in zip(
        table["metric"],
        table["algorithm"],
        table["series"],
        table["frame_index"],
        table["value"],
        strict=True,
    ):
        if i in by_index:
            xs, ys = groups.setdefault((m, a, s), ([], []))
            xs.append(by_index[i])
            ys.append(float("nan") if v is None else v)
    per_frame = {
        key: (np.array(xs, dtype=np.int64), np.array(ys, dtype=np.float64))
        for key, (xs, ys) in groups.items()
    }
    return tuple(bookmarks), per_frame


def find_run_log(run: RunData) -> Path | None:
    """The log to show a run over, if it is there: a sensor-level closed-loop run's recording
    of its rendered sensors (``closed_loop.sensor_log``, in the run directory), else the log
    the run was made from, where the manifest says."""
    recorded = run.manifest.closed_loop.get("sensor_log")
    if isinstance(recorded, str) and recorded:
        sensor_log = run.path / recorded
        return sensor_log if sensor_log.is_file() else None
    path = run.manifest.log.path
    if path and Path(path).exists():
        return Path(path)
    return None


@dataclass(slots=True, kw_only=True)
class Series:
    """Time series of the log for the plots (stamps ns, values)."""

    speed_mps: tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]] | None = None
    yaw_rate_rad_s: tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]] | None = None
    imu_accel: tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]] | None = None  # (N, 3)


def series_from_log(
    path: Path,
    assembler: FrameAssembler,
    *,
    max_samples: int = 200_000,
    stop: threading.Event | None = None,
) -> Series:
    """Ego speed, yaw rate and IMU series of a log (small topics; read with their own reader);
    ``stop`` ends the reading early."""
    from redrive.io.ros.decoders import decode
    from redrive.types import Imu
    from redrive.types.enums import SensorType

    smap = assembler.sensor_map
    imu_topics = [s.topic for s in smap.sensors if s.sensor_type is SensorType.IMU][:1]
    state_topic = smap.vehicle_state_topic
    topics = [t for t in [state_topic, *imu_topics] if t]
    out = Series()
    if not topics:
        return out
    st: list[int] = []
    speed: list[float] = []
    yaw: list[float] = []
    it: list[int] = []
    acc: list[Any] = []
    with open_log(path, strict=False) as log:
        for n, message in enumerate(log.messages(topics=topics)):
            if n >= max_samples or (stop is not None and stop.is_set()):
                break
            try:
                decoded = decode(message, log.deserialize)
            except (LogError, UnsupportedMessageError):
                continue
            value = decoded.value
            if isinstance(value, VehicleState):
                st.append(value.stamp_ns)
                speed.append(float(np.hypot(value.velocity[0], value.velocity[1])))
                yaw.append(value.yaw_rate_rad_s)
            elif isinstance(value, Imu):
                it.append(decoded.stamp_ns)
                acc.append(value.linear_acceleration)
    if st:
        stamps = np.array(st, dtype=np.int64)
        out.speed_mps = (stamps, np.array(speed))
        out.yaw_rate_rad_s = (stamps, np.array(yaw))
    if it:
        stamps = np.array(it, dtype=np.int64)
        out.imu_accel = (stamps, np.array(acc, dtype=np.float64))
    return out
