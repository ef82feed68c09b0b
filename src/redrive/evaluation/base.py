"""The metric contract: one small base class per metric, found like algorithms.

A metric reads a run directory (through :class:`EvalData`, which caches what it loads) for one
algorithm of the run (or for the run as a whole) and returns a :class:`MetricResult`: named
aggregate values (the first is the headline), per-frame series, curves (precision/recall …) and
failure-frame bookmarks.  Metrics are plugins of the ``redrive.metrics`` entry-point group; the
run manifest records each metric's name, version and parameters so that numbers made under
different definitions are never compared silently.

>>> class MeanObjects(Metric):
...     '''Mean number of objects per frame.'''
...     name = "mean_objects"
...     role = Role.PERCEPTION
...     needs = frozenset({"detections"})
...     unit = "objects"
...     def evaluate(self, data):
...         per = data.detections()
...         counts = np.array([len(v) for v in per.values()], dtype=np.float64)
...         frames = np.array(sorted(per), dtype=np.int64)
...         return MetricResult(values={"mean": float(counts.mean()) if counts.size else 0.0},
...                             per_frame={"objects": (frames, counts)})
"""

from __future__ import annotations

import hashlib
import json
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar, TypeVar, cast

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from redrive.errors import ConfigError, PluginError
from redrive.results import Run
from redrive.types import (
    ControlCommands,
    DetectedObject,
    PlannedPath,
    RoadMap,
    Role,
    TrafficLight,
    VehicleState,
)

__all__ = [
    "NEEDS",
    "POOLING_RULES",
    "SCORES",
    "SCORES_EGO",
    "SCORES_OUTPUT",
    "STATISTICS",
    "SUBJECT_LOG",
    "WHOLE_RUN",
    "Bookmark",
    "EvalData",
    "Metric",
    "MetricResult",
    "MetricSkipped",
    "Series",
    "params_hash",
]

_T = TypeVar("_T")

#: what a metric may need from a run.
NEEDS = frozenset(
    {
        "ground_truth",
        "ego",
        "logged_ego",
        "closed_loop",
        "road_map",
        "traffic_lights",
        "detections",
        "paths",
        "commands",
        "steps",
        "frames",
    }
)
#: what provides each need, for the message when a run lacks it.
NEED_SOURCES: Mapping[str, str] = MappingProxyType(
    {
        "ground_truth": "a log with ground-truth objects",
        "ego": "a log with the ego state (odometry)",
        "logged_ego": "a closed-loop run, which stores the logged ego apart from the driven one",
        "closed_loop": "a closed-loop run (its closed_loop table: the command that moved the ego each frame)",
        "road_map": "a road map in the run (runs of a synthetic scenario or its log store one; recorded logs have none)",
        "traffic_lights": "a log with traffic-light states (synthetic scenarios with lights record them)",
        "detections": "a perception algorithm with at least one successful step",
        "paths": "a planning algorithm with at least one successful step",
        "commands": "a control algorithm with at least one successful step",
        "steps": "a run with at least one algorithm step",
        "frames": "a run with at least one frame",
    }
)


class MetricSkipped(Exception):  # noqa: N818 - a skip is an outcome, not an error
    """Raised by :meth:`Metric.evaluate` when the metric does not apply to what it was given
    (say, a detector without track ids for a tracking metric); the reason is shown to the user.

    Any other exception a metric raises is an error: reported, and the command exits non-zero.
    """

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


#: how a metric pools across the logs of a batch (``Metric.pooling``).
POOLING_RULES = ("concatenate", "frame_weighted_mean", "scenario_mean", "none")

#: what ``Metric.role`` is stored as when a metric scores the run as a whole (``role = None``).
WHOLE_RUN = "run"

#: what a value scores (``Metric.scores``, ``MetricResult.scores``): the algorithm's own output
#: (its boxes, plans, commands, step times) …
SCORES_OUTPUT = "output"
#: … or the ego's motion (the ``ego`` table): in open loop that is the *logged* ego, the same
#: whatever the pipeline did, so its values are the log's, not an algorithm's.
SCORES_EGO = "ego"
SCORES = (SCORES_OUTPUT, SCORES_EGO)
#: the stored ``subject`` of a value that scores the logged ego of an open-loop run.
SUBJECT_LOG = "log"
#: how a value is made from a per-frame series (``MetricResult.statistics``): the statistic
#: over the frames that ``redrive compare`` bootstraps for the value's confidence interval.
STATISTICS = ("mean", "sum", "max", "min", "max_abs", "rms", "p50", "p95", "p99")

