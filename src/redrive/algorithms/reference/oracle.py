"""A noisy oracle: ground truth made to look like a detector's output, for testing planners."""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any, ClassVar, NoReturn

import numpy as np
import numpy.typing as npt

from redrive.algorithms.base import GROUND_TRUTH, Algorithm, Role, StageOutputs
from redrive.algorithms.reference._oracle_kernels import oracle_frame_packed
from redrive.errors import AlgorithmError, ConfigError
from redrive.types import DetectedObject, Frame, ObjectClass, ObjectColumns, SensorType
from redrive.types._arrays import finite, finite_nonnegative, minus_ones, ones, zeros

__all__ = ["CONFUSABLE_CLASSES", "FALSE_POSITIVE_SHAPES", "NoisyOracle"]

logger = logging.getLogger(__name__)

_F = npt.NDArray[np.float64]

#: classes a confused label is drawn from (uniformly, never the true one).
CONFUSABLE_CLASSES: tuple[ObjectClass, ...] = (
    ObjectClass.VEHICLE,
    ObjectClass.TRUCK,
    ObjectClass.PEDESTRIAN,
    ObjectClass.BICYCLE,
    ObjectClass.MOTORCYCLE,
)

#: false positives: class → (probability, size l, w, h in metres).
FALSE_POSITIVE_SHAPES: Mapping[ObjectClass, tuple[float, tuple[float, float, float]]] = (
    MappingProxyType(
        {
            ObjectClass.VEHICLE: (0.6, (4.5, 1.9, 1.5)),
            ObjectClass.PEDESTRIAN: (0.25, (0.6, 0.6, 1.75)),
            ObjectClass.BICYCLE: (0.15, (1.8, 0.6, 1.6)),
        }
    )
)

#: false positives lie between this range and min(max_range_m, FALSE_POSITIVE_MAX_RANGE_M).
FALSE_POSITIVE_MIN_RANGE_M = 3.0
FALSE_POSITIVE_MAX_RANGE_M = 60.0


