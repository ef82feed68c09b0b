"""A noisy oracle: ground truth made to look like a detector's output, for testing planners."""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any, ClassVar, NoReturn

import numpy as np

from redrive.algorithms.base import GROUND_TRUTH, Algorithm, Role, StageOutputs
from redrive.algorithms.reference._oracle_kernels import perturb_rows
from redrive.errors import AlgorithmError, ConfigError
from redrive.types import DetectedObject, Frame, ObjectClass, ObjectColumns, SensorType

__all__ = ["CONFUSABLE_CLASSES", "FALSE_POSITIVE_SHAPES", "NoisyOracle"]

logger = logging.getLogger(__name__)

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

    Determinism: the random generator of a frame is ``numpy.random.default_rng([seed,
    frame.index])``, so the output depends only on the frame and the config — not on which
    frames ran before — and pipelined, parallel or resumed runs give identical outputs.
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
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            self._bad("seed", seed, "an integer ≥ 0")
        self._seed = int(seed)
        self._center_std = self._number(config, "center_std_m")
        self._size_std = self._number(config, "size_std_rel")
        self._yaw_std = self._number(config, "yaw_std_rad")
        self._vel_std = self._number(config, "velocity_std_mps")
        self._p_miss = self._number(config, "miss_probability", upper=1.0)
        self._fp_rate = self._number(config, "false_positive_rate")
        self._fp_conf = self._number(config, "false_positive_confidence", upper=1.0)
        self._p_confuse = self._number(config, "class_confusion_probability", upper=1.0)
        self._stds = np.array([self._center_std, self._size_std, self._yaw_std, self._vel_std])
        self._visible_only = bool(config["visible_only"])
        self._keep_ids = bool(config["keep_ids"])
        max_range = config["max_range_m"]
        if max_range is None:
            self._max_range_m = math.inf
        else:
            self._max_range_m = self._number(config, "max_range_m")
            if self._max_range_m <= FALSE_POSITIVE_MIN_RANGE_M:
                self._bad("max_range_m", max_range, f"None or > {FALSE_POSITIVE_MIN_RANGE_M} m")

    def bind(self, sensors: Mapping[str, SensorType], *, extras: Iterable[str] = ()) -> None:
        """As :meth:`Algorithm.bind`, then one made-up perturbation, so that numba loads the
        oracle's kernel from the cache (or compiles it after an install) here, before a run's
        first frame, not inside that frame's latency."""
        super().bind(sensors, extras=extras)
        frozen3, frozen1 = np.zeros((1, 3)), np.zeros(1)  # ObjectColumns' arrays are read-only
        frozen3.flags.writeable = frozen1.flags.writeable = False
        normal3 = np.zeros((1, 3))
        perturb_rows(
            frozen3,
            frozen1,
            frozen3,
            frozen3,
            np.zeros(1, dtype=np.int64),
            np.zeros(1, dtype=np.bool_),
            normal3,
            normal3,
            np.zeros(1),
            np.zeros((1, 2)),
            self._stds,
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
        rng = np.random.default_rng([self._seed, frame.index])
        # the ground truth as columns (no pass over the objects when they came from
        # DetectedObject.many, as a simulator's and the decoders' do)
        truth_columns = ObjectColumns.from_objects(truth)
        kept = self._eligible(truth_columns)
        columns = self._perturb(truth_columns, kept, rng)
        columns += self._false_positives(rng)
        out = [] if not columns else DetectedObject.many(**_concatenated(columns))
        logger.debug(
            "%s frame %d: %d ground-truth objects, %d eligible, %d returned",
            self.name,
            frame.index,
            len(truth),
            len(kept),
            len(out),
        )
        return out

    def _eligible(self, truth: ObjectColumns) -> list[int]:
        """The rows of the objects seen (when ``visible_only``) and within ``max_range_m``."""
        near = (np.hypot(truth.centers[:, 0], truth.centers[:, 1]) <= self._max_range_m).tolist()
        if not self._visible_only:
            return [i for i, ok in enumerate(near) if ok]
        return [
            i
            for i, (ok, points, seen) in enumerate(
                zip(near, truth.num_lidar_points, truth.visible, strict=True)
            )
            if ok and points != 0 and seen is not False
        ]

    def _perturb(
        self, truth: ObjectColumns, rows: list[int], rng: np.random.Generator
    ) -> list[dict[str, Any]]:
        """The kept detections of ground-truth rows ``rows`` as ``DetectedObject.many``'s
        columns (an empty list when none is kept)."""
        n = len(rows)
        # every draw is made for every object, in a fixed order, whatever the config
        missed = rng.random(n) < self._p_miss
        n_center = rng.normal(0.0, 1.0, (n, 3))
        n_size = rng.normal(0.0, 1.0, (n, 3))
        n_yaw = rng.normal(0.0, 1.0, n)
        n_vel = rng.normal(0.0, 1.0, (n, 2))
        confused = rng.random(n) < self._p_confuse
        pick = rng.random(n)  # which other class, as a fraction of the choices
        if n == 0:
            return []
        # the arithmetic of the kept objects in one compiled call on the ground truth's
        # columns (numpy's elementwise operations, bit for bit: ._oracle_kernels), but for
        # the sizes' np.maximum (see there)
        index = np.array(rows, dtype=np.int64)
        true_sizes = truth.sizes[index]
        d_size = n_size * self._size_std
        sizes_all = np.maximum(true_sizes * (1.0 + d_size), 0.1 * true_sizes)
        kept_at, centers, sizes, yaws, velocities, orientations = perturb_rows(
            truth.centers,
            truth.yaws_rad,
            truth.velocities,
            truth.orientations,
            index,
            missed,
            n_center,
            sizes_all,
            n_yaw,
            n_vel,
            self._stds,
        )
        kept = kept_at.tolist()
        if not kept:
            return []
        picked = [rows[i] for i in kept]
        true_classes = truth.object_classes
        classes = [true_classes[r] for r in picked]
        if self._p_confuse > 0.0:
            for j, i in enumerate(kept):
                if confused[i]:
                    cls = classes[j]
                    choices = [c for c in CONFUSABLE_CLASSES if c is not cls]
                    classes[j] = choices[min(int(pick[i] * len(choices)), len(choices) - 1)]
        ids = truth.object_ids
        return [
            {
                "object_ids": [ids[r] for r in picked] if self._keep_ids else [-1] * len(kept),
                "object_classes": classes,
                "confidences": truth.confidences[picked],
                "centers": centers,
                "sizes": sizes,
                "yaws_rad": yaws,
                "velocities": velocities,
                "accelerations": truth.accelerations[picked],
                "orientations": orientations,
            }
        ]

    def _false_positives(self, rng: np.random.Generator) -> list[dict[str, Any]]:
        """The false positives as ``DetectedObject.many``'s columns (an empty list for none)."""
        count = int(rng.poisson(self._fp_rate)) if self._fp_rate > 0 else 0
        if count == 0:
            return []
        classes = list(FALSE_POSITIVE_SHAPES)
        probs = np.array([FALSE_POSITIVE_SHAPES[c][0] for c in classes])
        picks = rng.choice(len(classes), size=count, p=probs / probs.sum())
        far_m = min(self._max_range_m, FALSE_POSITIVE_MAX_RANGE_M)
        ranges_m = rng.uniform(FALSE_POSITIVE_MIN_RANGE_M, far_m, count)
        bearings = rng.uniform(-math.pi, math.pi, count)
        yaws = rng.uniform(-math.pi, math.pi, count)
        d_size = rng.normal(0.0, 1.0, (count, 3)) * self._size_std
        fp_classes, centers, sizes = [], [], []
        for k in range(count):
            cls = classes[int(picks[k])]
            typical = np.array(FALSE_POSITIVE_SHAPES[cls][1])
            size = np.maximum(typical * (1.0 + d_size[k]), 0.1 * typical)
            centers.append(
                [
                    ranges_m[k] * math.cos(bearings[k]),
                    ranges_m[k] * math.sin(bearings[k]),
                    0.5 * size[2],
                ]
            )
            fp_classes.append(cls)
            sizes.append(size)
        orientations = np.zeros((count, 3))
        orientations[:, 0] = yaws
        return [
            {
                "object_ids": [-1] * count,
                "object_classes": fp_classes,
                "confidences": np.full(count, self._fp_conf),
                "centers": np.array(centers, dtype=np.float64),
                "sizes": np.array(sizes, dtype=np.float64),
                "yaws_rad": yaws,
                "velocities": np.zeros((count, 3)),
                "accelerations": np.zeros((count, 3)),
                "orientations": orientations,
            }
        ]


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