#: a per-frame series: (frame indices int64 (N,), values float64 (N,)).
Series = tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]


@dataclass(frozen=True, slots=True, kw_only=True)
class Bookmark:
    """A frame worth looking at: a metric crossed a threshold there.

    Attributes:
        frame_index: the frame (``Frame.index``).
        kind: what happened: ``missed_object``, ``collision``, ``low_ttc``, ``deadline_miss`` …
        detail: one line for a human ("car 12.3 m ahead not detected").
        severity: larger is worse (e.g. 1/distance, 1/TTC, ms over the deadline); used to rank.
        metric, algorithm: filled in by the evaluator.
    """

    frame_index: int
    kind: str
    detail: str = ""
    severity: float = 0.0
    metric: str = ""
    algorithm: str = ""


@dataclass(frozen=True, slots=True, kw_only=True)
class MetricResult:
    """What a metric says about one algorithm (or the run).

    Attributes:
        values: named aggregates, the headline first (``{"mAP": 0.61, "NDS": 0.55, "AP/car/2.0": …}``);
            NaN where a value is undefined (e.g. no ground truth of a class).
        units: unit per value name when it differs from the metric's ``unit``.
        per_frame: named per-frame series (frame indices, values).
        curves: named curves (x, y), e.g. ``PR/car/2.0`` → (recall, precision).
        bookmarks: failure frames.
        higher_is_better: per value name, where it differs from the metric's
            ``higher_is_better`` (e.g. ``{"MOTP": False, "num_switches": False}``); None for a
            value that is neither better nor worse when it grows (a count of what the log
            held, a parameter echoed): compared, it gets no verdict.
        scores: per value (or per-frame series) name, what it scores where it differs from the
            metric's :meth:`Metric.scores_kind`: :data:`SCORES_OUTPUT` (the algorithm's output)
            or :data:`SCORES_EGO` (the ego's motion, the logged one in open loop).
        statistics: per value name, the per-frame series it is made from and the statistic over
            the frames (:data:`STATISTICS`): ``{"max_lon_accel_mps2": ("max_lon_accel_mps2",
            "max")}``; ``redrive compare`` bootstraps that statistic for the value's confidence
            interval.  A value not named here gets a CI only when it is the mean of the series
            of its own name (checked on the stored numbers).
    """

    values: Mapping[str, float]
    units: Mapping[str, str] = field(default_factory=dict)
    higher_is_better: Mapping[str, bool | None] = field(default_factory=dict)
    per_frame: Mapping[str, Series] = field(default_factory=dict)
    curves: Mapping[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]] = field(
        default_factory=dict
    )
    bookmarks: Sequence[Bookmark] = ()
    scores: Mapping[str, str] = field(default_factory=dict)
    statistics: Mapping[str, tuple[str, str]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "values", MappingProxyType({k: float(v) for k, v in self.values.items()})
        )
        object.__setattr__(self, "units", MappingProxyType(dict(self.units)))
        object.__setattr__(self, "higher_is_better", MappingProxyType(dict(self.higher_is_better)))
        per_frame = {}
        for key, (frames, vals) in self.per_frame.items():
            f = np.asarray(frames, dtype=np.int64)
            v = np.asarray(vals, dtype=np.float64)
            if f.shape != v.shape or f.ndim != 1:
                msg = (
                    f"MetricResult.per_frame[{key!r}]: frames {f.shape} and values {v.shape} differ"
                )
                raise ValueError(msg)
            per_frame[key] = (f, v)
        object.__setattr__(self, "per_frame", MappingProxyType(per_frame))
        curves = {}
        for key, (x, y) in self.curves.items():
            cx, cy = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
            if cx.shape != cy.shape or cx.ndim != 1:
                msg = f"MetricResult.curves[{key!r}]: x {cx.shape} and y {cy.shape} differ"
                raise ValueError(msg)
            curves[key] = (cx, cy)
        object.__setattr__(self, "curves", MappingProxyType(curves))
        object.__setattr__(self, "bookmarks", tuple(self.bookmarks))
        bad = sorted(k for k, v in self.scores.items() if v not in SCORES)
        if bad:
            msg = f"MetricResult.scores[{bad[0]!r}]: give one of {', '.join(SCORES)}"
            raise ValueError(msg)
        object.__setattr__(self, "scores", MappingProxyType(dict(self.scores)))
        stats = {}
        for key, (series, stat) in self.statistics.items():
            if stat not in STATISTICS:
                msg = (
                    f"MetricResult.statistics[{key!r}]: statistic {stat!r} is not one of "
                    f"{', '.join(STATISTICS)}"
                )
                raise ValueError(msg)
            stats[key] = (str(series), str(stat))
        object.__setattr__(self, "statistics", MappingProxyType(stats))

    @property
    def headline(self) -> str:
        """The name of the main value (the first)."""
        return next(iter(self.values), "")