class NoisyOracle(Algorithm):
    """Ground-truth objects with detector-like noise, misses and false positives.

    For each ground-truth object of the frame (``frame.ground_truth``, in base_link), in order:

    * dropped when ``visible_only`` and it was not seen (``num_lidar_points == 0`` or
      ``visible is False``; ``None`` counts as seen), or when its centre lies farther than
      ``max_range_m`` (horizontal distance from the base_link origin; None = no limit);
    * missed with probability ``miss_probability``;
    * otherwise returned with Gaussian noise: ``center_std_m`` on each of x, y, z (m),
      ``size_std_rel`` relative on each of l, w, h (``size · (1 + N(0, σ))``, floored at 10 %
      of the true size), ``yaw_std_rad`` on the yaw (also in ``orientation[0]``) and
      ``velocity_std_mps`` on vx and vy (m/s; vz and the acceleration are kept).  With
      probability ``class_confusion_probability`` its class is replaced by another of
      :data:`CONFUSABLE_CLASSES`, drawn uniformly.  Confidence is the ground truth's (1.0).
      ``object_id`` is the ground-truth id when ``keep_ids`` (so it is a perfect tracker too),
      else -1 (as from a detector without tracking: feed it to a tracker).  ``num_lidar_points``,
      ``visible`` and ``bbox_2d`` are cleared: they are annotations, not detections.

    False positives: a Poisson number with mean ``false_positive_rate`` per frame, each a box
    of a class drawn from :data:`FALSE_POSITIVE_SHAPES` (vehicle 60 %, pedestrian 25 %,
    bicycle 15 %) with that class's typical size (± ``size_std_rel``), standing on the ground
    plane of base_link (centre z = h/2), at a range uniform in
    [:data:`FALSE_POSITIVE_MIN_RANGE_M`, min(``max_range_m``, :data:`FALSE_POSITIVE_MAX_RANGE_M`)]
    and a bearing uniform all around the ego, yaw uniform, velocity zero over ground (static
    clutter, in the ground-truth velocity convention), confidence ``false_positive_confidence``,
    id -1.

    Determinism: every draw of a frame is a counter-based random number keyed by ``(seed,
    frame.index)`` (SplitMix64, :mod:`._oracle_kernels`), and each ground-truth row has its own
    counters, so the output depends only on the frame and the config — not on which frames ran
    before — and pipelined, parallel or resumed runs give identical outputs.  (Before issue
    15's h-obj7 the generator was ``numpy.random.default_rng([seed, frame.index])``: the same
    distributions, other numbers.)
    Outputs: true detections in ground-truth order, then the false positives.
    """

    role = Role.PERCEPTION
    inputs = (GROUND_TRUTH,)
    version = "1"
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {
            "seed": 0,
            "center_std_m": 0.2,
            "size_std_rel": 0.05,
            "yaw_std_rad": 0.05,
            "velocity_std_mps": 0.3,
            "miss_probability": 0.05,
            "false_positive_rate": 0.1,
            "false_positive_confidence": 0.5,
            "class_confusion_probability": 0.0,
            "visible_only": True,
            "max_range_m": None,
            "keep_ids": True,
        }
    )

    def __init__(self, *, name: str | None = None) -> None:
        super().__init__(name=name)
        self.setup(self.config)

    def setup(self, config: Mapping[str, Any]) -> None:
        seed = config["seed"]
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 1 << 63:
            self._bad("seed", seed, "an integer in [0, 2**63)")
        self._seed = int(seed)
        self._center_std = self._number(config, "center_std_m")
        self._size_std = self._number(config, "size_std_rel")
        self._yaw_std = self._number(config, "yaw_std_rad")
        self._vel_std = self._number(config, "velocity_std_mps")
        self._p_miss = self._number(config, "miss_probability", upper=1.0)
        self._fp_rate = self._number(config, "false_positive_rate")
        self._fp_conf = self._number(config, "false_positive_confidence", upper=1.0)
        self._p_confuse = self._number(config, "class_confusion_probability", upper=1.0)
        self._visible_only = bool(config["visible_only"])
        self._keep_ids = bool(config["keep_ids"])
        max_range = config["max_range_m"]
        if max_range is None:
            self._max_range_m = math.inf
        else:
            self._max_range_m = self._number(config, "max_range_m")
            if self._max_range_m <= FALSE_POSITIVE_MIN_RANGE_M:
                self._bad("max_range_m", max_range, f"None or > {FALSE_POSITIVE_MIN_RANGE_M} m")
        far_m = min(self._max_range_m, FALSE_POSITIVE_MAX_RANGE_M)
        self._params = np.array(
            [
                self._center_std,
                self._size_std,
                self._yaw_std,
                self._vel_std,
                self._p_miss,
                self._p_confuse,
                self._fp_rate,
                FALSE_POSITIVE_MIN_RANGE_M,
                far_m,
                self._max_range_m,
            ]
        )

    def bind(self, sensors: Mapping[str, SensorType], *, extras: Iterable[str] = ()) -> None:
        """As :meth:`Algorithm.bind`, then one made-up frame, so that numba loads the oracle's
        kernel from the cache (or compiles it after an install) here, before a run's first
        frame, not inside that frame's latency."""
        super().bind(sensors, extras=extras)
        self.warm_kernels()

    def warm_kernels(self) -> None:
        """The made-up frame of :meth:`bind` (configured, not bound, is enough): numba's kernel
        loaded in this process (also by :mod:`redrive.batch.preload`)."""
        frozen3, frozen1 = np.zeros((1, 3)), np.zeros(1)  # ObjectColumns' arrays are read-only
        frozen3.flags.writeable = frozen1.flags.writeable = False
        oracle_frame_packed(
            self._seed,
            0,
            frozen3,
            frozen3,
            frozen1,
            frozen3,
            frozen3,
            _all_true(1),
            self._params,
            _FP_PROBS,
            _FP_SIZES,
        )

    def _bad(self, key: str, value: object, wanted: str) -> NoReturn:
        msg = f"algorithm {self.name!r}: config {key} = {value!r}; expected {wanted}"
        raise ConfigError(msg)

    def _number(self, config: Mapping[str, Any], key: str, *, upper: float = math.inf) -> float:
        value = config[key]
        ok = not isinstance(value, bool) and isinstance(value, int | float)
        if not ok or not 0.0 <= float(value) <= upper:
            bounds = "≥ 0" if upper == math.inf else f"in [0, {upper}]"
            self._bad(key, value, f"a number {bounds}")
        return float(value)

    # -- one frame ----------------------------------------------------------------------------

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        truth = frame.ground_truth
        if truth is None:
            msg = (
                f"{self.name}: frame {frame.index} (stamp {frame.stamp_ns} ns) carries no "
                "ground truth; the noisy oracle needs a log with ground-truth objects"
            )
            raise AlgorithmError(msg)
        # the ground truth as columns (no pass over the objects when they came from
        # DetectedObject.many, as a simulator's and the decoders' do)
        columns = ObjectColumns.from_objects(truth)
        # every draw and the arithmetic of the frame in one compiled call (._oracle_kernels;
        # its arrays packed in two, unpacked as views)
        k, m, ints, floats = oracle_frame_packed(
            self._seed,
            frame.index,
            columns.center_m,
            columns.size_m,
            columns.yaw_rad,
            columns.velocity_mps,
            columns.orientation_rad,
            self._seen(columns),
            self._params,
            _FP_PROBS,
            _FP_SIZES,
        )
        rows, confuse, centers, sizes, yaws, velocities, orientations = _unpacked(k, ints, floats)
        fp_picks, fp_centers, fp_sizes, fp_yaws = _unpacked_fp(k, m, ints, floats)
        parts = []
        if len(rows):
            parts.append(
                self._detections(
                    columns, rows, confuse, centers, sizes, yaws, velocities, orientations
                )
            )
        if parts and not len(fp_picks) and _trusted_defaults(columns, sizes, yaws):
            out = _as_trusted(parts[0])
        else:
            if len(fp_picks):
                parts.append(self._false_positives(fp_picks, fp_centers, fp_sizes, fp_yaws))
            out = [] if not parts else DetectedObject.many(**_concatenated(parts))
        logger.debug(
            "%s frame %d: %d ground-truth objects, %d returned",
            self.name,
            frame.index,
            len(truth),
            len(out),
        )
        return out

    def _seen(self, truth: ObjectColumns) -> npt.NDArray[np.bool_]:
        """Which rows count as seen: all unless ``visible_only``, else those with LiDAR points
        (≠ 0) and not ``visible is False`` (None counts as seen); the range is the kernel's."""
        n = len(truth)
        points, visible = truth.num_lidar_points, truth.visible
        if not self._visible_only or (bool((points == -1).all()) and visible.count(None) == n):
            return _all_true(n)
        seen: npt.NDArray[np.bool_] = (points != 0) & np.array(
            [v is not False for v in visible], dtype=np.bool_
        )
        seen.flags.writeable = False  # the kernel's one signature: read-only columns
        return seen

    def _detections(  # noqa: PLR0917
        self,
        truth: ObjectColumns,
        rows_a: npt.NDArray[np.int64],
        confuse: npt.NDArray[np.float64],
        centers: npt.NDArray[np.float64],
        sizes: npt.NDArray[np.float64],
        yaws: npt.NDArray[np.float64],
        velocities: npt.NDArray[np.float64],
        orientations: npt.NDArray[np.float64],
    ) -> dict[str, Any]:
        """The kept ground-truth rows ``rows_a`` with their noisy columns as
        ``DetectedObject.many``'s columns (classes confused here)."""
        rows = rows_a.tolist()
        true_classes = truth.object_class
        classes = [true_classes[r] for r in rows]
        p = self._p_confuse
        if p > 0.0:
            for j, u in enumerate(confuse.tolist()):
                if u < p:  # then u / p is uniform in [0, 1): which other class
                    cls = classes[j]
                    choices = [c for c in CONFUSABLE_CLASSES if c is not cls]
                    classes[j] = choices[min(int(u / p * len(choices)), len(choices) - 1)]
        return {
            "object_id": truth.object_id[rows_a] if self._keep_ids else [-1] * len(rows),
            "object_class": classes,
            "confidence": truth.confidence[rows_a],
            "center_m": centers,
            "size_m": sizes,
            "yaw_rad": yaws,
            "velocity_mps": velocities,
            "acceleration_mps2": truth.acceleration_mps2[rows_a],
            "orientation_rad": orientations,
        }

    def _false_positives(
        self,
        picks: npt.NDArray[Any],
        centers: npt.NDArray[Any],
        sizes: npt.NDArray[Any],
        yaws: npt.NDArray[Any],
    ) -> dict[str, Any]:
        """The kernel's false positives as ``DetectedObject.many``'s columns."""
        count = len(picks)
        orientations = np.zeros((count, 3))
        orientations[:, 0] = yaws
        return {
            "object_id": [-1] * count,
            "object_class": [_FP_CLASSES[k] for k in picks.tolist()],
            "confidence": np.full(count, self._fp_conf),
            "center_m": centers,
            "size_m": sizes,
            "yaw_rad": yaws,
            "velocity_mps": np.zeros((count, 3)),
            "acceleration_mps2": np.zeros((count, 3)),
            "orientation_rad": orientations,
        }


