"""An open log (and optionally a run over it) as the GUI sees it — no Qt here.

:class:`LogSession` streams: opening reads the log's index only; frame *k* is assembled by the
Sensor Dispatcher (:class:`~redrive.io.frames.FrameAssembler`) starting at the log time of the
*k*-th driver sample, so a 1 GB log shows its first frame as fast as a small one.  The list of
driver samples (the timeline) is built by :meth:`LogSession.index` in the background, from a
second reader, while the first frames are already shown.

:class:`RunData` is a run directory's outputs keyed by frame stamp: detections per algorithm,
ground truth, planned paths, ego states, bookmarks and per-frame metrics.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import LogError, UnsupportedMessageError
from redrive.io import LogReader, open_log
from redrive.io.frames import FrameAssembler
from redrive.results import Run, RunManifest, open_run
from redrive.types import DetectedObject, Frame, PlannedPath, Role, VehicleState

__all__ = ["Bookmark", "LogSession", "RunData", "find_run_log", "series_from_log"]

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
        self.log: LogReader = open_log(self.path)
        try:
            self.assembler = FrameAssembler(self.log)
        except BaseException:
            self.log.close()
            raise
        smap = self.assembler.sensor_map
        self.driver_topic = smap.sensor(smap.driver or "").topic
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
        with open_log(self.path) as log:
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


@dataclass(slots=True, kw_only=True)
class RunData:
    """A run's outputs, keyed by frame stamp (ns) so they line up with a log's frames."""

    path: Path
    manifest: RunManifest
    detections: dict[str, dict[int, tuple[DetectedObject, ...]]] = field(default_factory=dict)
    ground_truth: dict[int, tuple[DetectedObject, ...]] = field(default_factory=dict)
    paths: dict[str, dict[int, PlannedPath]] = field(default_factory=dict)
    ego: dict[int, VehicleState] = field(default_factory=dict)
    stamps: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    bookmarks: list[Bookmark] = field(default_factory=list)
    #: (metric, algorithm, series) → (stamps_ns, values)
    per_frame: dict[tuple[str, str, str], tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]] = (
        field(default_factory=dict)
    )

    @classmethod
    def load(cls, path: str | Path) -> RunData:
        """Read a run directory (and its evaluation, when it has one).

        Raises:
            LogError: ``path`` is not a readable run directory.
        """
        run = open_run(path)
        data = cls(path=Path(path), manifest=run.manifest)
        frames = run.table("frames").to_pydict()
        by_index = dict(zip(frames["frame_index"], frames["stamp_ns"], strict=True))
        data.stamps = np.array(sorted(by_index.values()), dtype=np.int64)
        for entry in run.manifest.algorithms:
            if entry.role is Role.PERCEPTION:
                data.detections[entry.name] = _by_stamp(run.detections(entry.name), by_index)
            elif entry.role is Role.PLANNING:
                data.paths[entry.name] = _by_stamp(run.paths(entry.name), by_index)
        data.ground_truth = _by_stamp(run.ground_truth(), by_index)
        data.ego = _by_stamp(run.ego(), by_index)
        _load_evaluation(data, run, by_index)
        return data


_BOOKMARK_FIELDS = ("frame_index", "stamp_ns", "kind", "metric", "algorithm", "detail", "severity")


def _by_stamp(values: Mapping[int, Any], by_index: Mapping[int, int]) -> dict[int, Any]:
    return {by_index[i]: v for i, v in values.items() if i in by_index}


def _load_evaluation(data: RunData, run: Run, by_index: Mapping[int, int]) -> None:
    from redrive.results.evaluation import read_evaluation, stored_metric_names

    if not stored_metric_names(run.path):
        return
    evaluation = read_evaluation(run.path)
    data.bookmarks = sorted(
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
    data.per_frame = {
        key: (np.array(xs, dtype=np.int64), np.array(ys, dtype=np.float64))
        for key, (xs, ys) in groups.items()
    }


def find_run_log(run: RunData) -> Path | None:
    """The log a run was made from, if it is still where the manifest says."""
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
    from redrive.io.decoders import decode
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
    with open_log(path) as log:
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