class EvalData:
    """One run, seen for one algorithm, with every table loaded at most once.

    Args:
        run: the run directory (``redrive.results.open_run``).
        algorithm: the algorithm scored ("" for run-level metrics).
    """

    def __init__(self, run: Run, algorithm: str = "") -> None:
        self.run = run
        self.algorithm = algorithm
        self._cache: dict[str, Any] = {}

    def _cached(self, key: str, load: Callable[[], _T]) -> _T:
        if key not in self._cache:
            self._cache[key] = load()
        return cast("_T", self._cache[key])

    @property
    def frame_period_s(self) -> float:
        """Median time between frames (the driving sensor's period), seconds; 0.0 if unknown."""
        stamps = np.asarray(self.frames().column("stamp_ns").to_numpy(), dtype=np.int64)
        if stamps.size < 2:
            return 0.0
        return float(np.median(np.diff(np.sort(stamps)))) / 1e9

    def frames(self) -> pa.Table:
        return self._cached("frames", lambda: self.run.table("frames"))

    def steps(self) -> pa.Table:
        return self._cached("steps", lambda: self.run.table("steps"))

    def detections(self) -> dict[int, tuple[DetectedObject, ...]]:
        """frame index → this algorithm's objects (frames where its step succeeded)."""
        return self._cached("detections", lambda: self.run.detections(self.algorithm))

    def ground_truth(self) -> dict[int, tuple[DetectedObject, ...]]:
        return self._cached("ground_truth", self.run.ground_truth)

    def ego(self) -> dict[int, VehicleState]:
        return self._cached("ego", self.run.ego)

    def logged_ego(self) -> dict[int, VehicleState]:
        """frame index → the logged ego state stored apart from the driven one (closed loop);
        empty in open loop, where :meth:`ego` is the logged ego."""
        return self._cached("logged_ego", self.run.logged_ego)

    def closed_loop(self) -> pa.Table:
        """The closed-loop run's ``closed_loop`` table (the command that moved the ego, where it
        came from, the deviation from the logged pose), sorted by frame; empty in open loop."""
        return self._cached("closed_loop", lambda: self.run.table("closed_loop"))

    def road_map(self) -> RoadMap | None:
        """The run's road map, None when it has none."""
        return self._cached("road_map", self.run.road_map)

    def traffic_lights(self) -> dict[int, tuple[TrafficLight, ...]]:
        """frame index → the traffic lights' states of the frame (frames that had any)."""
        return self._cached("traffic_lights", self.run.traffic_lights)

    def paths(self) -> dict[int, PlannedPath]:
        return self._cached("paths", lambda: self.run.paths(self.algorithm))

    def commands(self) -> dict[int, ControlCommands]:
        return self._cached("commands", lambda: self.run.commands(self.algorithm))


def params_hash(params: Mapping[str, Any]) -> str:
    text = json.dumps(params, sort_keys=True, separators=(",", ":"), default=repr)
    return hashlib.sha256(text.encode()).hexdigest()