def _unpacked(
    k: int, ints: npt.NDArray[np.int64], floats: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.int64], _F, _F, _F, _F, _F, _F]:
    """The kept rows' arrays of :func:`._oracle_kernels.oracle_frame_packed` (C-contiguous
    views): rows, confusion uniforms, centres, sizes, yaws, velocities, orientations."""
    k3 = 3 * k
    return (
        ints[:k],
        floats[:k],
        floats[k : k + k3].reshape(k, 3),
        floats[k + k3 : k + 2 * k3].reshape(k, 3),
        floats[k + 2 * k3 : 2 * k + 2 * k3],
        floats[2 * k + 2 * k3 : 2 * k + 3 * k3].reshape(k, 3),
        floats[2 * k + 3 * k3 : 14 * k].reshape(k, 3),
    )


def _unpacked_fp(
    k: int, m: int, ints: npt.NDArray[np.int64], floats: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.int64], _F, _F, _F]:
    """The false positives' arrays of :func:`._oracle_kernels.oracle_frame_packed` (views):
    classes, centres, sizes, yaws."""
    at = 14 * k
    return (
        ints[k:],
        floats[at : at + 3 * m].reshape(m, 3),
        floats[at + 3 * m : at + 6 * m].reshape(m, 3),
        floats[at + 6 * m : at + 7 * m],
    )


_FP_CLASSES = tuple(FALSE_POSITIVE_SHAPES)
_FP_PROBS = np.array([FALSE_POSITIVE_SHAPES[c][0] for c in _FP_CLASSES])
_FP_PROBS /= _FP_PROBS.sum()
_FP_SIZES = np.array([FALSE_POSITIVE_SHAPES[c][1] for c in _FP_CLASSES], dtype=np.float64)
_ALL_TRUE: dict[int, npt.NDArray[np.bool_]] = {}


def _all_true(n: int) -> npt.NDArray[np.bool_]:
    """A read-only (n,) column of True (one per n)."""
    arr = _ALL_TRUE.get(n)
    if arr is None:
        arr = np.ones(n, dtype=np.bool_)
        arr.flags.writeable = False
        _ALL_TRUE[n] = arr
    return arr


def _trusted_defaults(
    truth: ObjectColumns, sizes: npt.NDArray[np.float64], yaws: npt.NDArray[np.float64]
) -> bool:
    """Whether detections of ``truth`` with these noisy sizes and yaws are what
    ``ObjectColumns.trusted`` builds: the truth's confidences and accelerations the shared
    defaults (ones, zeros: what the detections take from them), and the columns passing
    ``DetectedObject.many``'s checks (the sizes finite and non-negative, the yaws finite)."""
    n = len(truth)
    return (
        truth.confidence is ones(n)
        and truth.acceleration_mps2 is zeros(n)
        and finite_nonnegative(sizes)
        and finite(yaws)
    )


def _as_trusted(columns: dict[str, Any]) -> list[DetectedObject]:
    """``DetectedObject.many(**columns)`` of :meth:`NoisyOracle._detections`' columns that
    :func:`_trusted_defaults` vouched for: the same objects and values, not checked again."""
    ids = columns["object_id"]
    return ObjectColumns.trusted(
        object_id=minus_ones(len(ids)) if isinstance(ids, list) else ids,
        object_class=tuple(columns["object_class"]),
        center_m=columns["center_m"],
        size_m=columns["size_m"],
        yaw_rad=columns["yaw_rad"],
        velocity_mps=columns["velocity_mps"],
        orientation_rad=columns["orientation_rad"],
    ).objects()


def _concatenated(parts: list[dict[str, Any]]) -> dict[str, Any]:
    """``DetectedObject.many``'s keyword arguments for the rows of ``parts`` one after another."""
    if len(parts) == 1:
        return parts[0]
    out: dict[str, Any] = {}
    for key, first in parts[0].items():
        columns = [part[key] for part in parts]
        if isinstance(first, list):
            out[key] = [v for column in columns for v in column]
        else:
            out[key] = np.concatenate(columns)
    return out