class Metric(ABC):
    """Base of every metric.

    Class attributes:
        name: unique name (``nuscenes_detection``); the entry-point name should match it.
        version: bump when the definition changes; stored with every value.
        role: which algorithms it scores: those of a :class:`~redrive.types.Role`, or None for
            the run as a whole (stored as :data:`WHOLE_RUN`).
        needs: what it reads (:data:`NEEDS`), checked before ``evaluate`` is called: an
            algorithm whose run lacks it is skipped, with what would provide it.
        unit: unit of its values (per value in ``MetricResult.units`` when they differ).
        higher_is_better: for A/B comparisons and report colouring.
        defaults: parameters and their defaults; ``Metric(**params)`` overrides them.
        pooling: how ``redrive evaluate BATCH`` pools it across the logs of a batch
            (:mod:`redrive.evaluation.pooling`): ``"concatenate"`` — evaluated once over all
            frames of all logs together (frame and object ids made unique per log), for metrics
            whose definition is a sum over frames (detection AP, CLEAR MOT and HOTA totals,
            latency percentiles); ``"frame_weighted_mean"`` (default) — each value is the mean of
            the logs' values weighted by their frame counts; ``"scenario_mean"`` — the plain
            mean of the logs' values, each log (scenario) counting once (nuPlan's final score
            over its scenarios); ``"none"`` — it cannot be pooled (per-log values only).
        pooled_name: the name of the pooled headline when the pooled value has a name of its
            own (``nuplan_scenario_score`` pools to ``cls``); None: the headline's name.
        scores: what its values score: :data:`SCORES_OUTPUT` (the algorithm's output) or
            :data:`SCORES_EGO` (the ego's motion: in open loop the logged ego, so the value is
            stored with subject :data:`SUBJECT_LOG`, the log's, not an algorithm's); None
            (default): :data:`SCORES_EGO` for a whole-run metric that needs ``ego``, else
            :data:`SCORES_OUTPUT` (:meth:`scores_kind`).  Per value in ``MetricResult.scores``.
    """

    name: ClassVar[str]
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None]
    needs: ClassVar[frozenset[str]] = frozenset()
    unit: ClassVar[str] = ""
    higher_is_better: ClassVar[bool] = True
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType({})
    pooling: ClassVar[str] = "frame_weighted_mean"
    pooled_name: ClassVar[str | None] = None
    scores: ClassVar[str | None] = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        unknown = sorted(set(cls.needs) - NEEDS)
        if unknown:
            msg = (
                f"metric class {cls.__qualname__}: needs {', '.join(unknown)} not known; "
                f"a metric may need {', '.join(sorted(NEEDS))}"
            )
            raise PluginError(msg)
        if cls.pooling not in POOLING_RULES:
            msg = (
                f"metric class {cls.__qualname__}: pooling {cls.pooling!r} is not one of "
                f"{', '.join(POOLING_RULES)}"
            )
            raise PluginError(msg)
        if cls.scores is not None and cls.scores not in SCORES:
            msg = (
                f"metric class {cls.__qualname__}: scores {cls.scores!r} is not one of "
                f"{', '.join(SCORES)}"
            )
            raise PluginError(msg)

    def __init__(self, **params: Any) -> None:
        unknown = sorted(set(params) - set(self.defaults))
        if unknown:
            msg = (
                f"metric {self.name!r}: unknown parameter(s) {', '.join(unknown)}; "
                f"known: {', '.join(sorted(self.defaults)) or 'none'}"
            )
            raise ConfigError(msg)
        self.params: Mapping[str, Any] = MappingProxyType({**self.defaults, **params})

    @abstractmethod
    def evaluate(self, data: EvalData) -> MetricResult:
        """Score ``data.algorithm`` of ``data.run``."""

    @classmethod
    def role_name(cls) -> str:
        """The role's value, or :data:`WHOLE_RUN` for a metric of the run as a whole."""
        return WHOLE_RUN if cls.role is None else cls.role.value

    @classmethod
    def scores_kind(cls) -> str:
        """What the metric's values score unless a value says otherwise (``scores``)."""
        if cls.scores is not None:
            return cls.scores
        role = getattr(cls, "role", None)
        return SCORES_EGO if role is None and "ego" in cls.needs else SCORES_OUTPUT

    def subject(self, result: MetricResult, key: str, *, algorithm: str, closed_loop: bool) -> str:
        """Whose motion or output value (or series) ``key`` of ``result`` scores: the algorithm's
        name, :data:`WHOLE_RUN` for a whole-run metric, or :data:`SUBJECT_LOG` for a value of
        the ego's motion in an open-loop run (the logged ego's)."""
        kind = result.scores.get(key, self.scores_kind())
        if kind == SCORES_EGO and not closed_loop:
            return SUBJECT_LOG
        return algorithm or WHOLE_RUN

    def describe(self) -> dict[str, Any]:
        """What the manifest records: name, version, parameters and their hash."""
        params = dict(self.params)
        return {
            "name": self.name,
            "version": self.version,
            "role": self.role_name(),
            "unit": self.unit,
            "higher_is_better": self.higher_is_better,
            "scores": self.scores_kind(),
            "params": json.loads(json.dumps(params, default=repr)),
            "params_hash": params_hash(params),
        }
